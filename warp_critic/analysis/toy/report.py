"""The toy analysis end to end: loops, closed forms, curves and init sweep; figures, recording, table.

:func:`run_toy` is the entry point (``warp-critic analyze toy``); what the numbers mean: ``docs/toy.md``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warp_critic.analysis import checks
from warp_critic.analysis.toy.closed_forms import closed_form, paper_meta_critic_theta
from warp_critic.analysis.toy.curves import BYTES_PER_POINT, CURVE_KEYS, curves, default_thetas
from warp_critic.analysis.toy.loops import init_sweep, run_meta_critic, run_ours, run_supervised
from warp_critic.analysis.toy.problem import ALPHA, GAMMA, METHODS, T
from warp_critic.analysis.toy.roots import stationary_points
from warp_critic.running.files import save_figure

MAX_ABS = 1e6
"""Largest ``|s0|``, ``|g|``, ``|theta0|``: the fits use ``s^8`` (TD curvature squared), which stays far from
float64 overflow up to here; the loops reproduce the closed forms to ~1e-14 over this range."""
MIN_ABS_S0 = 1e-6
"""Smallest ``|s0|``: at ``s0 = 0`` the supervised fixed point has all critic features zero (undefined fit)."""
MAX_ITERS = 1_000_000


def check_settings(
    *, s0: float, goal: float, theta0: float, alpha: float, plain_lr: float, iters: int, grid: int
) -> None:
    """Validate the settings of :func:`run_toy` before any work (:class:`~warp_critic.core.errors.FieldError`)."""
    s0 = checks.number("s0", s0, max_abs=MAX_ABS)
    if abs(s0) < MIN_ABS_S0:
        raise checks.FieldError(
            "s0",
            f"must be non-zero (|s0| >= {MIN_ABS_S0:g}), got {s0!r}: at s0 = 0 the "
            "supervised fixed point theta = 0 has all critic features (s_t + a_t)^2 = 0 "
            "and the TD fit is undefined there",
        )
    checks.number("goal", goal, max_abs=MAX_ABS)
    checks.number("theta0", theta0, max_abs=MAX_ABS)
    checks.number("alpha", alpha, positive=True, hi=MAX_ABS)
    checks.number("plain_lr", plain_lr, positive=True, hi=MAX_ABS)
    checks.integer("iters", iters, 1, MAX_ITERS)
    checks.integer("grid", grid, 3)
    checks.memory("grid", grid, BYTES_PER_POINT * grid, what=" for the curves")


# ---------------------------------------------------------------------------------------------------
# figures, recording, table
# ---------------------------------------------------------------------------------------------------
_TITLES = {
    "supervised": "Supervised Q learning (Alg. 1)",
    "ours": r"Ours: model-based meta-learned $\mathcal{L}_{critic}$ (Alg. 2)",
    "meta_critic": r"Meta-Critic: $Q_\phi + Q_{meta,\beta}$ (App. A.3)",
}


def _robust_ylim(*arrays, q: float = 0.95, pad: float = 0.1):
    vals = np.concatenate([np.asarray(a)[np.isfinite(a)] for a in arrays])
    lo, hi = np.quantile(vals, 1 - q), np.quantile(vals, q)
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    span = hi - lo if hi > lo else 1.0
    return lo - pad * span, hi + pad * span


def _plot_method(path: Path, method: str, cv: dict, result: dict, s0: float, g: float) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    vkey, gkey = CURVE_KEYS[method]
    th = cv["theta"]
    fig = Figure(figsize=(7.0, 6.5), dpi=110)
    FigureCanvasAgg(fig)
    ax_v, ax_g = fig.subplots(2, 1, sharex=True)
    crit = (
        r"$\sum_{t=0}^{1} \mathcal{L}_{critic}(s_t,\theta) + r_2$"
        if method == "ours"
        else r"$\sum_{t=0}^{1} Q(s_t,\theta) + r_2$"
    )
    ax_v.plot(th, cv["Q_true"], color="k", lw=2, label=r"$Q_{true} = r_2 = (s_0+2\theta-g)^2$")
    # break the line at the pole of our critic (phi* ~ 1/c where c = s0 + s1 + 2 theta changes sign)
    cut = np.flatnonzero(np.sign(cv["c"][:-1]) * np.sign(cv["c"][1:]) < 0) + 1
    ax_v.plot(
        np.insert(th, cut, np.nan),
        np.insert(cv[vkey], cut, np.nan),
        color="C0",
        lw=2,
        label=crit + r", critic fitted at each $\theta$",
    )
    ax_v.plot(
        th,
        cv[vkey + "_fixed"],
        color="C0",
        ls="--",
        lw=1,
        label="critic frozen at the loop's converged value",
    )
    ax_v.set_ylim(*_robust_ylim(cv["Q_true"], cv[vkey]))
    ax_v.set_ylabel("value (cost)")
    ax_v.legend(fontsize=7, loc="upper center")
    ax_v.set_title(f"{_TITLES[method]}   ($s_0={s0:g}$, $g={g:g}$)", fontsize=10)

    ax_g.plot(th, cv["dQ_true"], color="k", lw=2, label=r"$dQ_{true}/d\theta$")
    coef = r"(\phi+\beta)" if method == "meta_critic" else r"\phi"
    ax_g.plot(
        th,
        cv[gkey],
        color="C1",
        lw=2,
        label=r"policy gradient $2\,"
        + coef
        + r"\,(s_0+s_1+2\theta)$, critic fitted at each $\theta$",
    )
    ax_g.plot(
        th, cv[gkey + "_fixed"], color="C1", ls="--", lw=1, label="with the converged critic frozen"
    )
    ax_g.axhline(0.0, color="0.5", lw=0.8)
    for j, (x, kind) in enumerate(result["stationary_points"][method]):
        ax_g.plot(
            [x],
            [0.0],
            marker="o" if kind == "sign change" else "D",
            ms=8,
            mfc="none",
            mec="C3",
            mew=2,
        )
        ax_g.annotate(
            f"{x:.3g} ({kind})",
            (x, 0.0),
            textcoords="offset points",
            xytext=(6, 10 if j % 2 == 0 else -16),
            fontsize=8,
            color="C3",
        )
    opt = result["optimal"]
    for ax in (ax_v, ax_g):
        ax.axvline(opt, color="g", ls=":", lw=1.2, label=r"optimal $\theta^*$")
        ax.axvline(
            result["numerical"][method], color="C3", ls="-.", lw=1.0, label="loop converged to"
        )
    ax_g.set_ylim(*_robust_ylim(cv["dQ_true"], cv[gkey]))
    ax_g.set_xlabel(r"policy parameter $\theta$")
    ax_g.set_ylabel(r"$d/d\theta$")
    ax_g.legend(fontsize=7, loc="upper left")
    fig.subplots_adjust(left=0.1, right=0.97, top=0.94, bottom=0.08, hspace=0.08)
    save_figure(fig, path)


def _blueprint():
    from warp_critic.running.recording import rrb

    cols = []
    for m in METHODS:
        cols.append(
            rrb.Vertical(
                rrb.TimeSeriesView(origin=f"/toy/{m}/value", name=f"{m}: value vs theta_index"),
                rrb.TimeSeriesView(
                    origin=f"/toy/{m}/gradient", name=f"{m}: d/dtheta vs theta_index"
                ),
                rrb.TimeSeriesView(
                    origin=f"/toy/{m}/trace", name=f"{m}: learning trace (timeline 'iteration')"
                ),
            )
        )
    return rrb.Blueprint(rrb.Horizontal(*cols), rrb.TimePanel(timeline="theta_index"))


def _default_recorder(path: Path, blueprint):
    from warp_critic.running.recording import Recorder

    return Recorder(path, application_id="warp-critic-toy", blueprint=blueprint)


def _record(rec, cv: dict, traces: dict, result: dict) -> None:
    colors = {"true": (20, 20, 20), "critic": (31, 119, 180), "fixed": (140, 180, 230)}
    for m in METHODS:
        vkey, gkey = CURVE_KEYS[m]
        for grp, true_name in (("value", "Q_true"), ("gradient", "dQ_true")):
            rec.series_style(f"toy/{m}/{grp}/{true_name}", true_name, colors["true"])
            rec.series_style(
                f"toy/{m}/{grp}/critic", "critic (fitted at each theta)", colors["critic"]
            )
            rec.series_style(
                f"toy/{m}/{grp}/critic_fixed", "critic (frozen at convergence)", colors["fixed"]
            )
    rec.series_style("toy/grid/theta", "theta at theta_index")
    for i, th in enumerate(cv["theta"]):
        rec.set_time("theta_index", i)
        rec.scalar("toy/grid/theta", th)
        for m in METHODS:
            vkey, gkey = CURVE_KEYS[m]
            vals = {
                f"toy/{m}/value/Q_true": cv["Q_true"][i],
                f"toy/{m}/value/critic": cv[vkey][i],
                f"toy/{m}/value/critic_fixed": cv[vkey + "_fixed"][i],
                f"toy/{m}/gradient/dQ_true": cv["dQ_true"][i],
                f"toy/{m}/gradient/critic": cv[gkey][i],
                f"toy/{m}/gradient/critic_fixed": cv[gkey + "_fixed"][i],
            }
            for ent, v in vals.items():
                if np.isfinite(v):
                    rec.scalar(ent, v)
    rec.reset_time()
    for m in METHODS:
        tr = traces[m]
        for k in range(len(tr["theta"])):
            rec.set_time("iteration", k)
            for name, arr in tr.items():
                if k < len(arr) and np.isfinite(arr[k]):
                    rec.scalar(f"toy/{m}/trace/{name}", arr[k])
    rec.reset_time()
    rec.text("toy/summary", result["table_markdown"])


def _format_table(result: dict) -> tuple[str, str]:
    rows = [("method", "closed-form theta", "numerical theta", "optimal theta")]
    for m in METHODS:
        rows.append(
            (
                m,
                f"{result['closed_form'][m]:.6g}",
                f"{result['numerical'][m]:.6g}",
                f"{result['optimal']:.6g}",
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    text = "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows)
    md = (
        "| "
        + " | ".join(rows[0])
        + " |\n|"
        + "---|" * 4
        + "\n"
        + "\n".join("| " + " | ".join(r) + " |" for r in rows[1:])
    )
    return text, md


def run_toy(
    out_dir: Path,
    s0: float = -6.0,
    g: float = 0.0,
    recorder_factory=None,
    *,
    iters: int = 500,
    theta0: float = 0.1,
    alpha: float = ALPHA,
    plain_lr: float = 0.05,
    thetas=None,
    verbose: bool = True,
) -> dict:
    """Run the whole analysis: loops, closed forms, curves, init sweep; write figures and a recording.

    Writes ``out_dir/toy.rrd`` and ``out_dir/toy_{supervised,ours,meta_critic}.png``; prints a table
    (method, closed-form theta, numerical theta, optimal theta) and the init sweep when ``verbose``.
    ``recorder_factory(path, blueprint)`` makes the recorder (default: :class:`warp_critic.running.recording.Recorder`).
    ``iters`` caps every learning loop (the init sweep uses at most 200); ``theta0`` starts the reported
    runs; ``thetas`` is the curve grid (default :func:`default_thetas`).

    Returns a dict with ``closed_form``, ``numerical`` (theta per method), ``critic_params`` (converged
    ``phi`` per method; ``beta`` for the Meta-Critic), ``optimal``, ``stationary_points`` (per method, on the
    fitted-at-each-theta gradient curves), ``init_sweep`` rows, ``paper_meta_critic_theta``, ``files``.
    """
    if thetas is None:
        thetas = default_thetas(s0, g)
    check_settings(
        s0=s0, goal=g, theta0=theta0, alpha=alpha, plain_lr=plain_lr, iters=iters, grid=len(thetas)
    )
    out_dir = checks.out_dir("out", out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cf = closed_form(s0, g)

    th_s, phi_s, tr_s = run_supervised(s0, g, theta0, iters)
    th_o, phi_o, tr_o = run_ours(s0, g, theta0, iters, alpha)
    th_m, phi_m, tr_m = run_meta_critic(s0, g, theta0, iters, alpha)
    beta_m = float(tr_m["beta"][-1])
    traces = {"supervised": tr_s, "ours": tr_o, "meta_critic": tr_m}
    converged = {"supervised": (phi_s, 0.0), "ours": (phi_o, 0.0), "meta_critic": (phi_m, beta_m)}
    cv = curves(s0, g, thetas, alpha, converged=converged)

    result: dict = {
        "s0": float(s0),
        "g": float(g),
        "closed_form": cf,
        "numerical": {"supervised": th_s, "ours": th_o, "meta_critic": th_m},
        "critic_params": {
            "supervised": {"phi": phi_s},
            "ours": {"phi": phi_o},
            "meta_critic": {"phi": phi_m, "beta": beta_m},
        },
        "iterations": {m: len(tr["theta"]) - 1 for m, tr in traces.items()},
        "optimal": cf["optimal"],
        "stationary_points": {
            m: stationary_points(cv["theta"], cv[CURVE_KEYS[m][1]]) for m in METHODS
        },
        "paper_meta_critic_theta": paper_meta_critic_theta(s0),
        "init_sweep": init_sweep(s0, g, iters=min(iters, 200), alpha=alpha, plain_lr=plain_lr),
    }
    text, md = _format_table(result)
    result["table"], result["table_markdown"] = text, md

    result["files"] = _write_outputs(out_dir, cv, traces, result, s0, g, recorder_factory)
    if verbose:
        _print_report(result, s0, g, alpha, iters)
    return result


def _write_outputs(
    out_dir: Path, cv: dict, traces: dict, result: dict, s0: float, g: float, recorder_factory
) -> dict:
    """The figures ``toy_{method}.png`` and the recording ``toy.rrd`` in ``out_dir``: their paths by
    method (and ``rrd``)."""
    files = {m: out_dir / f"toy_{m}.png" for m in METHODS}
    for m in METHODS:
        _plot_method(files[m], m, cv, result, s0, g)
    rrd = out_dir / "toy.rrd"
    factory = recorder_factory or _default_recorder
    rec = factory(rrd, _blueprint())
    try:
        _record(rec, cv, traces, result)
    finally:
        rec.close()
    files["rrd"] = rrd
    return files


def _print_report(result: dict, s0: float, g: float, alpha: float, iters: int) -> None:
    """The table, the stationary points, the paper's Meta-Critic formula and the init sweep."""
    files = result["files"]
    print(f"1-D toy example (s0={s0:g}, g={g:g}, T={T}, gamma={GAMMA:g}, alpha={alpha:g})")
    print(result["table"])
    print(
        "stationary points of the policy gradient (critic fitted at each theta): "
        + "; ".join(
            f"{m}: " + ", ".join(f"{x:.4g} ({k})" for x, k in result["stationary_points"][m])
            for m in METHODS
        )
    )
    print(
        f"paper's printed Meta-Critic formula gives theta = {result['paper_meta_critic_theta']:.4g} "
        f"(not a fixed point; the loop converges to {result['numerical']['meta_critic']:.4g})"
    )
    n_sweep = min(iters, 200)
    print(
        f"init sweep, at most {n_sweep} iterations (theta0 -> theta; '(~fixed point, kind)' when "
        "not within 1e-6 of a listed fixed point):"
    )
    for variant in dict.fromkeys(r["variant"] for r in result["init_sweep"]):
        cells = [
            f"{r['theta0']:.3g}->{r['theta']:.4g}"
            + ("" if r["distance"] < 1e-6 else f"(~{r['nearest']:.3g},{r['kind']})")
            for r in result["init_sweep"]
            if r["variant"] == variant
        ]
        print(f"  {variant:<20} " + "  ".join(cells))
    print(f"wrote {files['rrd']} and {', '.join(str(files[m]) for m in METHODS)}")
