"""A unit for ``tests/test_executors.py``'s progress test, importable by a spawned worker: it writes
one ``metrics.jsonl`` row (with its ``seconds``) per simulated iteration into two seed runs."""

from __future__ import annotations

import json
import time
from pathlib import Path


def slow_iterations(d: Path, values: dict, pause: float) -> dict:
    runs = [Path(d) / "run" / f"seed{k}" for k in (0, 1)]
    for r in runs:
        r.mkdir(parents=True, exist_ok=True)
    for i in range(values["iterations"]):
        time.sleep(pause)
        for r in runs:
            with open(r / "metrics.jsonl", "a", encoding="utf-8") as f:
                f.write(json.dumps({"iteration": i, "seconds": pause}) + "\n")
    return {"iterations": values["iterations"]}
