"""Outputs of the landscape analysis: the rerun recording and the PNG figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warp_critic.analysis.landscape.fields import METHODS
from warp_critic.analysis.landscape.problem import analytic_optimum
from warp_critic.running.files import save_figure


def _colormap(values: np.ndarray) -> np.ndarray:
    """``(n1, n2)`` indexed ``[i1, i2]`` -> RGB image, row 0 = largest theta_2 (viridis, min-max)."""
    from matplotlib import colormaps

    v = values.T[::-1]
    lo, hi = float(np.min(v)), float(np.max(v))
    u = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v)
    return (colormaps["viridis"](u)[..., :3] * 255).astype(np.uint8)


def goal_names(G):
    return ["train"] + [f"test{i}" for i in range(1, G)]


def write_recording(
    path, cfg, axis, values, grads, goals, optima, trace_new, ours_loss, sup_loss, fractions
):
    from warp_critic.running.recording import Recorder, rrb

    names = goal_names(len(goals))
    n = axis.size
    rows = [
        rrb.Horizontal(
            *[rrb.Spatial2DView(origin=f"/landscape/{gn}/{m}", name=f"{gn}: {m}") for m in METHODS]
        )
        for gn in names
    ]
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(*rows),
            rrb.Vertical(
                rrb.Spatial2DView(origin="/trace", name="theta_new during meta-training"),
                rrb.TimeSeriesView(origin="/train", name="training losses"),
            ),
            column_shares=[3, 1],
        ),
        rrb.TimePanel(timeline="iteration", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )
    rec = Recorder(path, application_id="warp-critic landscape", blueprint=blueprint)
    try:
        i1, i2 = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        origins = np.stack([i1.ravel() + 0.5, (n - 1 - i2).ravel() + 0.5], 1).astype(np.float32)
        h = axis[1] - axis[0]

        def to_px(theta):
            theta = np.atleast_2d(theta)
            return np.stack(
                [(theta[:, 0] - axis[0]) / h + 0.5, (n - 1) - (theta[:, 1] - axis[0]) / h + 0.5], 1
            )

        for gi, gn in enumerate(names):
            for mi, m in enumerate(METHODS):
                base = f"landscape/{gn}/{m}"
                rec.image(f"{base}/value", _colormap(values[gi, mi]), static=True)
                rec.tensor(
                    f"{base}/raw",
                    values[gi, mi].astype(np.float32),
                    dim_names=["theta_1", "theta_2"],
                    static=True,
                )
                d = -grads[gi, mi].reshape(-1, 2)
                norm = np.linalg.norm(d, axis=1, keepdims=True)
                d = np.where(norm > 0, d / np.maximum(norm, 1e-12), 0.0) * 0.8
                d[:, 1] *= -1  # image rows grow downwards
                rec.arrows2d(
                    f"{base}/descent_direction",
                    origins,
                    d.astype(np.float32),
                    colors=np.array([[255, 255, 255]] * len(d), dtype=np.uint8),
                    static=True,
                )
                rec.points2d(
                    f"{base}/optimum",
                    to_px(optima[gi]).astype(np.float32),
                    colors=[[255, 0, 0]],
                    radii=[0.4],
                    static=True,
                )
                rec.text(f"{base}/fraction", f"descent success fraction: {fractions[gi][m]:.3f}")
        for it in range(trace_new.shape[0]):
            rec.set_time("iteration", it)
            rec.points2d("trace/theta_new", trace_new[it].astype(np.float32), radii=[0.04])
            rec.scalar("trace/theta_1_world0", float(trace_new[it, 0, 0]))
            rec.scalar("trace/theta_2_world0", float(trace_new[it, 0, 1]))
            rec.scalar("train/ours_task_loss", float(ours_loss[it]))
            if it < len(sup_loss):
                rec.scalar("train/sup_td_loss", float(sup_loss[it]))
        rec.reset_time()
        rec.points2d(
            "trace/optimum",
            np.asarray(optima[0], np.float32)[None],
            colors=[[255, 0, 0]],
            radii=[0.1],
            static=True,
        )
    finally:
        rec.close()


def write_figures(
    out: Path, cfg, axis, values, grads, goals, optima, trace_new, init_states, fractions
):
    from matplotlib.figure import Figure  # no pyplot: no global backend or figure state

    names = goal_names(len(goals))
    G = len(goals)
    fig = Figure(figsize=(12, 4 * G))
    axes = fig.subplots(G, 3, squeeze=False)
    T1, T2 = np.meshgrid(axis, axis, indexing="ij")
    ext = [axis[0], axis[-1], axis[0], axis[-1]]
    for gi in range(G):
        for mi, m in enumerate(METHODS):
            ax = axes[gi, mi]
            ax.imshow(values[gi, mi].T, origin="lower", extent=ext, cmap="viridis", aspect="equal")
            d = -grads[gi, mi]
            nrm = np.linalg.norm(d, axis=-1, keepdims=True)
            d = np.where(nrm > 0, d / np.maximum(nrm, 1e-12), 0.0)
            ax.quiver(T1, T2, d[..., 0], d[..., 1], color="white", scale=30, width=0.004)
            ax.plot(*optima[gi], marker="*", color="red", markersize=14)
            ax.set_title(
                f"{m}, goal {names[gi]} g=({goals[gi][0]:g},{goals[gi][1]:g})\n"
                f"descent success {fractions[gi][m]:.2f}",
                fontsize=9,
            )
            ax.set_xlabel("theta_1 (N)")
            ax.set_ylabel("theta_2 (N)")
    fig.tight_layout()
    save_figure(fig, out / "landscape.png", dpi=90)

    fig = Figure(figsize=(6, 6))
    ax = fig.subplots()
    K = trace_new.shape[0]
    colors = np.repeat(np.arange(K), trace_new.shape[1])
    sc = ax.scatter(
        trace_new[..., 0].ravel(), trace_new[..., 1].ravel(), c=colors, cmap="viridis", s=6
    )
    W = trace_new.shape[1]
    per = W // len(init_states)
    for si, s0 in enumerate(init_states):
        th = analytic_optimum(goals[0], s0, cfg.dt, cfg.horizon, cfg.substeps)
        ax.plot(
            *th,
            marker="**^sD"[si % 5],
            color=["red", "orange", "magenta", "cyan", "white"][si % 5],
            markeredgecolor="black",
            markersize=14,
            linestyle="none",
            label=f"theta* from q0=({s0[0]:g},{s0[1]:g})",
        )
    fig.colorbar(sc, ax=ax, label="meta-iteration (dark -> light)")
    ax.set_xlim(axis[0] * 1.5, axis[-1] * 1.5)
    ax.set_ylim(axis[0] * 1.5, axis[-1] * 1.5)
    ax.set_xlabel("theta_1 (N)")
    ax.set_ylabel("theta_2 (N)")
    ax.set_title(
        f"theta_new during meta-training ({per} random inits x {len(init_states)} initial states)"
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "exploration.png", dpi=90)
