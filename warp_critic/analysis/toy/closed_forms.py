"""Closed forms of the toy (section 4.1 / Appendix A): fixed points of the three loops, the converged
critic parameters, and the paper's printed Meta-Critic formula. Derivations and errata: ``docs/toy.md``."""

from __future__ import annotations

import numpy as np

from warp_critic.analysis.toy.problem import ALPHA


def closed_form(s0: float, g: float) -> dict[str, float]:
    """Fixed points (policy parameters) of the three learning loops, and the optimum, in closed form.

    Returns ``{'supervised': -2 s0/3, 'ours': (g - s0)/2, 'meta_critic': -2 s0/3, 'optimal': (g - s0)/2}``
    (the Meta-Critic value differs from the paper's printed formula, :func:`paper_meta_critic_theta`).
    """
    s0, g = float(s0), float(g)
    return {
        "supervised": -2.0 * s0 / 3.0,
        "ours": (g - s0) / 2.0,
        "meta_critic": -2.0 * s0 / 3.0,
        "optimal": (g - s0) / 2.0,
    }


def closed_form_critic_params(
    s0: float, g: float, thetas, alpha: float = ALPHA
) -> dict[str, np.ndarray]:
    """Converged critic parameters on the rollout of ``pi_theta``, in closed form, for each ``theta``.

    ``supervised``: ``phi* = s_2^2 r_2 / ((s_1^2 - s_2^2)^2 + s_2^4)``; ``ours``:
    ``phi* = (s_0 + 2 theta - g) / (4 alpha c)``; ``meta_critic_beta``: ``1/(4 alpha) - phi*_sup``.
    Degenerate rollouts (flat objective) give ``nan``.
    """
    th = np.asarray(thetas, dtype=np.float64)
    s1, s2 = s0 + th, s0 + 2 * th
    r2 = (s2 - g) ** 2
    c = s0 + s1 + 2 * th
    with np.errstate(divide="ignore", invalid="ignore"):
        den = (s1**2 - s2**2) ** 2 + s2**4
        phi_sup = np.where(den > 0, s2**2 * r2 / np.where(den > 0, den, 1.0), np.nan)
        phi_ours = np.where(c != 0, (s2 - g) / (4 * alpha * np.where(c != 0, c, 1.0)), np.nan)
        beta = np.where((phi_sup != 0) & (c != 0), 1.0 / (4 * alpha) - phi_sup, np.nan)
    return {
        "supervised": phi_sup,
        "ours": phi_ours,
        "meta_critic_phi": phi_sup,
        "meta_critic_beta": beta,
    }


def fixed_points(s0: float, g: float) -> dict[str, list[dict]]:
    """All fixed points of the three loops: ``{method: [{'theta', 'kind', 'why'}, ...]}``.

    ``kind`` is ``'attracting'`` (reached from generic initialisations by the default solvers) or
    ``'degenerate'`` (the update vanishes because the fitted critic gives no gradient; reached only
    from that exact point, or -- supervised with a plain learning rate -- crept towards from one side).
    Coinciding points are listed once.
    """
    cf = closed_form(s0, g)
    a, opt, z = cf["supervised"], cf["optimal"], -float(s0) / 2.0

    def dedup(items):
        out = []
        for it in items:
            if not any(abs(it["theta"] - o["theta"]) < 1e-12 for o in out):
                out.append(it)
        return out

    return {
        "supervised": dedup(
            [
                {
                    "theta": a,
                    "kind": "attracting",
                    "why": "c = s0 + s1 + 2 theta = 0 (minimiser of the fitted Q)",
                },
                {"theta": opt, "kind": "degenerate", "why": "r2 = 0 => phi* = 0 (optimal)"},
                {"theta": z, "kind": "degenerate", "why": "s2 = 0 => phi* = 0"},
            ]
        ),
        "ours": dedup(
            [
                {
                    "theta": opt,
                    "kind": "attracting",
                    "why": "L_task = 0 after one inner step (optimal)",
                },
                {
                    "theta": a,
                    "kind": "degenerate",
                    "why": "c = 0: inner gradient is 0 for every phi",
                },
            ]
        ),
        "meta_critic": dedup(
            [
                {
                    "theta": a,
                    "kind": "attracting",
                    "why": "c = 0 (updated policy minimises the TD critic)",
                },
                {
                    "theta": opt,
                    "kind": "degenerate",
                    "why": "phi* = 0 (r2 = 0): l flat in beta; fixed only with beta = 0",
                },
                {
                    "theta": z,
                    "kind": "degenerate",
                    "why": "phi* = 0 (s2 = 0): l flat in beta; fixed only with beta = 0",
                },
            ]
        ),
    }


def nearest_fixed_point(theta: float, fps: list[dict]) -> tuple[dict, float]:
    """The listed fixed point closest to ``theta`` and its distance."""
    best = min(fps, key=lambda f: abs(f["theta"] - theta))
    return best, abs(best["theta"] - theta)


def paper_meta_critic_theta(s0: float) -> float:
    """The paper's printed Meta-Critic "fixed point" (Appendix A.3), solved for ``theta``.

    ``theta = -(s0 + s1) / (2 [(s0 + a)^2 + (s1 + a)^2])`` with ``s1 = s0 + theta``, ``a = theta``, i.e. the
    cubic ``2 theta [(s0 + theta)^2 + (s0 + 2 theta)^2] + 2 s0 + theta = 0``. Returns the real root closest
    to zero. It is *not* a fixed point of the Meta-Critic loop (``docs/toy.md``, errata).
    """
    P = np.polynomial.Polynomial
    th = P([0.0, 1.0])
    poly = 2 * th * ((s0 + th) ** 2 + (s0 + 2 * th) ** 2) + (2 * s0 + th)
    roots = poly.roots()
    real = roots[np.abs(roots.imag) < 1e-9].real
    return float(real[np.argmin(np.abs(real))])
