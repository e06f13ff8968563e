"""Tests of the 1-D analytic example (section 4.1 / Appendix A): loops vs closed forms, curves, outputs."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from warp_critic.analysis.toy import command as toy
from warp_critic.analysis.toy.closed_forms import (
    closed_form,
    closed_form_critic_params,
    fixed_points,
    paper_meta_critic_theta,
)
from warp_critic.analysis.toy.curves import curves, default_thetas
from warp_critic.analysis.toy.loops import init_sweep, run_meta_critic, run_ours, run_supervised
from warp_critic.analysis.toy.problem import METHODS
from warp_critic.analysis.toy.report import run_toy
from warp_critic.analysis.toy.roots import stationary_points
from warp_critic.core.errors import UserError
from warp_critic.running.recording import read_entity_paths

PAIRS = [(-6.0, 0.0), (1.0, 3.0), (2.0, -2.0), (0.5, 4.0)]
INITS = [0.1, -1.3, 2.7]
RUNNERS = {"supervised": run_supervised, "ours": run_ours, "meta_critic": run_meta_critic}


@pytest.mark.parametrize("s0,g", PAIRS)
def test_closed_forms_are_what_the_formulas_say(s0, g):
    cf = closed_form(s0, g)
    assert set(cf) == {"supervised", "ours", "meta_critic", "optimal"}
    # the optimum minimises Q_true = (s0 + 2 theta - g)^2 ...
    assert (s0 + 2 * cf["optimal"] - g) == pytest.approx(0.0, abs=1e-12)
    # ... the supervised fixed point satisfies theta = -(s0 + s1)/2 with s1 = s0 + theta
    th = cf["supervised"]
    assert th == pytest.approx(-(s0 + (s0 + th)) / 2.0, abs=1e-12)
    assert cf["meta_critic"] == pytest.approx(th)
    assert cf["ours"] == pytest.approx(cf["optimal"])


@pytest.mark.slow
@pytest.mark.parametrize("s0,g", PAIRS)
def test_loops_converge_to_the_closed_forms(s0, g):
    cf = closed_form(s0, g)
    final = {}
    for method, run in RUNNERS.items():
        for theta0 in INITS:
            theta, phi, trace = run(s0, g, theta0=theta0, iters=500)
            assert trace["theta"][0] == theta0
            assert trace["theta"][-1] == theta
            assert len(trace["theta"]) < 500, f"{method} from {theta0} did not converge"
            assert theta == pytest.approx(cf[method], abs=1e-8), (method, theta0)
            final[method, theta0] = theta
    # ours is optimal, supervised Q learning and the Meta-Critic are not (s0 != -3 g for all pairs)
    for theta0 in INITS:
        assert final["ours", theta0] == pytest.approx(cf["optimal"], abs=1e-10)
        assert abs(final["supervised", theta0] - cf["optimal"]) > 0.1
        assert abs(final["meta_critic", theta0] - cf["optimal"]) > 0.1


@pytest.mark.parametrize("s0,g", PAIRS)
def test_converged_critics(s0, g):
    # supervised / Meta-Critic TD critic at theta = -2 s0/3: phi* = ((s0 + 3g)/s0)^2; ours vanishes at the optimum
    _, phi_sup, tr_sup = run_supervised(s0, g)
    assert phi_sup == pytest.approx(((s0 + 3 * g) / s0) ** 2, rel=1e-8)
    _, phi_ours, tr_ours = run_ours(s0, g)
    assert phi_ours == pytest.approx(0.0, abs=1e-10)
    assert tr_ours["cost"][-1] == pytest.approx(0.0, abs=1e-16)
    assert len(tr_ours["theta"]) <= 3  # one iteration to the optimum, one to confirm
    _, phi_m, tr_m = run_meta_critic(s0, g, alpha=0.5)
    assert phi_m == pytest.approx(phi_sup, rel=1e-8)
    # phi + beta = 1 / (4 alpha) along the trace (first 20 iterations: later c -> 0 and the beta fit,
    # whose curvature is ~c^2, loses precision)
    np.testing.assert_allclose(tr_m["phi"][:20] + tr_m["beta"][:20], 0.5, atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("s0,g", PAIRS)
def test_autograd_critic_fits_match_closed_form(s0, g):
    thetas = default_thetas(s0, g, 60)
    cv = curves(s0, g, thetas)
    ref = closed_form_critic_params(s0, g, thetas)
    for key, ref_key in (
        ("supervised_phi", "supervised"),
        ("ours_phi", "ours"),
        ("meta_critic_beta", "meta_critic_beta"),
    ):
        ok = np.isfinite(ref[ref_key])
        assert ok.sum() >= 55
        np.testing.assert_allclose(cv[key][ok], ref[ref_key][ok], rtol=1e-7, atol=1e-9)
    s1, s2 = s0 + thetas, s0 + 2 * thetas
    np.testing.assert_allclose(cv["Q_true"], (s2 - g) ** 2)
    np.testing.assert_allclose(
        cv["supervised_dQ"], 2 * cv["supervised_phi"] * (s0 + s1 + 2 * thetas), atol=1e-9
    )
    # our fitted critic's policy gradient is s0 + 2 theta - g, a quarter of dQ_true/dtheta
    np.testing.assert_allclose(cv["ours_dL"], 0.25 * cv["dQ_true"], rtol=1e-7, atol=1e-9)


def test_stationary_points_helper():
    x = np.linspace(-1.0, 2.0, 300)  # 0 and 1 are not grid points
    pts = stationary_points(x, (x + 0.5) * (x - 1.0) ** 4)  # sign change at -0.5, flat touch at 1
    assert [k for _, k in pts] == ["sign change", "touch"]
    assert pts[0][0] == pytest.approx(-0.5, abs=1e-3)
    assert pts[1][0] == pytest.approx(1.0, abs=0.01)
    xi = (
        np.arange(-100, 201) / 100.0
    )  # contains 1.0 exactly: an exact zero is a touch even if not flat
    assert [k for _, k in stationary_points(xi, (xi + 0.5) * (xi - 1.0) ** 2)] == [
        "sign change",
        "touch",
    ]
    assert stationary_points(x, (x + 0.5) * ((x - 1.0) ** 2 + 0.1)) == [
        (pytest.approx(-0.5, abs=1e-3), "sign change")
    ]
    # a double zero between grid points: found by the parabola through the neighbouring samples
    quad = stationary_points(x, (x + 0.5) * (x - 1.0) ** 2)
    assert [k for _, k in quad] == ["sign change", "touch"] and quad[1][0] == pytest.approx(
        1.0, abs=0.01
    )
    assert stationary_points(x, x + 5.0) == []
    assert len(stationary_points(x, np.sin(6 * x))) == 5  # 6x = k pi, k = -1..3


def test_curves_stationary_points_for_the_paper_example():
    cv = curves(-6.0, 0.0)
    sup = stationary_points(cv["theta"], cv["supervised_dQ"])
    ours = stationary_points(cv["theta"], cv["ours_dL"])
    meta = stationary_points(cv["theta"], cv["meta_critic_dQ"])
    # supervised: zero at theta = 3 (phi* = 0, no sign change) and at theta = 4 (sign change)
    assert len(sup) == 2
    assert sup[0][0] == pytest.approx(3.0, abs=0.01) and sup[0][1] == "touch"
    assert sup[1][0] == pytest.approx(4.0, abs=1e-3) and sup[1][1] == "sign change"
    sign_changes = np.count_nonzero(np.diff(np.sign(cv["supervised_dQ"])) != 0)
    assert sign_changes == 1
    # ours: one stationary point, at the optimum
    assert len(ours) == 1 and ours[0][0] == pytest.approx(3.0, abs=1e-6)
    assert np.count_nonzero(np.diff(np.sign(cv["ours_dL"])) != 0) == 1
    assert len(meta) == 1 and meta[0][0] == pytest.approx(4.0, abs=1e-6)
    # critics frozen at the loops' converged values: supervised phi = 1, ours phi = 0 (= Q_true, zero gradient)
    np.testing.assert_allclose(cv["ours_L_fixed"], cv["Q_true"], atol=1e-9)
    np.testing.assert_allclose(cv["ours_dL_fixed"], 0.0, atol=1e-9)
    fixed = stationary_points(cv["theta"], cv["supervised_dQ_fixed"])
    assert len(fixed) == 1 and fixed[0][0] == pytest.approx(4.0, abs=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("s0,g", PAIRS)
def test_supervised_curve_zeros_are_the_loop_fixed_points(s0, g):
    thetas = default_thetas(s0, g)
    cv = curves(s0, g, thetas)
    step = thetas[1] - thetas[0]
    found = stationary_points(thetas, cv["supervised_dQ"])
    expected = fixed_points(s0, g)["supervised"]
    assert len(found) == len(expected)
    for fp in expected:
        x, kind = min(found, key=lambda f: abs(f[0] - fp["theta"]))
        assert abs(x - fp["theta"]) < step
        assert kind == ("sign change" if fp["kind"] == "attracting" else "touch")
    ours = stationary_points(thetas, cv["ours_dL"])
    assert len(ours) == 1 and ours[0][0] == pytest.approx(closed_form(s0, g)["optimal"], abs=1e-9)


def test_paper_printed_meta_critic_formula_is_not_a_fixed_point():
    s0, g = -6.0, 0.0
    th_paper = paper_meta_critic_theta(s0)
    s1 = s0 + th_paper
    assert th_paper == pytest.approx(
        -(s0 + s1) / (2 * ((s0 + th_paper) ** 2 + (s1 + th_paper) ** 2)), abs=1e-9
    )
    theta, _, trace = run_meta_critic(s0, g, theta0=th_paper)
    assert trace["theta"][1] == pytest.approx(
        -(s0 + s1) / 2.0, abs=1e-9
    )  # jumps to the TD critic's minimiser
    assert abs(trace["theta"][1] - th_paper) > 1.0
    assert theta == pytest.approx(closed_form(s0, g)["meta_critic"], abs=1e-8)


@pytest.mark.slow
def test_degenerate_fixed_points_and_initialisations():
    s0, g = -6.0, 0.0
    # ours: c = 0 makes the inner gradient vanish for every phi -> stays at -2 s0/3 = 4
    assert run_ours(s0, g, theta0=4.0)[0] == pytest.approx(4.0)
    assert run_ours(s0, g, theta0=4.0 + 1e-6)[0] == pytest.approx(3.0)
    # Meta-Critic from 0: 0 -> -s0 (beta* = 0) -> -s0/2 (phi* = 0): stuck at 3
    theta, _, tr = run_meta_critic(s0, g, theta0=0.0)
    assert tr["theta"][1:3] == pytest.approx([6.0, 3.0])
    assert theta == pytest.approx(3.0)
    # supervised with a plain learning rate creeps towards the degenerate point 3 from below, 4 from above
    th_lo = run_supervised(s0, g, theta0=2.0, iters=150, policy_lr=0.05)[0]
    th_hi = run_supervised(s0, g, theta0=6.0, iters=150, policy_lr=0.05)[0]
    assert 2.0 < th_lo < 3.0
    assert th_hi == pytest.approx(4.0, abs=1e-6)
    rows = init_sweep(s0, g, thetas0=[0.0, 2.0, 6.0], iters=60)
    byv = {(r["variant"], r["theta0"]): r for r in rows}
    assert byv[("supervised", 0.0)]["nearest"] == pytest.approx(4.0)
    assert byv[("meta_critic", 0.0)]["kind"] == "degenerate"
    assert byv[("ours", 2.0)]["kind"] == "attracting" and byv[("ours", 2.0)]["distance"] < 1e-9


@pytest.mark.slow
def test_run_toy_writes_outputs(tmp_path, capsys):
    res = run_toy(tmp_path)
    out = capsys.readouterr().out
    for m in METHODS:
        png = tmp_path / f"toy_{m}.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert m in out
        assert res["numerical"][m] == pytest.approx(res["closed_form"][m], abs=1e-8)
    assert res["optimal"] == pytest.approx(3.0)
    assert res["closed_form"]["supervised"] == pytest.approx(4.0)
    assert "closed-form theta" in out and "numerical theta" in out and "optimal theta" in out
    rrd = tmp_path / "toy.rrd"
    assert rrd.is_file()
    paths = read_entity_paths(rrd)
    for m in METHODS:
        for e in (
            "value/Q_true",
            "value/critic",
            "gradient/critic",
            "gradient/dQ_true",
            "trace/theta",
            "trace/phi",
        ):
            assert f"/toy/{m}/{e}" in paths
    assert "/toy/meta_critic/trace/beta" in paths


def test_cli(tmp_path, monkeypatch):
    parser = argparse.ArgumentParser()
    toy.add_arguments(parser)
    args = parser.parse_args([])
    assert args.s0 == -6.0 and args.goal == 0.0 and str(args.out) == "runs/analysis-toy"
    out = tmp_path / "o"
    calls = []
    monkeypatch.setattr(
        toy, "run_toy", lambda *a, **k: calls.append((a, k)) or {}
    )  # run_toy is tested above
    args = parser.parse_args(
        [
            "--s0",
            "2",
            "--goal",
            "-2",
            "--out",
            str(out),
            "--iters",
            "50",
            "--grid",
            "40",
            "--theta0",
            "0.3",
            "--alpha",
            "0.25",
        ]
    )
    assert toy.run_from_args(args) == 0
    ((a, k),) = calls
    assert a == (out, 2.0, -2.0) and k["iters"] == 50 and k["theta0"] == 0.3 and k["alpha"] == 0.25
    assert len(k["thetas"]) == 40
    bad = [
        (["--iters", "0"], "--iters"),
        (["--s0", "nan"], "--s0"),
        (["--goal", "inf"], "--goal"),
        (["--alpha", "-1"], "--alpha"),
        (["--s0", "0"], "--s0"),
        (["--grid", "2"], "--grid"),
    ]
    for argv, flag in bad:
        with pytest.raises(UserError, match=flag) as err:
            toy.run_from_args(parser.parse_args(argv + ["--out", str(out)]))
        assert "\n" not in str(err.value)
    afile = tmp_path / "file"
    afile.write_text("x")
    with pytest.raises(UserError, match="--out"):
        toy.run_from_args(parser.parse_args(["--out", str(afile)]))


@pytest.mark.parametrize(
    "argv,flag,words",
    [
        (["--s0", "1e300"], "--s0", "within"),
        (["--s0", "1e-9"], "--s0", "non-zero"),
        (["--goal=-1e300"], "--goal", "within"),
        (["--theta0", "inf"], "--theta0", "finite"),
        (["--alpha", "1e300"], "--alpha", "<="),
        (["--plain-lr", "0"], "--plain-lr", "> 0"),
        (["--iters", "10000000000"], "--iters", "<="),
        (["--grid", "1000000000000000"], "--grid", "memory"),
    ],
)
def test_cli_rejects_absurd_values_on_one_line(argv, flag, words, tmp_path, capsys):
    from warp_critic.cli.main import main

    out = tmp_path / "o"
    code = main(["analyze", "toy", "--out", str(out), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and flag in err[0] and words in err[0] and "error" in err[0], err
    assert not out.exists()  # refused before any work


def test_run_toy_validates_its_settings(tmp_path):
    from warp_critic.core.errors import FieldError

    with pytest.raises(FieldError) as err:
        run_toy(tmp_path / "o", 1e300, 0.0)
    assert err.value.field == "s0"
    with pytest.raises(FieldError) as err:
        run_toy(tmp_path / "o", -6.0, 0.0, thetas=[0.0, 1.0])
    assert err.value.field == "grid"
    assert not (tmp_path / "o").exists()
