"""Carry the complete stages of a reproduce output to another machine, without training-only state.

A paper-setting ``reproduce`` takes longer than one sitting on a laptop CPU. Its complete stages
can be saved into a small archive (a folder that can be committed or copied), and restored into an
output folder on another machine, where ``reproduce`` then skips them and runs only what is left.

* :func:`save` copies every complete stage of ``out`` (its ``stage.json`` is present and usable)
  into ``archive/<stage dir>``, without recordings (``*.rrd``) and locks. What a stage keeps is told
  by the stages' owner (:class:`CarryRules`; the engine knows no stage and no method): the
  checkpoints of the slimmed group's runs lose the state only a resumed training needs, and a
  run's ``metrics.jsonl`` is carried only as far as a reader of the archive needs it
  (:func:`thin_metrics`). JSON and JSONL files are stored xz-compressed (``NAME.xz``: the
  records compress about 5x, and an archive is meant to be committed). A shipped scene's absolute
  path is written ``scenes/NAME`` (the scene is found by its content hash). A stage already in the
  archive is skipped when its ``stage.json`` is the same, refused when it differs. The output's
  ledger is merged into the archive's (:data:`ARCHIVED_LEDGER`).
* :func:`restore` copies every archived stage that ``out`` lacks into ``out``, decompressed (made a
  reproduce output if new; its lock is held while copying). A stage ``out`` already has complete is
  skipped; one that ``out`` holds incomplete (started there) is refused, never overwritten.
  Archives written before compression (plain JSON, whole metrics) restore as they are. The
  archive's ledger is merged into ``out``'s: a stage travels with the call that completed it, so a
  run resumed over sittings on fresh machines, saving into an archive it commits as it goes, ends
  with a ledger that holds every call of every sitting and no stage "carried in".
Publishing a finished report (a folder to commit, with the archive of the stages it read) is
:mod:`~warp_critic.reproduce.engine.publish`, on these functions.

Each stage is copied into a temporary sibling directory and renamed into place, so an interrupted
call leaves no half-copied stage behind.
"""

from __future__ import annotations

import json
import lzma
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from warp_critic.core.errors import UserError
from warp_critic.reproduce.engine import ledger, ledger_text, partway
from warp_critic.reproduce.engine.ledger import LEDGER
from warp_critic.reproduce.engine.stage import PROGRESS
from warp_critic.reproduce.engine.stages import (
    MARKER,
    PACKED,
    Check,
    claim_out,
    read_complete,
    read_stage,
)
from warp_critic.running.locks import LOCK


@dataclass(frozen=True)
class CarryRules:
    """What carrying keeps of a stage, told by the stages' owner."""

    check: Check  # what makes a complete record unusable (``stages.read_complete``)
    slim_group: str  # the stage group whose runs are slimmed: checkpoints, metrics
    training_only: tuple[str, ...]  # the checkpoint entries only a resumed training reads
    metrics_keys: tuple[str, ...]  # the columns of ``metrics.jsonl`` kept...
    metrics_row: str  # ...of the rows that hold this one
    record_only: Callable[[dict], bool]  # ``stage.json`` -> publish keeps only the record
    #: ``stage.json``, a run directory relative to its stage (``run/seed3``) -> whether publish keeps
    #: that run's checkpoint (of the slimmed group's stages it keeps whole)
    published_checkpoint: Callable[[dict, str], bool]
    #: the text of the note publish leaves where it drops a checkpoint (``running.rundir.OMITTED``)
    omitted_note: str


#: files never carried
SKIPPED_SUFFIXES = (".rrd",)
SKIPPED_NAMES = (LOCK,)
#: files an archive stores xz-compressed, as ``NAME.xz``
PACKED_SUFFIXES = (".json", ".jsonl")
METRICS = "metrics.jsonl"
ARCHIVE_STARTED = "exists but is not a complete stage; not replacing it"


def complete_stages(folder: Path, check: Check) -> dict[str, dict]:
    """Stage directory name -> ``stage.json`` of every complete stage directly under ``folder``."""
    found = {}
    for d in sorted(Path(folder).iterdir()) if Path(folder).is_dir() else []:
        data = read_stage(d) if d.is_dir() else None
        if data is not None and isinstance(data.get("group"), str):
            read_complete(d, data["group"], check)  # an edited or damaged stage.json: one line
            found[d.name] = data
    return found


#: the entries of a run's checkpoint and config that name its scene file
SCENE_KEYS = ("scene", "scene_path", "scene_file")


#: the entries of a run's config that name its own run directory (written as the user gave it)
OUT_KEYS = ("out",)


def _portable(record: dict, base: Path | None = None) -> dict:
    """``record`` as an archive keeps it, naming no machine's folders: a shipped scene's absolute
    path as ``scenes/NAME`` (a run's scene is found by its content hash wherever it is,
    :func:`~warp_critic.running.scenefile.find_run_scene`), and its run directory (``out``), where
    it is an absolute path inside ``base`` (the reproduce output carried), relative to ``base``
    (``STAGE/run/seed0``; a run is opened by where it lies, never by this entry). A shipped scene
    is a file of this install's ``scenes/`` folder, or an absolute ``.../scenes/NAME`` where NAME
    is one: the run may have trained from another checkout than the one that carries it. (A file
    of another content by that name is refused when the run is read: its content hash differs.)"""
    from warp_critic.physics.scene import scenes_dir

    shipped_dir = scenes_dir().resolve()
    shipped = (
        {p.name for p in shipped_dir.iterdir() if p.is_file()} if shipped_dir.is_dir() else set()
    )
    out = dict(record)
    for key in SCENE_KEYS:
        value = out.get(key)
        if isinstance(value, str) and Path(value).is_absolute():
            path = Path(value)
            if path.resolve().parent == shipped_dir or (
                path.parent.name == "scenes" and path.name in shipped
            ):
                out[key] = f"scenes/{path.name}"
    if base is None:
        return out
    root = base.resolve()
    for key in OUT_KEYS:
        value = out.get(key)
        if isinstance(value, str) and Path(value).is_absolute():
            try:
                out[key] = Path(value).resolve().relative_to(root).as_posix()
            except ValueError:
                pass  # outside the output carried: not this archive's to rename
    return out


def _slim_checkpoint(src: Path, dst: Path, training_only: tuple[str, ...], base: Path) -> None:
    from warp_critic.running.files import atomic_torch_save
    from warp_critic.running.rundir import load_checkpoint_file

    ckpt = load_checkpoint_file(src)
    slim = _portable({k: v for k, v in ckpt.items() if k not in training_only})
    if isinstance(slim.get("config"), dict):
        slim["config"] = _portable(slim["config"], base)
    atomic_torch_save(slim, dst)


def _portable_config(src: Path, base: Path) -> bytes:
    """A run's ``config.json`` with a shipped scene named ``scenes/NAME``; another file as it is."""
    try:
        config = json.loads(src.read_text())
    except (ValueError, UnicodeDecodeError):
        return src.read_bytes()  # not a run's config: carried as it is
    text = json.dumps(_portable(config, base) if isinstance(config, dict) else config, indent=2)
    return (text + "\n").encode()


def thin_metrics(text: str, rules: CarryRules) -> str | None:
    """A run's ``metrics.jsonl`` cut to what a reader of an archive takes from it: the rows that
    hold ``rules.metrics_row``, with only the columns ``rules.metrics_keys``. ``None`` for a run
    without such rows: the file is not carried."""
    rows = [json.loads(line) for line in text.splitlines() if line.strip()]
    keys = rules.metrics_keys
    kept = [{k: r[k] for k in keys if k in r} for r in rows if rules.metrics_row in r]
    return "".join(json.dumps(r) + "\n" for r in kept) if kept else None


def _pack(data: bytes) -> bytes:
    # preset 9: the stage records are written once and read rarely; the output is deterministic
    return lzma.compress(data, preset=9)


def _copy_stage(src: Path, dst_parent: Path, slim: CarryRules | None, pack: bool) -> None:
    """``src`` -> ``dst_parent/src.name`` through a temporary sibling renamed into place; ``slim``:
    checkpoints and metrics cut to what is read, by these rules (a stage of their slimmed group);
    ``pack``: JSON stored
    compressed (into an archive); else a packed file is unpacked (out of one)."""
    from warp_critic.running.files import atomic_write_bytes

    final = dst_parent / src.name
    tmp = dst_parent / f".carrying-{src.name}"
    if tmp.exists():
        shutil.rmtree(tmp)  # what an interrupted call of ours left; never a stage
    try:
        for path in sorted(src.rglob("*")):
            rel = path.relative_to(src)
            if (
                path.is_dir()
                or path.name in SKIPPED_NAMES
                or path.suffix in SKIPPED_SUFFIXES
                or rel.parts[0] == PROGRESS
            ):
                continue
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            if slim and path.name == "checkpoint.pt":
                _slim_checkpoint(path, target, slim.training_only, src.parent)
                continue
            if slim and path.name == "config.json":
                data = _portable_config(path, src.parent)
            elif slim and path.name == METRICS:
                thin = thin_metrics(path.read_text(), slim)
                if thin is None:
                    continue
                data = thin.encode()
            else:
                data = path.read_bytes()
            if pack and path.suffix in PACKED_SUFFIXES:
                atomic_write_bytes(target.with_name(target.name + PACKED), _pack(data))
            elif not pack and path.suffix == PACKED and Path(path.stem).suffix in PACKED_SUFFIXES:
                atomic_write_bytes(target.with_name(path.stem), lzma.decompress(data))
            else:
                atomic_write_bytes(target, data)
        tmp.rename(final)
    except (OSError, lzma.LZMAError) as e:
        shutil.rmtree(tmp, ignore_errors=True)
        why = e.strerror if isinstance(e, OSError) and e.strerror else e
        raise UserError(f"{final}: cannot write ({why})") from None


def copy_stages(
    src: Path,
    dst: Path,
    rules: CarryRules,
    *,
    slim: bool,
    pack: bool,
    started: str,
    only: set[str] | None = None,
) -> list[str]:
    """Copy the complete stages of ``src`` (those named in ``only``, where given) that ``dst``
    lacks; an identical stage there is skipped, a different or unfinished one refused (``started``
    says what an unfinished one is)."""
    have = complete_stages(dst, rules.check)
    copied = []
    for name, data in complete_stages(src, rules.check).items():
        if only is not None and name not in only:
            continue
        if name in have:
            if have[name] != data:
                raise UserError(
                    f"{dst / name}: holds another result of this stage than {src / name}; "
                    "not replacing it"
                )
            continue
        if partway.progress_only(dst / name):
            shutil.rmtree(dst / name)  # an archive's finished batches of it: the stage is done now
        if (dst / name).exists():
            raise UserError(f"{dst / name}: {started}")
        slimmed = rules if slim and data["group"] == rules.slim_group else None
        _copy_stage(src / name, dst, slim=slimmed, pack=pack)
        copied.append(name)
    return copied


@dataclass(frozen=True)
class Carried:
    """What :func:`save` or :func:`restore` copied."""

    stages: list[str]  # complete stages
    partway: list[str]  # stages part way, of which finished batches were copied (:mod:`.partway`)


def save(out: Path, archive: Path, rules: CarryRules) -> Carried:
    """Copy the complete stages of ``out`` into ``archive``, the finished batches of those part
    way (:mod:`~warp_critic.reproduce.engine.partway`), and merge ``out``'s ledger into the
    archive's (:data:`ARCHIVED_LEDGER`)."""
    out, archive = Path(out), Path(archive)
    if not (out / MARKER).is_file():
        raise UserError(f"{out}: not a reproduce output (no {MARKER})")
    complete = complete_stages(out, rules.check)  # an edited stage.json: refused before any write
    try:
        archive.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{archive}: cannot create ({e.strerror or e})") from None
    copied = copy_stages(out, archive, rules, slim=True, pack=True, started=ARCHIVE_STARTED)
    batches = partway.copy_batches(
        out, archive, partway.partway_stages(out, set(complete)), replace=True
    )
    _save_ledger(out, archive)
    return Carried(copied, batches)


def restore(archive: Path, out: Path, rules: CarryRules) -> Carried:
    """Copy the archived stages that ``out`` lacks into ``out``, the archived finished batches of
    the stages part way that ``out`` has not completed, and merge the archive's ledger into
    ``out``'s."""
    archive = Path(archive)
    if not archive.is_dir():
        raise UserError(f"{archive}: no such directory")
    names = [d.name for d in sorted(archive.iterdir()) if partway.progress_only(d)]
    if not (
        complete_stages(archive, rules.check) or names or (archive / ARCHIVED_LEDGER).is_file()
    ):
        raise UserError(f"{archive}: holds no complete reproduce stage")
    out, lock = claim_out(Path(out))
    try:
        copied = copy_stages(
            archive,
            out,
            rules,
            slim=False,
            pack=False,
            started="this stage was started here and is not complete; remove it to take the "
            "archived one",
        )
        done = set(complete_stages(out, rules.check))
        batches = partway.copy_batches(
            archive, out, [n for n in names if n not in done], replace=False
        )
        _restore_ledger(archive, out)
        return Carried(copied, batches)
    finally:
        lock.release()


#: an archive's copy of the ledger of the outputs it was saved from (``ledger.jsonl`` compressed).
#: The calls that completed its stages travel with them: restored, they are stages some call of
#: the ledger ran, never "carried in", and the ledger's wall time counts every sitting of a run
#: resumed on fresh machines from an archive it commits as it goes.
ARCHIVED_LEDGER = LEDGER + PACKED


def _read_packed_ledger(path: Path) -> str:
    try:
        return lzma.decompress(path.read_bytes()).decode("utf-8") if path.is_file() else ""
    except (OSError, lzma.LZMAError, UnicodeDecodeError) as e:
        raise UserError(f"{path}: not a readable packed ledger ({e})") from None


def _save_ledger(out: Path, archive: Path) -> None:
    from warp_critic.running.files import atomic_write_bytes

    if not (out / LEDGER).is_file():
        return
    first = next((r for r in ledger.read(out) if r.get("event") == "start"), {})
    shown = ledger_text.out_as_shown(str(first.get("command", "")), out)
    mine = ledger_text.portable_ledger((out / LEDGER).read_text(encoding="utf-8"), out, shown)
    have = _read_packed_ledger(archive / ARCHIVED_LEDGER)
    merged = ledger_text.merge(have, mine)
    if merged != have:
        atomic_write_bytes(archive / ARCHIVED_LEDGER, _pack(merged.encode("utf-8")))


def _restore_ledger(archive: Path, out: Path) -> None:
    from warp_critic.running.files import atomic_write_bytes

    carried = _read_packed_ledger(archive / ARCHIVED_LEDGER)
    have = (out / LEDGER).read_text(encoding="utf-8") if (out / LEDGER).is_file() else ""
    merged = ledger_text.merge(have, carried)
    if merged != have:
        atomic_write_bytes(out / LEDGER, merged.encode("utf-8"))


def summary(archive: Path, check: Check) -> str:
    """One line per archived stage: name, group, seconds (for the tool's listing)."""
    rows = [
        f"{name}: {data['group']}, {float(data.get('seconds', 0.0)):.0f} s"
        for name, data in complete_stages(Path(archive), check).items()
    ]
    return "\n".join(rows) if rows else f"{archive}: no complete stage"


__all__ = [
    "ARCHIVED_LEDGER",
    "CarryRules",
    "complete_stages",
    "copy_stages",
    "save",
    "restore",
    "summary",
]
