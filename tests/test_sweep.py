"""Sweeps (cosymp/sweep.py, `cosymp sweep`): axis and plan checks before any work, the measures
against analytically known values, failing points, identical figures in-process and on a Dask
cluster, progress and cancellation, the output files, and the command line.

Known values: the modulated scene at eps = 0 is the oscillator H = (q^2 + p^2)/2, where a
one-step method is its stability function R(hJ), so the growth of the product of N one-step maps
is exactly ln|R(ih)|/h; inside the principal Mathieu tongue (alpha = 2) the growth is the
Floquet exponent, eps/4 to first order.
"""
import io
import itertools
import math
import os
import re
import time

import numpy as np
import pytest

from cosymp import sweep
from cosymp.cli import main
from cosymp.diagnostics import relative_error
from cosymp.errors import InputError
from cosymp.integrate import MAX_STEPS, Setup, simulate
from cosymp.reference import fine_steps, scipy_reference

RK4_LIMIT = 2 * math.sqrt(2)


def run_cli(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), out=out, err=err)
    return code, out.getvalue(), err.getvalue()


def one_line_error(err):
    return err.startswith("cosymp: ") and err.count("\n") == 1 and "Traceback" not in err


def rk4_factor(h):
    x = 1j * h
    return abs(1 + x + x ** 2 / 2 + x ** 3 / 6 + x ** 4 / 24)


def hs(p, name="h"):
    return np.array(next(a.values for a in p.axes if a.name == name))


def ln_sigma_max(M):
    return math.log(np.linalg.norm(M, 2))


# ------------------------------------------------------------------ axes


def test_linear_axis_values():
    a = sweep.Axis.parse("eps=0:0.4:3")
    assert a.name == "eps" and a.values == (0.0, 0.2, 0.4)
    down = sweep.Axis.parse(" alpha = 3 : 1 : 5 ")
    assert down.name == "alpha" and down.values == pytest.approx((3.0, 2.5, 2.0, 1.5, 1.0), rel=1e-15)
    assert down.values[0] == 3.0 and down.values[-1] == 1.0
    assert sweep.Axis.parse("q0=-2:2:5").values == pytest.approx((-2, -1, 0, 1, 2), rel=0, abs=1e-15)
    assert sweep.Axis.parse("eps=0.3:0.3:1").values == (0.3,)
    assert all(isinstance(v, float) for v in a.values)
    assert sweep.Axis.parse("eps=0:0.8:5").values == (0.0, 0.2, 0.4, 0.6, 0.8), "no 0.6000000000000001"
    assert sweep.Axis.parse("eps=0:0.12345678901234568:2").values[-1] == 0.12345678901234568, "the ends as typed"
    with pytest.raises(InputError, match="not all different at 15 digits"):  # they were rounded into duplicates
        sweep.Axis.parse("eps=1:1.000000000000001:3")
    with pytest.raises(InputError, match="cannot vary 'eps' on scene 'damped'"):  # the name first, then the values
        sweep.plan("damped", "midpoint", ["eps=1:1.000000000000001:3"])
    with pytest.raises(InputError) as info:  # two values passed, equal at 15 digits, as three were refused
        sweep.Axis.parse("gamma=0.1:0.1000000000000001:2")
    assert str(info.value).startswith("gamma: 2 values from 0.1 to 0.1000000000000001 are"), "as typed, not .17g"
    assert sweep.Axis.parse("eps=-0.1:0.2:4").values == (-0.1, 0.0, 0.1, 0.2), "no 1.3877787807814457e-17"
    for spec in ("-0.1:0.5:7", "-0.2:0.5:8"):  # the zero rounded from -1e-17 was written -0.0
        assert all(math.copysign(1, v) > 0 for v in sweep.Axis.parse(f"eps={spec}").values if v == 0), spec
    assert sweep.Axis.parse("x=1e5:100001:3").values == (1e5, 100000.5, 100001.0)
    assert sweep.Axis.parse("h=1e-3:1:4:log").values == (1e-3, 1e-2, 1e-1, 1.0)


def test_log_axis_values():
    a = sweep.Axis.parse("h=0.02:0.16:4:log")
    assert a.values == pytest.approx((0.02, 0.04, 0.08, 0.16), rel=1e-14)
    assert a.values[0] == 0.02 and a.values[-1] == 0.16
    b = sweep.Axis.parse("h=1e-3:1:4:log")
    assert b.values == pytest.approx((1e-3, 1e-2, 1e-1, 1.0), rel=1e-14)
    ratios = np.diff(np.log(b.values))
    assert np.allclose(ratios, math.log(10), rtol=1e-13)


FORM = "NAME=START:STOP:NUM"
BAD_AXES = [
    ("eps", FORM),
    ("eps=0:1", FORM),
    ("eps=0:1:3:4:5", FORM),
    ("eps=0:1:3:lin", FORM),
    ("=0:1:3", FORM),
    ("eps=a:1:3", "start = 'a' is not a number"),
    ("eps=0:b:3", "stop = 'b' is not a number"),
    ("eps=nan:1:3", "finite"),
    ("eps=0:1e999:3", "finite"),
    ("eps=0:1:x", "NUM = 'x' must be a whole number"),
    ("eps=0:1:2.5", "whole number"),
    ("eps=0:1:0", f"between 1 and {sweep.MAX_AXIS}"),
    ("eps=0:1:-3", f"between 1 and {sweep.MAX_AXIS}"),
    (f"eps=0:1:{sweep.MAX_AXIS + 1}", f"between 1 and {sweep.MAX_AXIS}"),
    ("eps=0:1:" + "9" * 5000, "whole number"),
    ("eps=0:1:1", "NUM >= 2 or START = STOP"),
    ("h=0:1:3:log", "START and STOP > 0"),
    ("h=-1:1:3:log", "START and STOP > 0"),
]


@pytest.mark.parametrize("text,words", BAD_AXES, ids=[t[:30] for t, _ in BAD_AXES])
def test_bad_axis_says_what_to_change(text, words):
    with pytest.raises(InputError) as info:
        sweep.Axis.parse(text)
    msg = str(info.value)
    assert words in msg
    assert "\n" not in msg and len(msg) < 300  # one line, user text cut short
    if words != FORM:
        assert msg.startswith(text.partition("=")[0])  # names the axis


# ------------------------------------------------------------------ plan: every check before any work

MOD = ("modulated", "midpoint")
BAD_PLANS = [
    (("nosuch", "midpoint", ["eps=0:1:3"]), {}, "unknown scene"),
    (("modulated", "nosuch", ["eps=0:1:3"]), {}, "unknown method"),
    ((*MOD, []), {}, "nothing to sweep"),
    ((*MOD, ["mass=0:1:3"]), {}, "cannot vary 'mass'"),
    (("charged", "midpoint", ["gauge=0:1:3"]), {}, "cannot vary 'gauge'"),
    (("charged", "midpoint", ["beta=0:1:3"]), {}, "cannot vary 'beta'"),
    ((*MOD, ["theta=0:1:3"]), {}, "theta applies to the methods"),
    ((*MOD, ["eps=0:1:3", "eps=0:1:2"]), {}, "'eps' is varied twice"),
    ((*MOD, ["eps=0:1:3"]), {"measures": ["nosuch"]}, "unknown measure"),
    ((*MOD, ["eps=0:1:3"]), {"measures": []}, "no measure given"),
    (("damped", "exact", ["gamma=0:1:3"]), {"measures": ["growth"]}, "exact flow"),
    (("damped", "exact", ["gamma=0:1:3"]), {"measures": ["det_max_dev"]}, "exact flow"),
    ((*MOD, ["eps=0:1:1001", "alpha=0:1:1000"]), {}, "over the cap"),
    ((*MOD, ["eps=-20:0:3"]), {}, "eps = '-20.0' is outside"),
    ((*MOD, ["eps=0:0.1:3", "alpha=1:200:3"]), {}, "alpha = '200.0' is outside"),
    (("modulated", "theta", ["theta=0:2:3"]), {}, "theta = 2.0 is outside"),
    ((*MOD, ["eps=0:1:3"]), {"theta": 0.3}, "takes no theta"),
    ((*MOD, ["eps=0:1:3"]), {"values": {"mass": 1}}, "no parameter 'mass'"),
    ((*MOD, ["h=1e-9:1e-3:3"]), {"T": 1000.0}, "exceeds the cap"),
    ((*MOD, ["T=10:1e9:3"]), {"h": 1.0}, "exceeds the cap"),
    ((*MOD, ["eps=0:1:3"]), {"T": -1.0}, "T = -1"),
    ((*MOD, ["eps=0:1:3"]), {"h": 0.0}, "must be positive"),
    (("modulated", "boris", ["eps=0:1:3"]), {}, "boris"),
    (("charged", "midpoint", ["T=1:20:3"]), {"values": {"beta": "1/(t-5)"}}, "leaves floating-point range at t = 5"),
]


@pytest.mark.parametrize("args,kwargs,words", BAD_PLANS, ids=[w for *_, w in BAD_PLANS])
def test_bad_plan_is_refused_before_any_work(args, kwargs, words, monkeypatch):
    """Each mistake is an InputError from plan() that says what to change; no point is computed
    (figures is never called)."""
    def no_work(*a, **k):
        raise AssertionError("plan() computed a point")

    monkeypatch.setattr(sweep, "figures", no_work)
    monkeypatch.setattr(sweep, "scan", no_work)
    with pytest.raises(InputError) as info:
        sweep.plan(*args, **kwargs)
    msg = str(info.value)
    assert words in msg and "\n" not in msg


def test_grid_at_the_cap_is_accepted_and_one_over_is_not():
    p = sweep.plan("modulated", "midpoint", ["eps=0:1:1000", "alpha=1:2:1000"])
    assert p.size == sweep.MAX_POINTS and p.shape == (1000, 1000)
    with pytest.raises(InputError, match="over the cap"):
        sweep.plan("modulated", "midpoint", ["eps=0:1:1001", "alpha=1:2:1000"])


def test_over_the_cap_message_states_the_true_grid_size():
    """A grid of 1001 x 1000 = 1,001,000 points must not be reported as '1e+06 points, over the
    cap of 1e+06' (the .3g format rounds the size down to the cap)."""
    with pytest.raises(InputError) as info:
        sweep.plan("modulated", "midpoint", ["eps=0:1:1001", "alpha=1:2:1000"])
    msg = str(info.value)
    assert "1001000" in msg or "1,001,000" in msg or "1.001e+06" in msg, msg


def test_plan_point_order_and_run_of():
    """Flat index in C order (first axis slowest); varied h, T and theta go to the run, scene
    parameters to the setup, fixed values and defaults elsewhere."""
    p = sweep.plan("modulated", "theta", ["theta=0:1:3", "h=0.1:0.2:2", "eps=0:0.2:2"], ["det_max_dev"],
                   values={"alpha": 2.0}, T=4.0)
    assert p.shape == (3, 2, 2) and p.size == 12
    assert p.point(0) == {"theta": 0.0, "h": 0.1, "eps": 0.0}
    assert p.point(1) == {"theta": 0.0, "h": 0.1, "eps": 0.2}
    assert p.point(2) == {"theta": 0.0, "h": 0.2, "eps": 0.0}
    assert p.point(11) == {"theta": 1.0, "h": 0.2, "eps": 0.2}
    setup, h, T = p.run_of(p.point(7))  # theta 0.5, h 0.2, eps 0.2
    assert (setup.theta, h, T) == (0.5, 0.2, 4.0)
    assert setup.values["eps"] == 0.2 and setup.values["alpha"] == 2.0


def test_run_rejects_bad_workers_before_any_work(monkeypatch):
    p = sweep.plan("modulated", "midpoint", ["eps=0:0.1:2"], T=1.0)
    monkeypatch.setattr(sweep, "evaluate", lambda *a, **k: pytest.fail("run() computed a point"))
    for kwargs, words in [({"workers": 2, "scheduler": "tcp://127.0.0.1:1"}, "not both"),
                          ({"workers": 0}, "from 1 to 256"), ({"workers": 257}, "from 1 to 256"),
                          ({"workers": 2.0}, "whole number"), ({"workers": "2"}, "whole number")]:
        with pytest.raises(InputError, match=words):
            sweep.run(p, **kwargs)


# ------------------------------------------------------------------ known values


def test_rk4_growth_is_its_stability_function():
    """ln|R(ih)|/h to round-off, negative below h = 2 sqrt 2 and positive above; det M = |R(ih)|^2."""
    p = sweep.plan("modulated", "rk4", ["h=0.5:3.5:7"], ["growth", "det_max_dev"], {"eps": 0.0}, T=21.0)
    r = sweep.run(p)
    assert np.all(r.status == "ok")
    h = hs(p)
    expected = np.log([rk4_factor(x) for x in h]) / h
    assert r.values["growth"] == pytest.approx(expected, rel=1e-10, abs=1e-14)
    assert np.array_equal(r.values["growth"] > 0, h > RK4_LIMIT)
    det_dev = np.abs(np.array([rk4_factor(x) for x in h]) ** 2 - 1)
    assert r.values["det_max_dev"] == pytest.approx(det_dev, rel=1e-10, abs=1e-14)


def test_explicit_euler_growth_and_determinant():
    """R(ih) = 1 + ih: growth ln(1 + h^2)/(2h) and det M = 1 + h^2 at every step."""
    p = sweep.plan("modulated", "euler", ["h=0.25:4:5:log"], ["growth", "det_max_dev"], {"eps": 0.0}, T=16.0)
    r = sweep.run(p)
    h = hs(p)
    assert r.values["growth"] == pytest.approx(np.log1p(h * h) / (2 * h), rel=1e-12)
    assert r.values["det_max_dev"] == pytest.approx(h * h, rel=1e-12)


@pytest.mark.parametrize("method", ["midpoint", "gauss4"])
def test_implicit_methods_neither_grow_nor_change_volume_at_any_step(method):
    """The Gauss methods are rotations on the oscillator, far beyond any explicit limit; their
    H + p_t stays at round-off too (a quadratic invariant kept exactly)."""
    p = sweep.plan("modulated", method, ["h=0.25:16:4:log"], ["growth", "det_max_dev", "H_ext_max_abs"],
                   {"eps": 0.0}, T=64.0)
    r = sweep.run(p)
    assert np.all(r.status == "ok")
    assert np.max(np.abs(r.values["growth"])) < 1e-12
    assert np.max(r.values["det_max_dev"]) < 1e-13
    assert np.max(r.values["H_ext_max_abs"]) < 1e-13


@pytest.fixture(scope="module")
def mathieu_reference():
    """ln sigma_max of the true flow map over T = 200, from scipy's DOP853 (rtol 1e-12) run from
    the two unit states: the finite-time quantity a sweep's growth converges to, O(1/T) bias
    included, independent of cosymp's integrators."""
    T = 200.0
    out = {}
    for alpha in (2.0, 2.5):
        s = Setup.make("modulated", "rk8", {"eps": 0.2, "alpha": alpha})
        F = np.array([scipy_reference(s, T, z0=e, rtol=1e-12, atol=1e-12).y[:2, -1] for e in np.eye(2)]).T
        out[alpha] = ln_sigma_max(F) / T
    return out


def test_reference_tongue_is_at_the_first_order_rate(mathieu_reference):
    """Inside the tongue the reference is eps/4 = 0.05 within 2 % (first-order theory plus the
    O(ln(cond V)/T) finite-time term); outside it is 20 times smaller (bounded, only O(1/T))."""
    assert mathieu_reference[2.0] == pytest.approx(0.05, rel=0.02)
    assert abs(mathieu_reference[2.5]) < 0.05 / 20


@pytest.mark.parametrize("method,tol_in,tol_out", [("midpoint", 1e-2, 1e-4), ("gauss4", 1e-5, 1e-6)])
def test_mathieu_tongue_growth(method, tol_in, tol_out, mathieu_reference):
    """h = 0.05 to T = 200: the method's growth equals the true flow's finite-time exponent to its
    order (midpoint: relative O(h^2) = 2.5e-3; gauss4: O(h^4)), inside the tongue (alpha = 2) and
    outside it (alpha = 2.5). And it is exactly the method's own map: ln sigma_max of the ensemble
    run from the unit vectors agrees to round-off."""
    T, h = 200.0, 0.05
    p = sweep.plan("modulated", method, ["alpha=2:2.5:2"], ["growth"], {"eps": 0.2}, h=h, T=T)
    r = sweep.run(p)
    inside, outside = r.values["growth"]
    assert inside == pytest.approx(mathieu_reference[2.0], rel=tol_in)
    assert abs(outside - mathieu_reference[2.5]) < tol_out
    for alpha, got in ((2.0, inside), (2.5, outside)):
        z = simulate(Setup.make("modulated", method, {"eps": 0.2, "alpha": alpha}), h, T, z0=np.eye(2)).z[-1]
        assert got == pytest.approx(ln_sigma_max(z) / T, rel=1e-9, abs=1e-13)


def test_damped_growth_undoes_the_internal_scaling():
    """gamma = +-0.5 to T = 2000 (gamma T = 1000: the scaled coordinates' power-of-two exponent
    changes hundreds of times; entries of the map reach e^500): the sweep's growth is that of the
    true map, ln sigma_max of the ensemble run from the unit vectors (columns = images of unit
    vectors), and is |gamma|/2 up to the O(1)/T of the bounded co-moving ellipse; gamma = 0 is the
    plain oscillator, growth 0."""
    T = 2000.0
    p = sweep.plan("damped", "midpoint", ["gamma=-0.5:0.5:3"], ["growth", "det_max_dev"], h=0.1, T=T)
    r = sweep.run(p)
    assert np.all(r.status == "ok")
    for gamma, got in zip(hs(p, "gamma"), r.values["growth"]):
        z = simulate(Setup.make("damped", "midpoint", {"gamma": gamma}), 0.1, T, z0=np.eye(2)).z[-1]
        assert np.all(np.isfinite(z))
        assert got == pytest.approx(ln_sigma_max(z) / T, rel=1e-9, abs=1e-13)
        assert abs(got - abs(gamma) / 2) < 1e-3
    assert r.values["det_max_dev"].max() < 1e-12


@pytest.mark.parametrize("scene", ["damped", "decaying"])
def test_exact_flow_keeps_H_ext_and_has_no_error(scene):
    """The exact flow: |H + p_t| and the error at T are round-off (N exact steps against one exact
    step over T agree to a few ulps per step, not bit for bit)."""
    p = sweep.plan(scene, "exact", ["h=0.05:0.2:4"], ["H_ext_max_abs", "error_final"], T=20.0)
    r = sweep.run(p)
    assert np.all(r.status == "ok")
    assert np.max(r.values["H_ext_max_abs"]) < 1e-13
    assert np.max(r.values["error_final"]) < 1e-12


def test_error_final_where_one_exact_step_over_T_overflows():
    """gamma T = 1000: one exact step over T leaves floating point (every point's error_final was NaN
    with an overflow status) while the state does not (q ~ 1e215, p ~ 1e-218). Each point's error is
    now its distance from 10^4 exact steps of h, to their rounding of the phase (3e-11)."""
    p = sweep.plan("damped", "gauss4", ["gamma=0.9:1:2"], ["error_final"], h=0.1, T=1000.0)
    r = sweep.run(p)
    assert list(r.status) == ["ok", "ok"]
    for gamma, error in zip(hs(p, "gamma"), r.values["error_final"]):
        run, exact = (simulate(Setup.make("damped", m, {"gamma": gamma}), 0.1, 1000.0, stride=10_000).z[-1, 0]
                      for m in ("gauss4", "exact"))
        assert 1e-6 < error < 0.1 and error == pytest.approx(relative_error(run, exact)[0], rel=1e-5)


def test_a_sweeps_reference_is_checked_and_its_refusal_names_the_sweeps_way_out(monkeypatch):
    """A point's error_final runs its reference and the reference's check at twice its step, whose distance
    is the reference's uncertainty, written beside the error (the check was left out for a while to halve
    the cost: then a reference past rk8's stability edge gave an error of 3.47 where it is 0.82, with status
    ok and nothing to say it was not resolved); a reference over the cap named --no-error, which only
    `cosymp run` has."""
    from cosymp import reference

    steps = []
    run = reference.simulate
    monkeypatch.setattr(reference, "simulate", lambda s, h, *a, **kw: steps.append(h) or run(s, h, *a, **kw))
    r = sweep.run(sweep.plan("modulated", "midpoint", ["eps=0:0.1:2"], ["error_final"], h=0.1, T=5.0))
    assert list(r.status) == ["ok", "ok"] and all(np.isfinite(r.values["error_final"]))
    k = reference.refinement(Setup.make("modulated", "midpoint", {}), 0.1)
    assert steps == pytest.approx([0.1 / k, 0.2 / k] * 2), "the reference, then its check, at each point"
    assert (0 < r.values["error_final_uncertainty"]).all() and (r.values["error_final_uncertainty"] < 1e-12).all()
    with pytest.raises(InputError) as info:
        sweep.plan("kapitza", "midpoint", ["T=1e5:3e5:2"], ["error_final"])
    assert str(info.value).endswith("shorten T, or measure something other than error_final")


def test_a_point_whose_reference_fails_keeps_its_run_and_an_unbounded_one_is_not_resolved(tmp_path):
    """beta(t) = exp(t): midpoint reaches T = 8, 8.5 and 9; the reference's check overflows at 8.25 and
    the reference itself at 8.87. T = 9's row said t_final NaN and growth NaN, as if the run had failed;
    T = 8.5's error (3.47, where it is 0.82) was written with status ok and nothing beside it."""
    r = sweep.run(sweep.plan("charged", "midpoint", ["T=8:9:3"], ("growth", "error_final"),
                             values={"beta": "exp(t)"}))
    unc = r.values["error_final_uncertainty"]
    assert list(r.status[:2]) == ["ok", "ok"] and np.isfinite(unc[0]) and unc[1] == np.inf
    assert r.status[2].startswith("the reference for the error at T, rk8 at h/2, leaves floating-point range")
    assert r.status[2].endswith("shorten T to at most 8.867, or measure something other than error_final")
    assert np.isnan(r.values["error_final"][2]) and np.isfinite(r.values["growth"]).all()
    assert r.t_final() == pytest.approx([8.0, 8.5, 9.0])
    text = sweep.summary(r)
    assert "point failed" not in text and "1 point with error_final at most its reference's own uncertainty" in text
    assert "1 point without error_final, the run's other measures kept: its reference failed, e.g.: the" in text
    path = tmp_path / "s.csv"
    sweep.write(r, str(path))
    rows = sweep.read(str(path))
    assert rows["error_final_uncertainty"][1] == math.inf and rows["t_final"][2] == 9.0


@pytest.mark.parametrize("scene,method,order", [
    ("damped", "midpoint", 2), ("damped", "rk4", 4), ("damped", "gauss4", 4),
    ("damped", "symplectic-euler", 1),
    ("modulated", "rk4", 4), ("modulated", "midpoint", 2),
])
def test_error_final_converges_at_the_method_order(scene, method, order):
    """Halving h divides the error at T by 2^p: the fitted slope of log error against log h is p
    (damped: against the exact flow; modulated in the tongue: against rk8)."""
    p = sweep.plan(scene, method, ["h=0.02:0.16:4:log"], ["error_final"], {"eps": 0.2, "alpha": 2.0}
                   if scene == "modulated" else None, T=8.0)
    r = sweep.run(p)
    e = r.values["error_final"]
    assert np.all(r.status == "ok") and np.all(e > 0)
    slope = np.polyfit(np.log(hs(p)), np.log(e), 1)[0]
    assert slope == pytest.approx(order, abs=0.15)


# ------------------------------------------------------------------ failing points


def test_overflowing_point_has_nan_and_says_overflow():
    """rk4 at eps = 0 to T = 2100: h = 2.5 decays, h = 3 grows by |R(3i)|^700 = e^286 (finite),
    h = 3.5 grows by |R(3.5i)| = 3.8 per step and leaves floating point near step
    ln(max double / sqrt 2)/ln|R| = 530 of 600: that point alone is NaN with the overflow message."""
    p = sweep.plan("modulated", "rk4", ["h=2.5:3.5:3"], ["growth", "H_ext_max_abs", "det_max_dev"],
                   {"eps": 0.0}, T=2100.0)
    r = sweep.run(p)
    h = hs(p)
    assert list(r.status[:2]) == ["ok", "ok"]
    assert "overflow" in r.status[2]
    for k in p.measures:
        assert np.all(np.isfinite(r.values[k][:2])) and np.isnan(r.values[k][2])
    assert r.values["growth"][:2] == pytest.approx(np.log([rk4_factor(x) for x in h[:2]]) / h[:2], rel=1e-10)
    limit = math.log(np.finfo(float).max / math.sqrt(2)) / math.log(rk4_factor(3.5))
    step = int(re.search(r"step (\d+)", r.status[2]).group(1))
    assert limit - 9 < step < limit + 1
    text = sweep.summary(r)
    assert re.search(r"\b1 points? failed", text) and "overflow" in text and "3 points (h 3)" in text


# ------------------------------------------------------------------ in-process vs Dask


def mixed_plan():
    """6 x 5 points with every measure, the last h row overflowing (NaN measures, a status)."""
    return sweep.plan("modulated", "rk4", ["h=1:3.5:6", "eps=0:0.04:5"], list(sweep.MEASURES), T=2100.0)


@pytest.fixture(scope="module")
def inprocess():
    p = mixed_plan()
    return p, sweep.run(p)


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    import logging

    # dashboard_address=None still serves the dashboard on :8787 (distributed 2026.8); ":0" takes a
    # free port, so this cluster does not hold 8787 against the one run(p, workers=1) starts
    c = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                 silence_logs=logging.ERROR)
    yield c
    c.close()


def assert_same(a, b):
    assert a.status.shape == b.status.shape
    assert a.status.tolist() == b.status.tolist()
    for k in a.plan.measures:
        assert np.array_equal(a.values[k], b.values[k], equal_nan=True), k


def test_inprocess_threads_equal_a_serial_evaluation(inprocess):
    p, r = inprocess
    assert "this process" in r.where
    indices, cols, statuses, _ = sweep.evaluate(p, range(p.size))
    assert list(indices) == list(range(p.size))
    assert r.status.ravel().tolist() == statuses
    for k in p.measures:
        assert np.array_equal(r.values[k].ravel(), cols[k], equal_nan=True), k
    assert "not computed" not in statuses
    assert sum(s != "ok" for s in statuses) == 5 and all("overflow" in s for s in r.status[-1])
    assert np.all(np.isnan(r.values["growth"][-1])) and np.all(np.isfinite(r.values["growth"][:-1]))


@pytest.mark.slow
def test_dask_cluster_gives_identical_figures(inprocess, cluster):
    p, r = inprocess
    d = sweep.run(p, scheduler=cluster.scheduler_address)
    assert_same(r, d)
    assert d.workers == 2 and cluster.scheduler_address in d.where
    assert len(d.task_seconds) >= 2


@pytest.mark.slow
def test_dask_progress_exception_propagates_and_cluster_stays_usable(cluster):
    p = sweep.plan("modulated", "midpoint", ["eps=0:0.4:4", "alpha=1.8:2.2:5"], ["growth"], T=20.0)

    class Stop(Exception):
        pass

    def progress(done, total, label):
        if done > 2:
            raise Stop

    with pytest.raises(Stop):
        sweep.run(p, scheduler=cluster.scheduler_address, progress=progress)
    assert_same(sweep.run(p), sweep.run(p, scheduler=cluster.scheduler_address))


@pytest.mark.slow
def test_own_local_cluster_gives_identical_figures(inprocess):
    pytest.importorskip("distributed")
    p, r = inprocess
    d = sweep.run(p, workers=1)
    assert_same(r, d)
    assert "LocalCluster" in d.where and d.workers == 1


# ------------------------------------------------------------------ progress and cancellation


def test_progress_reports_increasing_counts_up_to_the_total():
    p = sweep.plan("modulated", "midpoint", ["eps=0:0.4:5", "alpha=1.8:2.2:8"], ["growth"], T=20.0)
    calls = []
    r = sweep.run(p, progress=lambda done, total, label: calls.append((done, total, label)))
    done = [c[0] for c in calls]
    assert done[0] == 0 and done[-1] == p.size == 40
    assert all(b >= a for a, b in itertools.pairwise(done))
    assert all(c[1] == p.size for c in calls) and all(isinstance(c[2], str) for c in calls)
    assert len(calls) >= 3 and np.all(r.status == "ok")


def test_exception_from_progress_stops_the_sweep(monkeypatch):
    """Raising from progress once the parallel phase reports stops the sweep: the exception comes
    out of run(), tasks not started are dropped, so fewer points than the grid's are computed (at
    least one task's fewer; a task's points run as one batch). Each point takes milliseconds (T =
    2000), so that the pool's workers cannot start every task before the stop is seen: with 0.1 ms
    points they had taken five of nine, and on a busy machine they could take all."""
    p = sweep.plan("modulated", "midpoint", ["eps=0:0.4:12", "alpha=1.8:2.2:12"], ["growth"], h=0.05,
                   T=2000.0)
    per = sweep.task_size(p, 1e-3, os.cpu_count() or 1, p.size - 2)
    computed = []
    real = sweep.evaluate

    def counting(*args):
        out = real(*args)
        computed.extend(out[0])
        return out

    monkeypatch.setattr(sweep, "evaluate", counting)

    class Stop(Exception):
        pass

    reports = []

    def progress(done, total, label):
        reports.append(done)
        if done > 2:
            raise Stop

    with pytest.raises(Stop):
        sweep.run(p, progress=progress)
    assert reports[-1] > 2 and sum(d > 2 for d in reports) == 1  # not called again after raising
    assert 2 < len(computed) <= p.size - per
    computed.clear()
    sweep.run(p)
    assert len(computed) == p.size  # the same plan, not stopped, computes every point once


# ------------------------------------------------------------------ files


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_write_read_round_trip(suffix, tmp_path, inprocess):
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    p, r = inprocess
    path = tmp_path / f"sweep{suffix}"
    sweep.write(r, path)
    cols = sweep.read(path)
    assert list(cols) == ["h", "eps", "t_final", *sweep.MEASURES, "error_final_uncertainty", "status"]
    assert all(len(v) == p.size for v in cols.values())
    ends = [math.ceil(p.T / h - 1e-9) * h if ok == "ok" else math.nan for h, ok in zip(cols["h"], cols["status"])]
    assert np.array_equal(np.array(cols["t_final"], float), ends, equal_nan=True) and "ok" in cols["status"]
    idx = np.unravel_index(np.arange(p.size), p.shape)
    assert np.array_equal(cols["h"], np.array(p.axes[0].values)[idx[0]])
    assert np.array_equal(cols["eps"], np.array(p.axes[1].values)[idx[1]])
    for k in (*p.measures, "error_final_uncertainty"):
        assert np.array_equal(np.array(cols[k], dtype=float), r.values[k].ravel(), equal_nan=True), k
    assert cols["status"] == r.status.ravel().tolist()
    if suffix == ".parquet":
        import pyarrow.parquet as pq

        meta = pq.read_schema(path).metadata
        assert meta[b"cosymp.scene"] == b"modulated" and meta[b"cosymp.method"] == b"rk4"
        assert float(meta[b"cosymp.T"]) == 2100.0


@pytest.mark.parametrize("name", ["sweep.txt", "sweep", "sweep.json", "sweep.csv.gz"])
def test_write_refuses_other_formats(name, tmp_path, inprocess):
    with pytest.raises(InputError, match=r"\.csv or \.parquet"):
        sweep.write(inprocess[1], tmp_path / name)
    assert not (tmp_path / name).exists()


# ------------------------------------------------------------------ command line

GRID = ["sweep", "modulated", "--method", "midpoint", "--vary", "eps=0:0.4:3", "--vary", "alpha=1.8:2.2:3",
        "--measure", "growth", "--T", "20"]


def test_cli_sweep_writes_rows_and_summary(tmp_path):
    path = tmp_path / "tmp.csv"
    code, out, err = run_cli(*GRID, "-o", str(path))
    assert code == 0, err
    cols = sweep.read(path)
    assert list(cols) == ["eps", "alpha", "t_final", "growth", "status"] and len(cols["status"]) == 9
    assert cols["status"] == ["ok"] * 9
    assert cols["eps"] == pytest.approx([0.0] * 3 + [0.2] * 3 + [0.4] * 3, rel=1e-15)
    assert cols["alpha"] == pytest.approx([1.8, 2.0, 2.2] * 3, rel=1e-15)
    g = np.array(cols["growth"])
    assert np.max(np.abs(g[:3])) < 1e-12  # eps = 0: the oscillator, midpoint is a rotation
    # det M = 1, so sigma_max >= 1 and growth >= 0; the tongue's centre alpha = 2 grows fastest,
    # and faster for the deeper modulation
    rows = g.reshape(3, 3)
    assert np.all(g > -1e-12)
    assert np.all(rows[1:, 1] > rows[1:, 0]) and np.all(rows[1:, 1] > rows[1:, 2]) and rows[2, 1] > rows[1, 1]
    expected = sweep.run(sweep.plan("modulated", "midpoint", ["eps=0:0.4:3", "alpha=1.8:2.2:3"], ["growth"],
                                    T=20.0))
    assert np.array_equal(g, expected.values["growth"].ravel())
    assert "9 points (eps 3 x alpha 3), h = 0.1, T = 20" in out and "growth: min" in out and f"written to {path}" in out


def test_the_sweep_summary_gives_only_the_step_and_horizon_it_did_not_vary():
    """With h on an axis the summary gave the plan's default h "where not varied", a value no point used."""
    result = sweep.run(sweep.plan("damped", "midpoint", ["h=0.1:0.2:2"], ["growth"], T=5.0))
    head = sweep.summary(result).splitlines()[0]
    assert head.endswith("2 points (h 2), T = 5") and "h =" not in head


BAD_CLI = [
    (["--vary", "eps=0:1"], "NAME=START:STOP:NUM"),
    (["--vary", "eps=0:1:0"], "between 1 and"),
    (["--vary", "gauge=0:1:3"], "cannot vary"),
    (["--vary", "eps=0:1:3", "--measure", "nosuch"], "unknown measure"),
    (["--vary", "eps=0:1:3", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "not allowed with"),
    (["--vary", "eps=0:1:3", "--workers", "0"], "from 1 to 256"),
    (["--vary", "eps=0:1:3", "--theta", "0.3"], "takes no theta"),
    (["--vary", "h=1e-9:1:3", "--T", "1000"], "exceeds the cap"),
    (["--vary", "eps=0:1:3", "--set", "alpha=abc"], "number"),
    (["--vary", "eps=0:1:3", "--set", "eps=0.5"], "both given a fixed value and varied"),
    (["--vary", "h=0.1:0.2:3", "--h", "0.1"], "both given a fixed value and varied"),
    ([], "nothing to sweep"),
]


@pytest.mark.parametrize("extra,words", BAD_CLI, ids=[w for _, w in BAD_CLI])
def test_cli_bad_input_exits_2_with_one_line(extra, words, tmp_path):
    path = tmp_path / "out.csv"
    code, _out, err = run_cli("sweep", "modulated", *extra, "-o", str(path))
    assert code == 2 and one_line_error(err), err
    assert words in err
    assert not path.exists()


def test_cli_wrong_output_suffix_is_refused_before_work(tmp_path):
    code, _, err = run_cli(*GRID, "-o", str(tmp_path / "out.txt"))
    assert code == 2 and one_line_error(err) and ".csv or .parquet" in err


def test_cli_unwritable_output_is_one_line_error(tmp_path):
    """-o naming a folder: a one-line error with exit 2 before any work, not a traceback after the
    whole sweep."""
    folder = tmp_path / "dir.csv"
    folder.mkdir()
    try:
        code, _, err = run_cli(*GRID, "-o", str(folder))
    except OSError as e:
        pytest.fail(f"cosymp sweep -o DIR.csv raised {e!r} instead of exiting 2 with one line")
    assert code == 2 and one_line_error(err), err


@pytest.mark.slow
def test_cli_unreachable_scheduler_is_a_one_line_error(tmp_path):
    """Nothing listens on port 1: a one-line error within the client's 10 s timeout, no hang."""
    pytest.importorskip("distributed")
    start = time.perf_counter()
    code, _, err = run_cli(*GRID, "--scheduler", "tcp://127.0.0.1:1", "-o", str(tmp_path / "x.csv"))
    took = time.perf_counter() - start
    *progress, last = err.splitlines(keepends=True)
    # the first two points are computed here before the cluster is reached: their progress lines come first
    assert code == 2 and one_line_error(last) and all(" done] " in line for line in progress), err
    assert "cannot reach a Dask scheduler at 'tcp://127.0.0.1:1'" in err
    assert took < 30
    assert not (tmp_path / "x.csv").exists()


# ------------------------------------------------------------------ task splitting


@pytest.mark.parametrize("size", [0, 1, 2, 7, 8, 9, 31, 100])
@pytest.mark.parametrize("per", [1, 2, 3, 8, 1000])
def test_split_covers_every_index_once_in_order(size, per):
    tasks = sweep.split(size, per)
    assert [i for t in tasks for i in t] == list(range(size))
    assert all(1 <= len(t) <= per for t in tasks)
    assert all(len(t) == per for t in tasks[:-1])


@pytest.mark.parametrize("seconds", [1e-9, 1e-3, 0.1, 2.0])
@pytest.mark.parametrize("workers", [1, 2, 7])
def test_tasks_cover_the_points_after_the_first_two(seconds, workers):
    p = sweep.plan("modulated", "midpoint", ["eps=0:0.4:7", "alpha=1:2:9"], T=1.0)
    tasks = sweep.tasks_for(p, seconds, workers)
    assert [i for t in tasks for i in t] == list(range(2, p.size))


def test_task_size_by_time_and_by_balance():
    """About TASK_SECONDS of points per task; never below one point; slow points one per task."""
    per = sweep.task_size(None, sweep.TASK_SECONDS / 10, 1, 10_000)
    assert per == 10
    assert sweep.task_size(None, 10 * sweep.TASK_SECONDS, 4, 10_000) == 1
    assert sweep.task_size(None, 0.0, 1, 1) == 1
    for workers in (1, 2, 3, 8):
        for remaining in (1, 50, 1000, 10_000):
            per = sweep.task_size(None, 1e-9, workers, remaining)
            assert per >= 1 and math.ceil(remaining / per) < 2 * sweep.TASKS_PER_WORKER * workers


def test_at_least_tasks_per_worker_while_the_points_allow():
    """The documented balance: at least TASKS_PER_WORKER tasks per worker whenever there are that
    many points (fast points, so the time bound does not limit)."""
    short = []
    for workers in (1, 2, 3, 4, 8):
        for remaining in range(1, 200):
            n = len(sweep.split(remaining, sweep.task_size(None, 1e-9, workers, remaining)))
            if n < min(remaining, sweep.TASKS_PER_WORKER * workers):
                short.append((workers, remaining, n))
    assert short == [], f"(workers, points, tasks) with too few tasks, e.g. {short[:5]}"


def test_max_steps_of_a_corner_is_the_integrator_cap():
    """The plan's step check is the integrator's own cap (T/h = MAX_STEPS is allowed)."""
    p = sweep.plan("modulated", "midpoint", ["h=1:2:2"], T=float(MAX_STEPS))
    assert p.size == 2
    with pytest.raises(InputError, match="exceeds the cap"):
        sweep.plan("modulated", "midpoint", ["h=0.5:2:2"], T=float(MAX_STEPS))


def test_step_counts_come_from_the_h_and_T_axes():
    """Every (h, T) pair's steps, and how many points share each: T/h rounded up, whatever
    else is varied (the app's work cap and memory lease read these)."""
    p = sweep.plan("modulated", "midpoint", ["h=0.1:0.4:4", "eps=0:0.4:3", "T=10:30:3"], ["growth"])
    counts, shared = p.step_counts()
    assert shared == 3 and counts.shape == (4, 3)
    assert counts.tolist() == [[math.ceil(T / h - 1e-9) for T in (10, 20, 30)] for h in (0.1, 0.2, 0.3, 0.4)]
    fixed = sweep.plan("modulated", "midpoint", ["eps=0:0.4:5"], ["growth"], h=0.25, T=10)
    assert fixed.step_counts()[0].tolist() == [[40]] and fixed.step_counts()[1] == 5


def test_a_horizon_that_is_not_a_whole_number_of_steps_says_where_its_runs_ended(tmp_path):
    """A run takes T/h rounded up steps: T = 49.61 ... 49.70 at h = 0.1 all ran to 49.7, and ten
    identical rows were labelled with ten horizons. The rows now carry t_final, and the summary says
    how many points ran past T and by how much."""
    p = sweep.plan("decaying", "midpoint", ["T=49.61:49.70:10"], ("error_final",), h=0.1)
    r = sweep.run(p, workers=None)
    assert np.allclose(r.t_final(), 49.7, rtol=1e-12) and len(set(r.values["error_final"].ravel())) == 1
    assert "9 points ran past T, up to 0.09 beyond it" in sweep.summary(r)
    on_grid = sweep.run(sweep.plan("decaying", "midpoint", ["T=49.6:49.7:2"], ("error_final",), h=0.1))
    assert "past T" not in sweep.summary(on_grid)


def test_a_failed_point_did_not_run_past_t():
    """RK4 at h = 3 and 3.5 leaves its stability limit (2.83) and overflows within a few hundred steps:
    its rows said t_final = T rounded up to whole steps, and the summary counted them among the points
    that ran past T."""
    r = sweep.run(sweep.plan("modulated", "rk4", ["h=2.5:3.5:3"], ("growth",), T=10000.3, values={"eps": 0.0}))
    assert list(r.status == "ok") == [True, False, False]
    assert r.t_final()[0] == pytest.approx(4001 * 2.5) and np.isnan(r.t_final()[1:]).all()
    assert "  1 point ran past T, up to 2.2 beyond it" in sweep.summary(r)


def test_the_reference_cap_is_checked_inside_the_h_axis_not_at_its_corners_only():
    """The reference takes k rk8 steps per step h, k = h / (2% of the time scale) rounded up to an even
    number: at an h axis' middle it can take more steps than at both of its ends, and such a sweep ran
    for minutes before failing there."""
    setup = Setup.make("modulated", "midpoint", {})
    unit = 0.02 * setup.scene.time_scale
    hs_, T = (2 * unit, 3 * unit, 4 * unit), 0.9 * MAX_STEPS * unit
    counts = [fine_steps(setup, h, T) for h in hs_]
    assert counts[0] <= MAX_STEPS and counts[2] <= MAX_STEPS < counts[1], counts  # the premise
    with pytest.raises(InputError, match="over the cap") as info:
        sweep.plan("modulated", "midpoint", [sweep.Axis("h", hs_)], ("error_final",), T=T)
    assert str(info.value).startswith(f"at h = {hs_[1]:.10g} and T = {T:.10g}, the reference for this run")
    assert sweep.plan("modulated", "midpoint", [sweep.Axis("h", hs_)], ("growth",), T=T).size == 3


@pytest.mark.parametrize("values, name", [({"beta": "constant"}, "eps"), ({"beta": "0.05*(1+t)"}, "B0")])
def test_a_name_the_run_does_not_use_is_refused(values, name):
    """eps and w shape only the paper's beta(t), B0 not a typed one: varied there, every row was the
    same run (the app's map already left such axes out)."""
    with pytest.raises(InputError) as info:
        sweep.plan("charged", "midpoint", [f"{name}=0.1:1:3"], values=values)
    assert str(info.value).startswith(f"'{name}' has no effect on scene 'charged'")
    assert sweep.plan("charged", "midpoint", [f"{name}=0.1:1:3"]).size == 3, "with the paper's beta(t) it acts"
