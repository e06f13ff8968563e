"""Stages ``toy`` (section 4.1 / Appendix A) and ``landscape`` (section 4.2, Figures 1 and 2).

Both call the analysis library (:func:`warp_critic.analysis.toy_report.run_toy`,
:func:`warp_critic.analysis.landscape_run.run_landscape`) with the stage directory as output folder and
return the numbers the report shows; file names in the results are relative to the stage directory.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path


def run_toy_stage(d: Path, s: dict) -> dict:
    from ..analysis.toy_curves import default_thetas
    from ..analysis.toy_report import run_toy

    r = run_toy(d, float(s["s0"]), float(s["goal"]), iters=int(s["iters"]), theta0=float(s["theta0"]),
                alpha=float(s["alpha"]), plain_lr=float(s["plain_lr"]),
                thetas=default_thetas(float(s["s0"]), float(s["goal"]), int(s["grid"])), verbose=False)
    return {
        "closed_form": r["closed_form"], "numerical": r["numerical"], "optimal": r["optimal"],
        "stationary_points": {m: [[float(x), str(k)] for x, k in pts] for m, pts in r["stationary_points"].items()},
        "paper_meta_critic_theta": r["paper_meta_critic_theta"], "iterations": r["iterations"],
        "table_markdown": r["table_markdown"],
        "files": {k: Path(v).name for k, v in r["files"].items()},
    }


def run_landscape_stage(d: Path, s: dict, device: str) -> dict:
    from ..analysis.landscape_run import LandscapeConfig, run_landscape
    from ..simulator import resolve_device

    kw = dict(s)
    kw["goal"] = tuple(kw["goal"])
    kw["test_goals"] = tuple(tuple(g) for g in kw["test_goals"])
    kw["init_states"] = tuple(tuple(g) for g in kw["init_states"])
    cfg = LandscapeConfig(out=d, device=resolve_device(device), quiet=True, **kw)
    with contextlib.redirect_stdout(io.StringIO()):
        r = run_landscape(cfg)
    return {
        "goals": r["goals"].tolist(), "goal_names": list(r["goal_names"]), "optima": r["optima"].tolist(),
        "fractions": r["fractions"], "ours_loss_last": float(r["ours_loss"][-1]), "sup_loss_last": float(r["sup_loss"][-1]),
        "files": {"landscape": "landscape.png", "exploration": "exploration.png", "rrd": "landscape.rrd",
                  "arrays": "landscape.npz"},
    }
