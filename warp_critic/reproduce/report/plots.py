"""The report's own figures: Figure 3's training curves and Figure 4's goal maps (matplotlib)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warp_critic.methods import methods
from warp_critic.reproduce.engine.stages import StageRecord
from warp_critic.reproduce.experiments.settings import METHOD_LABELS, present
from warp_critic.reproduce.report.rules import final_training_error
from warp_critic.running.files import save_figure

COLORS = {m.name: m.colour for m in methods()}


def figure(w: float, h: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


def save(fig, path: Path) -> Path:
    fig.tight_layout()
    save_figure(fig, path, dpi=90)
    return path


def log_limits(grids) -> tuple[float, float]:
    """``(lo, hi)`` of a log colour scale over the finite, positive values of several grids."""
    finite = [np.asarray(np.ma.filled(g, np.nan), dtype=float).ravel() for g in grids]
    v = np.concatenate(finite)
    v = v[np.isfinite(v)]
    lo = max(float(v[v > 0].min()) if (v > 0).any() else 1e-6, 1e-8)
    hi = float(v.max()) if v.size else lo
    return lo, max(hi, lo * 1.0001)


def diverged_cmap():
    """viridis, with non-finite cells (a diverged world in the cell) in black."""
    import matplotlib

    return matplotlib.colormaps["viridis"].with_extremes(bad="black")


def plot_metatrain(path: Path, scene: str, recs: dict[str, StageRecord]) -> dict:
    fig = figure(11, 4)
    ax_it, ax_env = fig.subplots(1, 2)
    summary = {}
    for m in present(recs):
        rec = recs.get(m)
        if rec is None:
            continue
        res = rec.data["result"]
        curves = [np.asarray(v["task_loss"]) for v in res["seeds"].values()]
        n = min(len(c) for c in curves)
        y = np.stack([c[:n] for c in curves])
        it = np.arange(n)
        env = (it + 1) * res["env_steps_per_iteration"]
        mean, lo, hi = y.mean(0), y.min(0), y.max(0)
        for ax, x in ((ax_it, it), (ax_env, env)):
            ax.plot(
                x, mean, color=COLORS[m], label=f"{METHOD_LABELS[m]} (mean of {len(curves)} seeds)"
            )
            ax.fill_between(x, lo, hi, color=COLORS[m], alpha=0.2)
        final = np.array([final_training_error(row) for row in y])  # the report's one definition
        summary[m] = {
            "final_mean": float(final.mean()),
            "final_std": float(final.std()),
            "final_per_seed": final.tolist(),
            "iterations": int(n),
            "env_steps": int(env[-1]),
            "first_mean": float(y[:, 0].mean()),
        }
    for ax, xl in ((ax_it, "outer iteration"), (ax_env, "simulated environment steps")):
        ax.set_yscale("log")
        ax.set_xlabel(xl)
        ax.set_ylabel("final squared error ||q_T - g||^2 (rad^2)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ax_it.set_title(
        f"{scene}: training goals, vs iterations (band: min-max over seeds)", fontsize=9
    )
    ax_env.set_title(f"{scene}: vs environment steps", fontsize=9)
    save(fig, path)
    return summary


def plot_goal_maps(path: Path, res: dict) -> None:
    from matplotlib.colors import LogNorm

    ax0, ax1 = np.asarray(res["axis_q1"]), np.asarray(res["axis_q2"])
    shown = present(res["goals"])
    vals = [np.ma.masked_invalid(np.asarray(res["goals"][m]["mse"])) for m in shown]
    lo, hi = log_limits(vals)
    fig = figure(13 * len(shown) / 3, 4.2)
    axes = fig.subplots(1, len(shown))
    tg = np.asarray(res["train_goals"])
    dq0 = (ax0[1] - ax0[0]) / 2 if len(ax0) > 1 else 0.5
    dq1 = (ax1[1] - ax1[0]) / 2 if len(ax1) > 1 else 0.5
    ext = [ax0[0] - dq0, ax0[-1] + dq0, ax1[0] - dq1, ax1[-1] + dq1]
    im = None
    for ax, m, v in zip(axes, shown, vals):
        im = ax.imshow(
            v.T,
            origin="lower",
            extent=ext,
            aspect="auto",
            cmap=diverged_cmap(),
            norm=LogNorm(vmin=lo, vmax=hi),
        )
        ax.plot(tg[:, 0], tg[:, 1], "x", color="red", markersize=10, mew=2, label="training goals")
        ax.set_title(f"{METHOD_LABELS[m]}: mean MSE {res['goals'][m]['mse_mean']:.3g}", fontsize=9)
        ax.set_xlabel("goal q1 (rad)")
        ax.set_ylabel("goal q2 (rad)")
    axes[0].legend(fontsize=7, loc="upper right")
    fig.colorbar(im, ax=list(axes), label="MSE over seeds x inits (rad^2)")
    save_figure(fig, path, dpi=90)
