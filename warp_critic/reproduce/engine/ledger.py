"""``ledger.jsonl``: one record per event of every ``reproduce`` call on an output folder.

A call that got the folder's lock appends ``start`` (its command, machine and code), one ``stage`` per
stage it completed, ``alive`` every :data:`HEARTBEAT` seconds while it works, and ``end`` (or
``end`` with ``"status": "interrupted"`` / ``"failed"``). A call refused before it holds the lock
(a bad flag, a folder in use) writes nothing. The report's header gives the ledger's total wall time
(the sum over calls of end - start; a call without an end, killed where it could not write one,
counts to its last record, so to within a heartbeat of its death) next to the sum of the report's
stage times, so a run resumed over many sittings states what it cost in all.
"""

from __future__ import annotations

import json
import os
import platform
import threading
import time
import uuid
from pathlib import Path

LEDGER = "ledger.jsonl"
#: seconds between a working call's ``alive`` records
HEARTBEAT = 300.0


def now() -> str:
    """UTC time as ``YYYY-MM-DDTHH:MM:SSZ``."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


#: the instruction sets that decide which float kernels torch and its libraries pick: two machines
#: that differ in them give numbers that differ in the last bits (a virtual machine's CPU name
#: often does not tell them apart)
SIMD_FLAGS = ("avx", "avx2", "fma", "avx512f", "avx512_bf16", "avx_vnni", "amx_tile")


def _cpu() -> dict:
    """The first CPU's model name, its vendor, family and model numbers and its
    :data:`SIMD_FLAGS`, from ``/proc/cpuinfo`` (elsewhere the model name alone)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return {"cpu": platform.processor() or "?"}
    first = dict(
        (k.strip(), v.strip())
        for k, _, v in (line.partition(":") for line in text.split("\n\n")[0].splitlines())
    )
    flags = set(first.get("flags", "").split())
    return {
        "cpu": first.get("model name") or platform.processor() or "?",
        "cpu_id": " ".join(first.get(k, "?") for k in ("vendor_id", "cpu family", "model")),
        "simd": [f for f in SIMD_FLAGS if f in flags],
    }


def machine(device: str) -> dict:
    """What the call ran on: the device, the CPU model, identity (vendor, family, model, the
    instruction sets that change float results) and count, the system (no host name)."""
    return {
        "device": device,
        **_cpu(),
        "cpus": os.cpu_count(),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
    }


#: the folder this package runs from: a git checkout where it holds ``.git`` (an installed package does not)
CHECKOUT = Path(__file__).resolve().parents[3]


def code(root: Path = CHECKOUT) -> dict:
    """What code the call ran: the package's version and, where it runs from a git checkout
    (``root/.git``), the commit checked out (``commit``, read from ``.git`` without running git;
    uncommitted changes are not seen). A run resumed over sittings may span commits; each call
    says which it ran."""
    from importlib import metadata

    try:
        found: dict = {"warp_critic": metadata.version("warp-critic")}
    except metadata.PackageNotFoundError:  # run from a source tree that was never installed
        found = {"warp_critic": "?"}
    commit = _head_commit(Path(root) / ".git")
    if commit is not None:
        found["commit"] = commit
    return found


def _head_commit(git: Path) -> str | None:
    """The first 12 hex digits of the commit ``git``'s HEAD names (detached, a loose branch ref or a
    packed one), or ``None`` (no such folder: an installed package; a worktree's ``.git`` file)."""
    try:
        head = (git / "HEAD").read_text().strip()
        if head.startswith("ref: "):
            ref = head[5:]
            if (git / ref).is_file():
                head = (git / ref).read_text().strip()
            else:
                packed = (
                    (git / "packed-refs").read_text() if (git / "packed-refs").is_file() else ""
                )
                head = next(
                    (x.split()[0] for x in packed.splitlines() if x.endswith(" " + ref)), ""
                )
    except OSError:
        return None
    ok = len(head) >= 12 and all(c in "0123456789abcdef" for c in head)
    return head[:12] if ok else None


def append(out: Path, record: dict) -> None:
    """Append one record (a line) to ``out``'s ledger, flushed to disk."""
    with open(Path(out) / LEDGER, "a", encoding="utf-8") as f:
        f.write(json.dumps(record, sort_keys=True) + "\n")
        f.flush()
        os.fsync(f.fileno())


def new_call() -> str:
    return uuid.uuid4().hex[:12]


class Call:
    """One ``reproduce`` call's records in the ledger of ``out`` (a context manager): ``start`` on
    entry, :meth:`stage` per completed stage, ``end`` on exit (status done / interrupted /
    failed). Enter it only once the call holds the folder's lock."""

    def __init__(
        self,
        out: Path,
        command: str,
        selected: list[str],
        device: str,
        heartbeat: float = HEARTBEAT,
    ):
        self.out, self.id, self.heartbeat = Path(out), new_call(), heartbeat
        self._lock = threading.Lock()  # the heartbeat's thread appends too
        self._stop = threading.Event()
        self._beat: threading.Thread | None = None
        self.ran: list[str] = []
        self.start = {
            "event": "start",
            "call": self.id,
            "command": command,
            "selected": list(selected),
            "machine": machine(device),
            "code": code(),
        }
        self.t0 = 0.0

    def __enter__(self) -> Call:
        self.t0 = time.perf_counter()
        self._append({**self.start, "time": now()})
        self._beat = threading.Thread(target=self._alive, name="ledger-heartbeat", daemon=True)
        self._beat.start()
        return self

    def _append(self, record: dict) -> None:
        with self._lock:
            append(self.out, record)

    def _alive(self) -> None:
        while not self._stop.wait(self.heartbeat):
            try:
                self._append({"event": "alive", "call": self.id, "time": now()})
            except OSError:  # a full disk: the call itself will say so; the beat stops
                return

    def stage(self, name: str, seconds: float, dir_name: str | None = None) -> None:
        self.ran.append(name)
        rec = {"event": "stage", "call": self.id, "stage": name, "seconds": float(seconds)}
        if dir_name is not None:  # the stage's directory: its settings' hash, not only its name
            rec["dir"] = dir_name
        self._append({**rec, "time": now()})

    def __exit__(self, kind, value, tb) -> None:
        # a run's own stop (``running.loop.Interrupted``) is a KeyboardInterrupt too: interrupted
        if kind is None:
            status = "done"
        elif issubclass(kind, KeyboardInterrupt):
            status = "interrupted"
        else:
            status = "failed"
        self._stop.set()
        if self._beat is not None:
            self._beat.join()
        self._append(
            {
                "event": "end",
                "call": self.id,
                "time": now(),
                "status": status,
                "wall_s": time.perf_counter() - self.t0,
                "stages_run": self.ran,
            },
        )


def read(out: Path) -> list[dict]:
    """The ledger's records (a torn last line, from a crash mid-write, is skipped)."""
    path = Path(out) / LEDGER
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            rows.append(json.loads(line))
        except ValueError:
            continue
    return rows


def _epoch(stamp: str) -> float:
    import calendar

    return float(calendar.timegm(time.strptime(stamp, "%Y-%m-%dT%H:%M:%SZ")))


def summary(rows: list[dict], open_call: str | None = None, open_wall: float = 0.0) -> dict:
    """calls, total wall time (s), first start, last end, stages run by the ledger's calls.

    ``open_call`` (the call writing the report, without its end yet) counts ``open_wall`` s."""
    calls: dict[str, dict] = {}
    for r in rows:
        c = calls.setdefault(r.get("call", "?"), {"start": None, "end": None, "last": None})
        if r.get("event") == "start":
            c["start"] = r["time"]
        elif r.get("event") == "end":
            c["end"] = r["time"]
        c["last"] = r.get("time", c["last"])
    total, first, last = 0.0, None, None
    for call, c in calls.items():
        if c["start"] is None:
            continue
        first = min(first or c["start"], c["start"])
        if call == open_call:
            total += open_wall
            last = max(last or "", now())
            continue
        end = c["end"] or c["last"]
        total += max(_epoch(end) - _epoch(c["start"]), 0.0)
        last = max(last or end, end)
    ran = [r.get("dir", r["stage"]) for r in rows if r.get("event") == "stage"]
    return {
        "calls": sum(c["start"] is not None for c in calls.values()),
        "unfinished": sum(
            c["start"] is not None and c["end"] is None and k != open_call for k, c in calls.items()
        ),
        "wall": total,
        "first": first,
        "last": last,
        "stages_run": ran,
    }


def calls(rows: list[dict]) -> list[dict]:
    """One entry per call of the ledger ``rows``, in start order: ``{"call", "command", "cpu",
    "start", "end", "wall_s", "status", "stages"}``. A call without an end (killed where it could
    not write one) ends at its last record (a stage or its 5-minute heartbeat) and its status is
    ``"killed"``; its wall time is counted to there, as :func:`summary` counts it (a call that
    wrote its end: the wall time it measured). ``stages``: the stage directories it completed."""
    out: dict[str, dict] = {}
    for r in rows:
        c = out.get(r.get("call", "?"))
        if r.get("event") == "start":
            out[r["call"]] = {
                "call": r["call"],
                "command": r.get("command", ""),
                "cpu": (r.get("machine") or {}).get("cpu", ""),
                "start": r["time"],
                "end": r["time"],
                "wall_s": 0.0,
                "status": "killed",
                "stages": [],
            }
            continue
        if c is None:
            continue  # a record of a call whose start is not in the ledger
        c["end"] = r.get("time", c["end"])
        if r.get("event") == "stage":
            c["stages"].append(r.get("dir", r.get("stage", "?")))
        elif r.get("event") == "end":
            c["status"] = str(r.get("status", "?"))
            if isinstance(r.get("wall_s"), (int, float)):
                c["wall_s"] = float(r["wall_s"])  # measured by the call, finer than the stamps
    for c in out.values():
        if c["status"] == "killed" or not c["wall_s"]:
            c["wall_s"] = max(_epoch(c["end"]) - _epoch(c["start"]), 0.0)
    return sorted(out.values(), key=lambda c: c["start"])


def stage_compute(rec) -> float:
    """A stage record's compute (s): its completing call's wall time, or the sum of its iteration
    times over all calls where that is more (a meta-training stage resumed over several calls
    records only its last call's wall time; its seeds are batched, so one seed's sum is the
    stage's)."""
    seeds = (rec.data.get("result", {}).get("seeds") if rec.group == "metatrain" else None) or {}
    trained = max((float(v.get("seconds", 0.0)) for v in seeds.values()), default=0.0)
    return max(float(rec.data["seconds"]), trained)


def numbers(
    s: dict, stage_seconds: dict[str, float], compute: dict[str, float] | None = None
) -> dict:
    """What the report states of the ledger (``results.json``'s ``ledger``): :func:`summary`'s
    ``s`` with the report's stage times (``stage_seconds``: stage directory, or name for records
    without one -> seconds) and, with ``compute`` (the same keys, :func:`stage_compute`), the
    compute of the stages carried in (``carried_compute_seconds``; ``None`` without it)."""
    before = [n for n in stage_seconds if n not in s["stages_run"]]
    return {
        "file": LEDGER,
        "calls": s["calls"],
        "unfinished": s["unfinished"],
        "wall_seconds": s["wall"],
        "first_start": s["first"],
        "last_end": s["last"],
        "stages": len(stage_seconds),
        "stage_seconds_sum": sum(stage_seconds.values()),
        "stages_before_ledger": before,
        "before_seconds": sum(stage_seconds[n] for n in before),
        "carried_compute_seconds": None
        if compute is None
        else sum(compute.get(n, stage_seconds[n]) for n in before),
    }


def header_line_of(n: dict) -> str:
    """The report header's line from :func:`numbers`' dict (as ``results.json`` holds it): the
    ledger's total wall time, the sum of the stage times and the stages carried in with their
    compute."""
    wall, total, before = n["wall_seconds"], n["stage_seconds_sum"], n["stages_before_ledger"]
    line = (
        f"- ledger (`{n['file']}`): {n['calls']} call(s) on this folder"
        + (f" ({n['unfinished']} without an end)" if n["unfinished"] else "")
        + (f", {n['first_start']} to {n['last_end']}" if n["first_start"] else "")
        + f"; total wall time {wall:.0f} s ({wall / 3600:.1f} h); sum of the report's "
        f"{n['stages']} stage times {total:.0f} s "
        f"({total / 3600:.1f} h; each stage's time is its completing call's)"
    )
    if before:  # carried in (``tools/carry_stages.py restore``) or run before the ledger existed
        line += (
            f"; {len(before)} of these stages were completed by no call of this ledger (carried in "
            f"with their records; their times {n['before_seconds']:.0f} s are in "
            f"the sum, not in the ledger's total): {', '.join(sorted(before))}"
        )
        carried = n["carried_compute_seconds"]
        if carried is not None:
            line += (
                f". Their compute, each the larger of its record's time and its iteration times "
                f"over all calls: {carried:.0f} s ({carried / 3600:.1f} h), which the ledger's "
                f"{wall / 3600:.1f} h of wall time does not include"
            )
    return line
