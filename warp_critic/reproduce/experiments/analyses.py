"""Stages ``toy`` (section 4.1 / Appendix A) and ``landscape`` (section 4.2, Figures 1 and 2).

Both call the analysis library (:func:`warp_critic.analysis.toy.report.run_toy`,
:func:`warp_critic.analysis.landscape.run.run_landscape`) with the stage directory as output folder and
return the numbers the report shows; file names in the results are relative to the stage directory.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path


def run_toy_stage(d: Path, s: dict) -> dict:
    from warp_critic.analysis.toy.curves import default_thetas
    from warp_critic.analysis.toy.report import run_toy

    r = run_toy(
        d,
        float(s["s0"]),
        float(s["goal"]),
        iters=int(s["iters"]),
        theta0=float(s["theta0"]),
        alpha=float(s["alpha"]),
        plain_lr=float(s["plain_lr"]),
        thetas=default_thetas(float(s["s0"]), float(s["goal"]), int(s["grid"])),
        verbose=False,
    )
    return {
        "closed_form": r["closed_form"],
        "numerical": r["numerical"],
        "optimal": r["optimal"],
        "stationary_points": {
            m: [[float(x), str(k)] for x, k in pts] for m, pts in r["stationary_points"].items()
        },
        "paper_meta_critic_theta": r["paper_meta_critic_theta"],
        "iterations": r["iterations"],
        "table_markdown": r["table_markdown"],
        "files": {k: Path(v).name for k, v in r["files"].items()},
    }


#: The landscape stage's sub-folder of the closest setting that generalises to unseen goals.
GENERALISING_DIR = "generalising"


def landscape_configs(d: Path, s: dict, device: str):
    """The validated ``(paper, generalising)`` :class:`~warp_critic.analysis.landscape.run.LandscapeConfig` of
    the landscape stage settings ``s``: the paper's setting (every key but ``generalising``) written to ``d``,
    and the same with the ``generalising`` overrides (the closest setting whose critic generalises to unseen
    goals, ``docs/landscape.md``) written to ``d / "generalising"``."""
    from warp_critic.analysis.landscape.run import LandscapeConfig
    from warp_critic.physics.simulator import resolve_device

    kw = dict(s)
    over = dict(kw.pop("generalising", None) or {})
    dev = resolve_device(device)

    def config(values: dict, out: Path):
        v = dict(values)
        for key in ("test_goals", "init_states", "train_goals"):
            if key in v:
                v[key] = tuple(tuple(g) for g in v[key])
        v["goal"] = tuple(v["goal"])
        return LandscapeConfig(out=out, device=dev, quiet=True, **v).validate()

    return config(kw, d), config({**kw, **over}, d / GENERALISING_DIR)


def _landscape_result(r: dict, prefix: str = "") -> dict:
    return {
        "goals": r["goals"].tolist(),
        "goal_names": list(r["goal_names"]),
        "optima": r["optima"].tolist(),
        "fractions": r["fractions"],
        "ours_loss_last": float(r["ours_loss"][-1]),
        "sup_loss_last": float(r["sup_loss"][-1]),
        "files": {
            "landscape": f"{prefix}landscape.png",
            "exploration": f"{prefix}exploration.png",
            "rrd": f"{prefix}landscape.rrd",
            "arrays": f"{prefix}landscape.npz",
        },
    }


def run_landscape_stage(d: Path, s: dict, device: str) -> dict:
    """Both landscape runs of the stage (:func:`landscape_configs`); the paper's results at the top level,
    the generalising setting's under ``generalising`` (with its ``overrides``)."""
    from warp_critic.analysis.landscape.run import run_landscape

    paper, gen = landscape_configs(d, s, device)  # both checked before any work
    with contextlib.redirect_stdout(io.StringIO()):
        r = run_landscape(paper)
        rg = run_landscape(gen)
    out = _landscape_result(r)
    out["generalising"] = {
        **_landscape_result(rg, f"{GENERALISING_DIR}/"),
        "overrides": dict(s.get("generalising") or {}),
    }
    return out
