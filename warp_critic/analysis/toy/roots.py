"""Zeros of a gradient sampled on a grid (the stationary points marked on the toy's curves)."""

from __future__ import annotations

import numpy as np


def stationary_points(
    thetas, grad, rtol: float = 1e-6, vertex_rtol: float = 0.1
) -> list[tuple[float, str]]:
    """Zeros of a gradient sampled on a grid: ``[(theta, kind), ...]`` sorted by ``theta``.

    * ``'sign change'``: neighbouring samples with opposite signs; the root is located by linear
      interpolation (so it is only as accurate as the grid resolves the curve).
    * ``'touch'``: the gradient reaches zero without changing sign (a double/quartic zero, e.g. where the
      fitted critic vanishes). Detected either as samples with ``|grad| <= rtol * max|grad|`` (a run of them
      counts once; it is a sign change if the samples around the run have opposite signs), or as a local
      minimum of ``|grad|`` whose interpolating parabola through the three samples reaches zero or comes
      within ``vertex_rtol`` of the neighbouring values (a non-zero minimum that the grid resolves has its
      vertex near the neighbouring values, ratio ~1). The location is the parabola's vertex.

    Non-finite samples are skipped.
    """
    th = np.asarray(thetas, dtype=np.float64)
    gr = np.asarray(grad, dtype=np.float64)
    keep = np.isfinite(gr)
    th, gr = th[keep], gr[keep]
    n = gr.size
    if n == 0 or float(np.max(np.abs(gr))) == 0.0:
        return []
    tol = rtol * float(np.max(np.abs(gr)))
    sgn = np.sign(np.where(np.abs(gr) <= tol, 0.0, gr))
    out: list[tuple[float, str]] = []
    i = 0
    while i < n:
        if sgn[i] == 0:  # a run of (near-)zero samples: one stationary point
            j = i
            while j + 1 < n and sgn[j + 1] == 0:
                j += 1
            k = i + int(np.argmin(np.abs(gr[i : j + 1])))
            left = sgn[i - 1] if i > 0 else 0
            right = sgn[j + 1] if j + 1 < n else 0
            if i > 0 and j + 1 < n:
                kind = "sign change" if left * right < 0 else "touch"
                x_k = float(th[k])
                if (
                    kind == "touch" and 0 < k < n - 1
                ):  # refine by the vertex of the parabola around the minimum
                    xs = th[k - 1 : k + 2] - th[k]
                    a, b, _ = np.polyfit(xs, gr[k - 1 : k + 2], 2)
                    if a != 0.0 and xs[0] <= -b / (2 * a) <= xs[2]:
                        x_k = float(th[k] - b / (2 * a))
                out.append((x_k, kind))
            i = j + 1
            continue
        if i + 1 < n and sgn[i] * sgn[i + 1] < 0:
            out.append(
                (float(th[i] - gr[i] * (th[i + 1] - th[i]) / (gr[i + 1] - gr[i])), "sign change")
            )
        i += 1
    absg = np.abs(gr)
    last = -10
    for k in range(1, n - 1):
        if not (sgn[k - 1] == sgn[k] == sgn[k + 1] != 0):
            continue
        if absg[k] > absg[k - 1] or absg[k] > absg[k + 1] or k - last <= 2:
            continue
        x = th[k - 1 : k + 2] - th[k]
        a, b, c = np.polyfit(x, gr[k - 1 : k + 2], 2)
        if a == 0.0:
            continue
        xv = -b / (2 * a)
        v = c - b * b / (4 * a)
        if not (x[0] <= xv <= x[2]):
            continue
        if v * gr[k] <= 0 or abs(v) <= vertex_rtol * max(absg[k - 1], absg[k + 1]):
            out.append((float(th[k] + xv), "touch"))
            last = k
    return sorted(out)
