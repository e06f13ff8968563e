#!/usr/bin/env python
"""Same seed, same numbers: five tiny CLI runs whose every number is fingerprinted, to compare two
checkouts (a refactor, a speed change) to the last bit.

The runs: a reacher meta-train (4 iterations, 2 inner steps, random starts with one home start),
a DDPG and a Meta-Critic run (4 iterations each), and meta-tests of ours and of DDPG. Each writes its
run directory under OUT; ``OUT/fingerprint.json`` then holds every metrics row, every meta-test
number and a SHA-256 of every tensor of every checkpoint.

    python tools/reference_runs.py --out runs/ref-new                     # this checkout
    python tools/reference_runs.py --out runs/ref-old --command 'OTHER/.venv/bin/warp-critic'
    python tools/reference_runs.py --compare runs/ref-old runs/ref-new    # exit 1 unless bit-identical

About 1-2 minutes on a 2-core CPU.
"""

from __future__ import annotations

import hashlib
import json
import math
import shlex
import subprocess
import sys
from pathlib import Path

PROG = "reference_runs"
SCENE = str(Path(__file__).resolve().parents[1] / "scenes" / "reacher.usda")
TASK = ["--horizon", "30", "--seed", "3", "--record-every", "2", "--checkpoint-every", "2"]
RUNS = {
    "ours": [
        "meta-train",
        SCENE,
        "--iterations",
        "4",
        "--inner-steps",
        "2",
        "--start-std",
        "0.3",
        "--home-starts",
        "1",
        *TASK,
    ],
    "ddpg": ["baseline", "ddpg", SCENE, "--iterations", "4", "--warmup-iterations", "1", *TASK],
    "meta-critic": [
        "baseline",
        "meta-critic",
        SCENE,
        "--iterations",
        "4",
        "--warmup-iterations",
        "1",
        *TASK,
    ],
}
TESTS = {
    "ours": ["--num-goals", "3", "--inits", "2", "--goal-std", "0.3"],
    "ddpg": ["--num-goals", "3", "--inits", "2", "--goal-std", "0.3"],
}


def run_all(command: list[str], out: Path) -> dict:
    """Run the five commands with ``command`` (the warp-critic executable) and fingerprint them."""
    if out.exists():
        raise SystemExit(f"{PROG}: error: --out {out} exists; give a new directory")
    out.mkdir(parents=True)
    for name, args in RUNS.items():
        subprocess.run(
            [*command, *args, "--out", str(out / name)], check=True, stdout=subprocess.DEVNULL
        )
    for name, args in TESTS.items():
        subprocess.run(
            [
                *command,
                "meta-test",
                str(out / name),
                *args,
                "--out",
                str(out / f"metatest-{name}.json"),
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    return fingerprint(out)


def fingerprint(out: Path) -> dict:
    import torch

    prints: dict = {}
    for name in RUNS:
        rows = [
            json.loads(line)
            for line in (out / name / "metrics.jsonl").read_text().splitlines()
            if line
        ]
        for row in rows:  # wall-clock fields differ between any two runs
            for key in [k for k in row if _is_time(k)]:
                row.pop(key)
        state = torch.load(out / name / "checkpoint.pt", weights_only=True)
        prints[name] = {"metrics": rows, "checkpoint": _tensor_hashes(state)}
    for name in TESTS:
        result = json.loads((out / f"metatest-{name}.json").read_text())
        prints[f"metatest-{name}"] = _numbers(result)
    (out / "fingerprint.json").write_text(json.dumps(prints, indent=1, sort_keys=True))
    return prints


def _is_time(key: str) -> bool:
    """Wall-clock fields, which differ between any two runs."""
    return "time" in key or "second" in key or key.endswith("_s")


def _tensor_hashes(obj, prefix: str = "") -> dict:
    import torch

    out = {}
    if isinstance(obj, torch.Tensor):
        out[prefix] = hashlib.sha256(obj.detach().contiguous().cpu().numpy().tobytes()).hexdigest()
    elif isinstance(obj, dict):
        for k, v in obj.items():
            out.update(_tensor_hashes(v, f"{prefix}/{k}"))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            out.update(_tensor_hashes(v, f"{prefix}/{i}"))
    return out


def _numbers(obj, prefix: str = "") -> dict:
    """Every number in a JSON document, by its path (times left out)."""
    out = {}
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return out
    if isinstance(obj, (int, float)):
        return {prefix: obj}
    items = obj.items() if isinstance(obj, dict) else enumerate(obj)
    for k, v in items:
        if _is_time(str(k)):
            continue
        out.update(_numbers(v, f"{prefix}/{k}"))
    return out


def compare(a: dict, b: dict) -> tuple[float, list[str]]:
    """Largest relative difference over every number, and the keys present in only one."""
    worst, missing = 0.0, []

    def walk(x, y, path):
        nonlocal worst
        if isinstance(x, dict) and isinstance(y, dict):
            for k in set(x) | set(y):
                if k not in x or k not in y:
                    missing.append(f"{path}/{k}")
                else:
                    walk(x[k], y[k], f"{path}/{k}")
        elif isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
            for i, (u, v) in enumerate(zip(x, y)):
                walk(u, v, f"{path}/{i}")
        elif (
            isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool)
        ):
            if x != y and not (math.isnan(x) and math.isnan(y)):
                worst = max(worst, abs(x - y) / max(abs(x), abs(y), 1e-300))
        elif x != y:
            worst = math.inf
            missing.append(f"{path} ({x!r} != {y!r})"[:200])

    walk(a, b, "")
    return worst, missing


def main(argv: list[str] | None = None) -> int:
    from warp_critic.cli.flags import ToolParser

    parser = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--out", type=Path, help="new directory for the five runs and fingerprint.json"
    )
    parser.add_argument(
        "--command",
        default="warp-critic",
        help="the warp-critic executable to run (quoted, may hold arguments)",
    )
    parser.add_argument(
        "--compare",
        nargs=2,
        type=Path,
        metavar=("A", "B"),
        help="compare two OUT directories; exit 1 unless every number is identical",
    )
    args = parser.parse_args(argv)
    if args.compare:
        for d in args.compare:
            if not (d / "fingerprint.json").is_file():
                parser.error(
                    f"--compare: {d / 'fingerprint.json'} does not exist (run --out {d} first)"
                )
        a, b = (json.loads((d / "fingerprint.json").read_text()) for d in args.compare)
        worst, missing = compare(a, b)
        print(f"maximum relative difference: {worst}; differing or missing entries: {len(missing)}")
        for m in missing[:10]:
            print(f"  {m}")
        return 0 if worst == 0.0 and not missing else 1
    if args.out is None:
        parser.error("give --out or --compare")
    prints = run_all(shlex.split(args.command), args.out)
    print(f"{args.out / 'fingerprint.json'}: {sum(len(v) for v in prints.values())} entries")
    return 0


if __name__ == "__main__":
    sys.exit(main())
