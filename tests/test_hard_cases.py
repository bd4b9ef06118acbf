"""Hard cases: where the paper's gentle parameters are left behind, each test asserts the
physically (or numerically) right outcome, with a known value where one exists.

The paper's long horizons and 1e7 steps are in test_longrun.py; the app's "Hard cases" presets
open the same settings (test_app_state.py checks that they do).
"""
import math

import numpy as np
import pytest

from conftest import setup
from cosymp.diagnostics import tangent_maps
from cosymp.drive import Drive
from cosymp.errors import RunError
from cosymp.integrate import local_rate, simulate
from cosymp.kernels.loops import vector_field
from cosymp.methods import METHODS
from cosymp.reference import reference_final, scipy_reference
from cosymp.scenes import SCENES

# ------------------------------------------------------------------ explicit stability limits
# The modulated scene at eps = 0 is the oscillator q'' = -q (H = (q^2 + p^2)/2). A one-step method
# is then R(hA), A = J the rotation generator, so each step scales |z| by |R(ih)| exactly.

RK4_LIMIT = 2 * math.sqrt(2)


def amplitude(run):
    return np.hypot(run.q[:, 0, 0], run.p[:, 0, 0])


def rk4_factor(h):
    x = 1j * h
    return abs(1 + x + x ** 2 / 2 + x ** 3 / 6 + x ** 4 / 24)


@pytest.mark.parametrize("h", [0.5, 2.0, 2.8, 2.85, 3.0])
def test_rk4_amplitude_follows_its_stability_function(h):
    """RK4 scales |z| by |R(ih)| per step: below h = 2 sqrt 2 it decays, above it grows, in both
    cases exactly as the stability function says (to 1e-10 after 200 steps)."""
    run = simulate(setup("modulated", "rk4", eps=0.0), h, 200 * h)
    ratio = amplitude(run)[-1] / amplitude(run)[0]
    expected = rk4_factor(h) ** 200
    assert ratio == pytest.approx(expected, rel=1e-10)
    assert (ratio < 1) == (h < RK4_LIMIT)


def test_rk4_beyond_its_limit_blows_up_and_says_where():
    """Just past the limit (h = 2.9) the growth reaches overflow; the run stops with the step and
    time (a few steps before |z| itself would: the stages are up to h^4/24 = 3 times larger), and
    the data up to there stay finite."""
    steps_to_overflow = math.log(np.finfo(float).max / math.sqrt(2)) / math.log(rk4_factor(2.9))
    with pytest.raises(RunError) as info:
        simulate(setup("modulated", "rk4", eps=0.0), 2.9, 2.9 * 2 * steps_to_overflow)
    err = info.value
    assert "overflow" in str(err) and f"step {err.step + 1}" in str(err)
    assert steps_to_overflow - 10 < err.step < steps_to_overflow
    assert np.all(np.isfinite(err.partial.z))


@pytest.mark.parametrize("h", [1e-3, 0.1, 1.0])
def test_explicit_euler_grows_at_every_step_size(h):
    """|1 + ih| = sqrt(1 + h^2) > 1: explicit Euler spirals out at any h, by exactly that factor."""
    run = simulate(setup("modulated", "euler", eps=0.0), h, 100 * h)
    ratio = amplitude(run)[-1] / amplitude(run)[0]
    assert ratio == pytest.approx((1 + h * h) ** 50, rel=1e-11) and ratio > 1


# Every implicit symmetric symplectic method of the registry (midpoint, the theta methods at 1/2,
# Gauss-Legendre, midpoint compositions): on q'' = -q each is a rotation at any step.
ROTATIONS = [m.name for m in METHODS.values()
             if m.preserves == "symplectic" and not m.requires and m.order_at(0.5) % 2 == 0]


@pytest.mark.parametrize("method", ROTATIONS)
@pytest.mark.parametrize("h", [2.9, 10.0, 100.0])
def test_implicit_methods_stay_on_the_circle_at_any_step(method, h):
    """The Cayley-type maps are rotations: |z| is kept to round-off far beyond RK4's limit."""
    run = simulate(setup("modulated", method, eps=0.0), h, 1000 * h)
    a = amplitude(run)
    assert np.max(np.abs(a / a[0] - 1)) < 1e-12


def test_symplectic_euler_is_bounded_below_h_2_and_grows_above():
    """The paper's symplectic Euler is explicit here (separable H): trace 2 - h^2, so it is
    stable exactly for h < 2."""
    bounded = amplitude(simulate(setup("modulated", "symplectic-euler", eps=0.0), 1.9, 1900.0))
    assert bounded.max() / bounded[0] < 1 / math.sqrt(1 - 1.9 ** 2 / 4) + 1e-9
    growing = amplitude(simulate(setup("modulated", "symplectic-euler", eps=0.0), 2.05, 205.0))
    assert growing[-1] / growing[0] > 1e5


# ------------------------------------------------------------------ Mathieu tongue
# q'' + (1 + eps sin(alpha t)) q = 0. At alpha = 2 (the principal tongue) the solution grows
# with Floquet exponent eps/4 to first order (Landau-Lifshitz, Mechanics, sec. 27); at
# alpha = 2.5 with eps = 0.2 it stays bounded.

# Every method of the registry that applies to the scene, but explicit Euler (its false growth has
# its own test below); the theta methods at their default 1/2.
METHODS_FLOQUET = [m.name for m in METHODS.values()
                   if m.refusal(SCENES["modulated"]) is None and m.name != "euler"]


def monodromy(method, eps, alpha, per_period):
    """The method's map over one period 2 pi / alpha (h = period / per_period), from the two unit
    initial states run as an ensemble."""
    period = 2 * math.pi / alpha
    run = simulate(setup("modulated", method, eps=eps, alpha=alpha), period / per_period, period,
                   z0=np.eye(2))
    return run.z[-1].T, period


def reference_monodromy(eps, alpha):
    period = 2 * math.pi / alpha
    s = setup("modulated", "rk8", eps=eps, alpha=alpha)
    cols = [scipy_reference(s, period, z0=e, rtol=1e-13, atol=1e-13).y[:2, -1] for e in np.eye(2)]
    return np.array(cols).T, period


def floquet_exponent(M, period):
    return math.log(max(abs(np.linalg.eigvals(M)))) / period


def test_reference_tongue_matches_the_perturbative_growth_rate():
    """The independent reference (scipy DOP853) puts (0.2, 2) inside the tongue with exponent
    eps/4 = 0.05 (first order: within 2 %), and (0.2, 2.5) outside (|trace| < 2, exponent 0)."""
    inside = floquet_exponent(*reference_monodromy(0.2, 2.0))
    assert inside == pytest.approx(0.05, rel=0.02)
    M, period = reference_monodromy(0.2, 2.5)
    assert abs(np.trace(M)) < 2 and floquet_exponent(M, period) < 1e-9


@pytest.mark.parametrize("method", METHODS_FLOQUET)
def test_methods_agree_the_tongue_grows_at_the_true_rate(method):
    """Inside the tongue every method (64 steps per period) reports growth at the reference's
    exponent, within 2 % (midpoint, symplectic Euler: order 2 and 1 at h = 0.05)."""
    ref = floquet_exponent(*reference_monodromy(0.2, 2.0))
    got = floquet_exponent(*monodromy(method, 0.2, 2.0, 64))
    assert got == pytest.approx(ref, rel=0.02)


@pytest.mark.parametrize("method", METHODS_FLOQUET)
def test_no_method_reports_growth_outside_the_tongue(method):
    """Outside the tongue no method grows: the symplectic ones have |trace| < 2, so eigenvalues on
    the unit circle (exponent 0 to round-off); RK4 and RK8 shrink slightly (det < 1)."""
    M, period = monodromy(method, 0.2, 2.5, 64)
    assert floquet_exponent(M, period) < 1e-12
    run = simulate(setup("modulated", method, eps=0.2, alpha=2.5), period / 64, 200 * period)
    a = amplitude(run)
    assert a[-1000:].max() < 3 * a[:1000].max()


def test_explicit_euler_reports_false_growth_outside_the_tongue():
    """Explicit Euler is the exception, and the reason it is only a reference: outside the tongue
    it grows anyway, at about the oscillator's rate log(1 + h^2)/(2h) = h/2."""
    M, period = monodromy("euler", 0.2, 2.5, 64)
    h = period / 64
    assert floquet_exponent(M, period) == pytest.approx(math.log(1 + h * h) / (2 * h), rel=0.1)


# ------------------------------------------------------------------ stiff field
# beta(t) = B0 (1 + eps sin(w t)) with eps = 10, w = 50: the field reverses 16 times per unit
# time. The system is rotation invariant for any beta(t) (K commutes with rotations), so the
# canonical angular momentum L = x p_y - y p_x is exact, and Gauss methods keep quadratic
# invariants exactly.

STIFF = {"eps": 10.0, "w": 50.0}


def angular_momentum(run):
    return run.q[:, 0, 0] * run.p[:, 0, 1] - run.q[:, 0, 1] * run.p[:, 0, 0]


@pytest.mark.parametrize("B0", [0.05, 5.0])
def test_stiff_field_converges_to_the_reference(B0):
    """At h = 1e-3 the high-order methods agree with scipy's DOP853 (rtol 1e-12) at T = 5, for
    a weak field (slow gyration, fast E) and a strong one (gyration up to 2 e beta / m = 110)."""
    s = setup("charged", "gauss6", B0=B0, **STIFF)
    ref = scipy_reference(s, 5.0, rtol=1e-12, atol=1e-12).y[:4, -1]
    for method in ("gauss6", "rk8"):
        z = simulate(setup("charged", method, B0=B0, **STIFF), 1e-3, 5.0).z[-1, 0]
        assert np.linalg.norm(z - ref) < 1e-7 * np.linalg.norm(ref)


@pytest.mark.parametrize("method", ["midpoint", "gauss4", "gauss6"])
def test_stiff_field_keeps_the_angular_momentum_where_rk4_loses_it(method):
    """h = 0.01 in the strong field (h x gyration 1.1 at peak): the Gauss methods keep L to
    round-off of the state's size; RK4 loses it entirely."""
    run = simulate(setup("charged", method, B0=5.0, **STIFF), 0.01, 20.0)
    L = angular_momentum(run)
    size = np.abs(run.q[:, 0]).max() * np.abs(run.p[:, 0]).max()
    assert np.max(np.abs(L - L[0])) < 1e-12 * size
    rk4 = angular_momentum(simulate(setup("charged", "rk4", B0=5.0, **STIFF), 0.01, 20.0))
    assert np.max(np.abs(rk4 - rk4[0])) > 1.0 * abs(rk4[0])


def test_stiff_field_beyond_rk4_stability_overflows_with_a_message():
    """h = 0.04 (h x gyration 4.4 > 2.83): RK4 blows up and the run says where."""
    with pytest.raises(RunError, match=r"overflow in step \d+ \(from t = "):
        simulate(setup("charged", "rk4", B0=5.0, **STIFF), 0.04, 20.0)


# ------------------------------------------------------------------ damped, large |gamma| T


@pytest.mark.parametrize("gamma", [0.2, -0.2])
def test_damped_runs_across_600_orders_of_magnitude(gamma):
    """gamma T = 1400: e^{gamma t} reaches 1e608, q ~ e^{gamma t/2} reaches 1e304 and p 1e-304
    (or the reverse). The steps are taken in scaled coordinates, so every method runs to T with a
    finite state and a bounded H + p_t. In the co-moving scale (q e^{-gamma t/2}, p e^{gamma t/2})
    every orbit stays an O(1) ellipse like the exact one, and the 4th-order methods stay within
    1e-2 of it after 70,000 steps (midpoint's O(T h^2) phase error is O(1) by then)."""
    T = 7000.0
    ref = simulate(setup("damped", "exact", gamma=gamma), 0.1, T, stride=100)
    big = 0 if gamma > 0 else 1
    assert abs(ref.z[-1, 0, big]) > 1e300 and abs(ref.z[-1, 0, 1 - big]) < 1e-300
    E = np.exp(gamma * ref.t / 2)

    def comoving(run):
        return np.stack([run.z[:, 0, 0] / E, run.z[:, 0, 1] * E], axis=1)

    exact = comoving(ref)
    for method in ("midpoint", "symplectic-euler", "gauss4", "rk4"):
        run = simulate(setup("damped", method, gamma=gamma), 0.1, T, stride=100)
        assert run.steps == 70_000 and np.all(np.isfinite(run.z))
        assert np.all(np.isfinite(run.H_ext)) and np.abs(run.H_ext).max() < 0.5
        size = np.hypot(*comoving(run).T)
        assert 1.2 < size.min() and size.max() < 1.6
        if method in ("gauss4", "rk4"):
            assert np.abs(comoving(run) - exact).max() < 1e-2


def test_damped_with_gamma_zero_is_the_plain_oscillator():
    """No scaling at gamma = 0: the exact flow is a rotation (q0 = p0 = 1, w0 = 1)."""
    run = simulate(setup("damped", "exact", gamma=0.0), 0.1, 100.0)
    assert run.z[-1, 0, 0] == pytest.approx(math.cos(100) + math.sin(100), rel=1e-10)


def test_damped_where_the_state_itself_overflows_says_so():
    """Beyond gamma t / 2 = 709.8 the true q is not a double: every method, and the exact flow,
    stops with the overflow message before t = 7100 (where 2^e itself leaves the exponent range)."""
    for method in ("exact", "midpoint", "rk4"):
        with pytest.raises(RunError, match="left floating-point range") as info:
            simulate(setup("damped", method, gamma=0.2), 0.1, 8000.0, stride=1000)
        assert 7090 < info.value.time < 7100


def damped_closed_form(gamma, t, q0=1.0, p0=1.0):
    """(q, p)(t) of q'' - gamma q' + q = 0 (m = w0 = 1, gamma < 2) with p = e^(-gamma t) q'."""
    W = math.sqrt(1.0 - gamma * gamma / 4)
    C, S, dC, dS = math.cos(W * t), math.sin(W * t) / W, -W * math.sin(W * t), math.cos(W * t)
    a, b = q0, p0 - gamma * q0 / 2  # q = e^(gamma t/2) (a C + b S)
    q = math.exp(gamma * t / 2) * (a * C + b * S)
    dq = math.exp(gamma * t / 2) * (gamma / 2 * (a * C + b * S) + a * dC + b * dS)
    return q, math.exp(-gamma * t) * dq


def test_damped_reference_reaches_where_the_state_does():
    """gamma T = 1000: the exact flow's one-step map over T passes floating point (e^(gamma T/2)
    beyond 709), the state (q ~ 1e215, p ~ 1e-218) does not. reference_final splits its exact
    step, agreeing with the closed form, and with 10^4 exact steps of h to their rounding of the
    phase (3e-11); within range it is still the one exact step, bit for bit."""
    s = setup("damped", "midpoint", gamma=1.0)
    with pytest.raises(RunError, match="left floating-point range"):
        simulate(setup("damped", "exact", gamma=1.0), 1000.0, 1000.0)
    z, spread = reference_final(s, 0.1, 1000.0)
    stepwise = simulate(setup("damped", "exact", gamma=1.0), 0.1, 1000.0, stride=10_000).z[-1]
    assert 1e214 < abs(z[0, 0]) < 1e216 and 1e-219 < abs(z[0, 1]) < 1e-217 and spread[0] == 0.0
    assert z[0] == pytest.approx(damped_closed_form(1.0, 1000.0), rel=1e-10)
    assert z[0] == pytest.approx(stepwise[0], rel=1e-9)
    short = setup("damped", "midpoint", gamma=0.2)
    one_step = simulate(setup("damped", "exact", gamma=0.2), 50.0, 50.0).z[-1]
    assert np.array_equal(reference_final(short, 0.1, 50.0)[0], one_step)


def test_damped_reference_beyond_floating_point_says_where():
    """At gamma = 1 the true q passes 1.8e308 at gamma t / 2 = ln(1.8e308 / |a C + b S|), near t = 1420:
    the reference says so and where, within a step."""
    with pytest.raises(RunError, match=r"the exact flow, leaves floating-point range \(\|z\| > 1.8e308\) at t ≈ 14") as info:
        reference_final(setup("damped", "midpoint", gamma=1.0), 0.1, 1500.0)
    assert 1415 < info.value.time < 1425


def test_a_method_overflowing_before_the_exact_state_is_told_to_reduce_h():
    """Explicit Euler at h = 0.5 and RK4 at h = 2.5 leave floating point at gamma = 1 near t = 982 and
    755, where the exact state is finite (to t = 1420) but one exact step from 0 is not: the
    message says to reduce h, not that no step size helps; midpoint at h = 0.1 passes t = 1300."""
    for method, h in (("euler", 0.5), ("rk4", 2.5)):
        with pytest.raises(RunError, match="reduce h if the solution should stay bounded") as info:
            simulate(setup("damped", method, gamma=1.0), h, 1300.0, stride=1000)
        assert 709 < info.value.time < 1300
    simulate(setup("damped", "midpoint", gamma=1.0), 0.1, 1300.0, stride=1000)
    with pytest.raises(RunError, match="as the exact solution does by then"):
        simulate(setup("damped", "midpoint", gamma=1.0), 0.1, 1500.0, stride=1000)


def test_damped_scaling_matches_the_unscaled_step_to_round_off():
    """Where nothing overflows (gamma t <= 20) the scaled steps agree with a direct check: the
    midpoint equations hold for the unscaled state to round-off."""
    s = setup("damped", "midpoint", gamma=2.0)
    h = 0.1
    run = simulate(s, h, 10.0)
    out = np.empty(3)
    for k in range(0, 100, 7):
        z0, z1 = run.z[k, 0], run.z[k + 1, 0]
        vector_field(s.P, run.t[k] + h / 2, (z0 + z1) / 2, out)
        assert np.allclose(z1 - z0, h * out[:2], rtol=1e-13, atol=1e-14 * np.abs(z1).max())


# ------------------------------------------------------------------ Newton at large h


@pytest.mark.parametrize("h", [0.01, 0.05, 0.1])
def test_newton_on_kapitza_converges_to_round_off_at_large_steps(h):
    """Kapitza with the drive of its preset (a = 0.1, nu = 40: h nu up to 4): every step's state
    solves the midpoint equations z1 - z0 = h f((z0 + z1)/2, t + h/2) to round-off."""
    s = setup("kapitza", "midpoint", q0=3.0)
    run = simulate(s, h, 10.0)
    out = np.empty(3)
    worst = 0.0
    for k in range(run.steps):
        z0, z1 = run.z[k, 0], run.z[k + 1, 0]
        vector_field(s.P, run.t[k] + h / 2, (z0 + z1) / 2, out)
        worst = max(worst, np.max(np.abs(z1 - z0 - h * out[:2])) / max(1.0, np.abs(z1).max()))
    assert worst < 1e-13


def kapitza_rate(s, z, t, h):
    """Kapitza's fastest local rate over the step of h from (z, t), in closed form: the Jacobian of
    (p, -g(t) sin q) is [[0, 1], [-g cos q, 0]], eigenvalues +-sqrt(-g cos q), at local_rate's
    points: q along the explicit Euler step (q + s h p), each at nine times across the step."""
    P = s.P
    q = z[0] + np.linspace(0.0, 1.0, 9)[:, None] * h * z[1]
    g = P.w0 ** 2 - P.a * P.nu ** 2 * np.cos(P.nu * np.linspace(t, t + h, 9))[None, :]
    return float(np.max(np.sqrt(np.abs(g * np.cos(q)))))


@pytest.mark.parametrize("name", ["midpoint", "theta-naive", "gauss4", "gauss6", "composition4", "composition6"])
def test_newton_failure_on_kapitza_says_how_far_to_reduce_h(name):
    """At h = 0.5 with a strong drive (a = 0.3, nu = 40) the implicit equations have no nearby
    solution: the run stops at the first such step, every step before it a converged one. 'Reduce h'
    alone misled there: midpoint at 0.4, 0.3, 0.2 and 0.1 fails sooner (steps 31, 8, 8, 3). The message
    gives the flow's local rate over the failing step (for midpoint, against Kapitza's closed form)
    and an h to try, scaled by how far the method's implicit stages reach (composition6's sub-steps
    of up to 2.3 h: about half of midpoint's): that h runs the whole horizon."""
    s = setup("kapitza", name, a=0.3, nu=40.0, q0=3.0)
    with pytest.raises(RunError) as info:
        simulate(s, 0.5, 100.0, stride=7)
    err = info.value
    part = err.partial
    assert part.steps == err.step and np.all(np.isfinite(part.z)) and part.t[-1] < err.time
    assert f"Newton did not converge in step {err.step + 1} (from t = {err.time:.6g}): the flow's local rate " in str(err)
    rate = float(str(err).split("local rate there is ")[1].split(",")[0])
    if name == "midpoint":  # the state at the failing step's start, from the record 1-6 steps before it
        start = simulate(s, 0.5, err.time).z[-1, 0]
        assert rate == float(f"{kapitza_rate(s, start, err.time, 0.5):.3g}")
        assert local_rate(s, start, err.time, 0.5) == pytest.approx(kapitza_rate(s, start, err.time, 0.5), rel=1e-6)
    times = float(str(err).split(", h times it ")[1].split(";")[0])
    assert times == pytest.approx(0.5 * rate, rel=5e-3) and "; try h below " in str(err)
    below = float(str(err).split("try h below ")[1].split()[0])
    assert below <= (0.5 if name == "composition6" else 1.0) / rate
    run = simulate(s, below, 100.0)
    assert run.t[-1] >= 100.0 and np.all(np.isfinite(run.z))


@pytest.mark.parametrize("method, params, h", [("midpoint", {"q0": 1.0}, 0.125), ("midpoint", {"q0": 1.0}, 0.3),
                                              ("midpoint", {"q0": 3.0, "a": 0.3, "nu": 40.0}, 0.09),
                                              ("gauss4", {"q0": 2.0}, 0.15), ("gauss4", {"q0": 3.0}, 0.5)])
def test_a_tangent_map_converges_wherever_its_step_does(method, params, h):
    """A tangent map's complex step starts its Newton from the real step's solution
    (kernels.families.theta_start, gauss_start). Started from the state, its real part rounded
    otherwise than the real step's and, where Newton converges only barely (h times the flow's
    rate 2-10), it could fail where the step converged: some of these fused runs stopped at a
    tangent map (midpoint at q0 = 3, h = 0.09 in step 265) that simulate stepped past (which ones
    depends on how the compiler contracts the products). Now a map fails only where its own step
    does, and that failure is named the step's."""
    s = setup("kapitza", method, **params)
    n = round(60 / h)
    drive = Drive(s, h, every=1)
    drive.run(n, strict=False)
    assert drive.done == n or drive.failure.startswith(("Newton did not converge in step ", "singular Newton matrix in step "))


def test_a_tangent_map_where_newton_barely_converges_is_the_derivative_of_the_step_taken():
    """Midpoint on kapitza at h = 0.125 (h times the flow's rate about 2.7): each step's map, by
    complex step from the real step's root, against central differences of the step itself. A
    check that the map is the step's derivative, to the differences' accuracy (1e-6 of its size);
    its determinant, 1 for midpoint, to round-off."""
    s = setup("kapitza", "midpoint", q0=1.0)
    traj = simulate(s, 0.125, 2.5)
    M = tangent_maps(traj)
    d = 1e-6
    for k in range(len(traj.t) - 1):
        z = traj.z[k, 0]
        columns = []
        for j in range(2):
            ends = [simulate(s, 0.125, 0.125, z0=(z + sign * d * np.eye(2)[j])[None], t0=traj.t[k], pt0=0.0).z[-1, 0]
                    for sign in (1, -1)]
            columns.append((ends[0] - ends[1]) / (2 * d))
        assert np.abs(M[k] - np.array(columns).T).max() <= 1e-6 * np.abs(M[k]).max()
        assert abs(np.linalg.det(M[k]) - 1) <= 1e-13 * np.abs(M[k]).max() ** 2


def test_a_failing_tangent_map_is_named_as_the_failing_step_it_is():
    """The fused driver forms a step's tangent map (by the step itself, in complex arithmetic)
    before the step: where that Newton fails, the step's own fails too, and the message names the
    step, not the map. Same message as simulate's, with the rate."""
    s = setup("kapitza", "midpoint", a=0.3, nu=40.0, q0=3.0)
    with pytest.raises(RunError) as info:
        simulate(s, 0.5, 100.0)
    drive = Drive(s, 0.5, every=1)
    drive.run(200, strict=False)
    assert drive.failure == str(info.value)
