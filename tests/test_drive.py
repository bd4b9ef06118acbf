"""The fused driver (cosymp.drive) against the diagnostics computed in NumPy from recorded runs
(every step recorded, tangent maps formed in a second pass), on every scene x method: a run's
maxima, long runs' envelopes, sweeps' batches and a comparison's per-record figures."""
import math
from fractions import Fraction

import numpy as np
import pytest

from cosymp import drive as drive_module
from cosymp import sweep
from cosymp.diagnostics import (
    det_deviation,
    nearby_states,
    paper_volume_form,
    symplecticity_defect,
    tangent_maps,
)
from cosymp.drive import Drive
from cosymp.errors import RunError
from cosymp.integrate import Setup, simulate
from cosymp.kernels.survey import _least, _most, defects, symplecticity
from cosymp.methods import METHODS
from cosymp.scenes import SCENES
from cosymp.study import compare
from cosymp.summary import long_drive, long_envelopes, run_summary

PAIRS = [(s, m) for s in SCENES for m in METHODS if METHODS[m].refusal(SCENES[s]) is None and m != "exact"]
STEPS = 48
WIDTH = 8


def close(a, b, rel, floor=1e-13):
    """a and b agree to `rel` relative or within `floor` (round-off of quantities near 0)."""
    return abs(a - b) <= floor + rel * abs(b)


def numpy_figures(setup, h, steps, z0=None):
    tr = simulate(setup, h, steps * h, z0=z0, stride=1, increments=True)
    M = tangent_maps(tr)
    return tr, M


@pytest.mark.parametrize("scene,method", PAIRS)
def test_fused_driver_matches_numpy_diagnostics(scene, method):
    s = Setup.make(scene, method)
    h = s.scene.h
    tr, M = numpy_figures(s, h, STEPS)
    d = Drive(s, h, growth=True)
    d.run(STEPS)
    assert d.t == pytest.approx(tr.t[-1], rel=1e-15)
    scale = np.max(np.abs(tr.z))
    assert np.max(np.abs(d.Z[0] - tr.z[-1, 0])) <= 1e-12 * scale
    H = np.abs(tr.H_ext[1:, 0])
    assert close(d.H_ext_max_abs, np.max(H), 1e-8, 1e-14 * max(1.0, np.max(np.abs(tr.H))))
    assert close(d.det_max_dev, np.max(det_deviation(M)), 1e-8)
    assert close(d.symp_max_dev, np.max(symplecticity_defect(M)), 1e-8)
    assert close(d.symp_max_rel, np.max(symplecticity_defect(M, relative=True)), 1e-8)
    # ln sigma_max of the product of every step's map, multiplied out in NumPy (no overflow in 48
    # steps); each map taken back from its step's scaled coordinates: S^-1 M S, S = diag(2^-e, 2^e)
    n = s.scene.ndof
    prod = np.eye(2 * n)
    for t, Mk in zip(tr.t, M):
        e = s.scene.kernel.scaling(s.P, t)
        S = np.diag([2.0 ** -e] * n + [2.0 ** e] * n)
        prod = np.linalg.solve(S, Mk @ S) @ prod
    assert d.growth.log_norm() == pytest.approx(math.log(np.linalg.norm(prod, 2)), abs=1e-10)


@pytest.mark.parametrize("scene,method", PAIRS)
def test_fused_run_takes_the_steps_of_simulate(scene, method):
    """Member steps on every scene, so the states and p_t are simulate's (on a linear scene the fused
    loop stepped by the step matrix, whose p_t quadratic form loses accuracy): to 16 eps of their
    size, as test_a_lone_run_between_events_takes_every_step_and_figure says why (bit for bit
    before the fused loop had a loop of its own for a lone run's quiet steps; since, decaying gauss4
    and gauss6 differ in p_t's last bit and modulated aba864's state by 5.7 eps)."""
    s = Setup.make(scene, method)
    h = s.scene.h
    tr = simulate(s, h, STEPS * h, stride=STEPS)
    d = Drive(s, h, width=WIDTH, growth=True)
    d.run(STEPS)
    _within_eps(d, tr.z[-1], tr.pt[-1], simulate(s, h, STEPS * h, stride=1))


SCALED = [("damped", m, {"gamma": 0.5}) for m in ("euler", "symplectic-euler", "rk4", "midpoint", "leapfrog")]


@pytest.mark.parametrize("scene,method,values", [(s, m, None) for s, m in PAIRS] + SCALED)
def test_a_lone_run_between_events_takes_every_step_and_figure(scene, method, values):
    """A lone trajectory's steps between events (a sampled map, a bin's start, a record, the last
    step) run in a loop of their own (kernels.survey._fused), where explicit and symplectic Euler
    take each step's first coefficient row from the row H was computed with: the states and p_t
    are simulate's, max |H + p_t| and the bins' envelopes NumPy's over every step, the maps those
    of every 5th step; in one call, in calls that cut the events, and recording every 5th state
    (simulate's records). The states and p_t within 16 eps of their size, not bit for bit: the
    same step compiled in two loops may contract its products into fused multiply-adds
    differently (the worst measured, modulated aba864's states: 5.7 eps). SCALED: the damped scene past
    gamma t = ln 2, where the steps' scaling changes (and the row of the step before is not
    reused)."""
    s = Setup.make(scene, method, values)
    h = s.scene.h
    tr, M = numpy_figures(s, h, STEPS)
    H = tr.H_ext[1:, 0]
    floor = 1e-14 * max(1.0, np.max(np.abs(tr.H)))
    d = Drive(s, h, every=5, width=WIDTH)
    bins = d.run(STEPS)
    _within_eps(d, tr.z[-1], tr.pt[-1], tr)
    assert close(d.H_ext_max_abs, np.max(np.abs(H)), 1e-8, floor)
    starts = np.arange(0, STEPS, WIDTH)
    np.testing.assert_allclose(bins["H_min"], np.minimum.reduceat(H, starts), rtol=1e-8, atol=floor)
    np.testing.assert_allclose(bins["H_max"], np.maximum.reduceat(H, starts), rtol=1e-8, atol=floor)
    assert close(d.det_max_dev, np.max(det_deviation(M[::5])), 1e-8)
    cut = Drive(s, h, every=0, maps=False)
    for steps in (13, 1, 34):
        cut.advance(steps)
    _within_eps(cut, tr.z[-1], tr.pt[-1], tr)
    assert close(cut.H_ext_max_abs, np.max(np.abs(H)), 1e-8, floor)
    rec, F = Drive(s, h, every=5).record(STEPS, 5)
    every5 = simulate(s, h, STEPS * h, stride=5)
    np.testing.assert_array_equal(rec.t, every5.t)
    _within_eps(rec, every5.z, every5.pt, tr)
    np.testing.assert_allclose(F[:, 0], det_deviation(M[::5]), rtol=1e-8, atol=1e-13)


def _within_eps(got, z, pt, tr, ulps=16):
    """got's states (Z or z) and p_t (PT or pt) are z and pt to `ulps` eps of the run's sizes."""
    eps = np.finfo(float).eps
    np.testing.assert_allclose(getattr(got, "Z", getattr(got, "z", None)), z, rtol=0,
                               atol=ulps * eps * np.max(np.abs(tr.z)))
    np.testing.assert_allclose(getattr(got, "PT", getattr(got, "pt", None)), pt, rtol=0,
                               atol=ulps * eps * max(1.0, np.max(np.abs(tr.H))))


@pytest.mark.parametrize("scene,method", [p for p in PAIRS if not SCENES[p[0]].kernel.linear])
def test_each_member_of_an_ensemble_is_its_own_single_run(scene, method):
    """simulate runs an ensemble of a nonlinear scene through the fused loop (member 0 in its own
    registers, the others through the arrays) and one trajectory through the single-trajectory
    loop (kernels.loops.propagate_one): each member's records, increments, p_t and H are its own
    run's to 64 ulps of their size, at a stride that does not divide the steps (kapitza, the one
    nonlinear scene: the states and H identical, member 0's p_t within an ulp; not bit for bit,
    since the same step compiled in two loops may contract its products differently)."""
    _members_are_their_own_runs(Setup.make(scene, method), 64)


def _members_are_their_own_runs(s, ulps):
    """An ensemble of three nearby states against each one's single run, at a stride that does not
    divide the steps: the records, increments, p_t and H within `ulps` eps of their size."""
    h = s.scene.h
    z0 = nearby_states(s.start[0], 1e-3, 2)
    ensemble = simulate(s, h, STEPS * h, z0=z0, stride=5, increments=True)
    assert ensemble.z.shape[1] == 3
    for i in range(3):
        one = simulate(s, h, STEPS * h, z0=z0[i:i + 1], stride=5, increments=True)
        scale = np.max(np.abs(one.z))
        energy = max(1.0, np.max(np.abs(one.H)))
        np.testing.assert_array_equal(ensemble.t, one.t)
        for got, own, size in ((ensemble.z, one.z, scale), (ensemble.increments[1:], one.increments[1:], scale),
                               (ensemble.pt, one.pt, energy), (ensemble.H, one.H, energy)):
            np.testing.assert_allclose(got[:, i], own[:, 0], rtol=0, atol=ulps * np.finfo(float).eps * size)


@pytest.mark.parametrize("scene,method", [p for p in PAIRS if SCENES[p[0]].kernel.linear])
def test_each_member_of_a_linear_ensemble_is_its_own_single_run_to_round_off(scene, method):
    """simulate runs an ensemble of a linear scene by the step's matrix (kernels.loops.propagate_matrix,
    compiled with LLVM's SLP vectorizer for the charged particle: kernels.dispatch.Vectorizing) and
    one trajectory by member steps: each member's records, increments, p_t and H are its own run's to
    round-off, 256 eps of their size over 48 steps (the worst measured, charged composition6: 82).
    A miscompiled or wrongly vectorized step matrix is off by far more."""
    _members_are_their_own_runs(Setup.make(scene, method), 256)


def test_a_nonlinear_ensemble_fails_where_its_first_member_fails():
    """Kapitza's midpoint at a step far beyond the drive period, so that Newton fails
    (test_failures), each member with its own p_t (no start): the ensemble's run stops at the
    first step any member's own run fails, with that run's message (but the local rate, which the
    ensemble takes over all its members), and keeps every record before it, each its member's own."""
    s = Setup.make("kapitza", "midpoint", {"a": 1.0, "nu": 100.0, "q0": 3.0})
    z0 = nearby_states(s.start[0], 1e-2, 2)
    pt0 = np.array([0.5, -1.0, 2.0])
    own = []
    for i in range(3):
        with pytest.raises(RunError) as single:
            simulate(s, 0.3, 60.0, z0=z0[i:i + 1], pt0=pt0[i], stride=2)
        own.append(single.value)
    first = min(own, key=lambda e: e.step)
    with pytest.raises(RunError) as info:
        simulate(s, 0.3, 60.0, z0=z0, pt0=pt0, stride=2)
    err = info.value
    head = f"Newton did not converge in step {first.step + 1} (from t = {first.time:.6g}): the flow's local rate"
    assert str(err).startswith(head) and str(first).startswith(head) and err.step == first.step > 0
    advice = [str(e).split("; try h below ")[1] for e in (err, first)]
    assert advice[0] == advice[1], "members 1e-2 apart: the same h to try, to the two figures given"
    part = err.partial
    assert len(part.t) == first.step // 2 + 1
    for i, e in enumerate(own):
        kept = len(part.t)
        for got, mine in ((part.z, e.partial.z), (part.pt, e.partial.pt), (part.H, e.partial.H)):
            size = max(1.0, np.max(np.abs(mine[:kept])))
            np.testing.assert_allclose(got[:, i], mine[:kept, 0], rtol=0, atol=64 * np.finfo(float).eps * size)


@pytest.mark.parametrize("scene,method", [p for p in PAIRS if p[1] in ("midpoint", "rk4", "gauss4", "leapfrog", "boris")])
def test_envelopes_match_numpy_reductions(scene, method):
    s = Setup.make(scene, method)
    h = s.scene.h
    n = s.scene.ndof
    Z0 = nearby_states(s.start[0], 1e-4, 2 * n + 1)
    tr, M = numpy_figures(s, h, STEPS, Z0)
    drive = long_drive(s, h, WIDTH)
    bins = drive.advance(STEPS)
    Z = drive.Z
    assert drive.failure == ""

    def reduce(values, op):
        return op.reduceat(values, np.arange(0, len(values), WIDTH))

    H = tr.H_ext[1:, 0]
    vol = paper_volume_form(tr)
    want = {"t": tr.t[1:][::WIDTH], "H_min": reduce(H, np.minimum), "H_max": reduce(H, np.maximum),
            "vol_min": reduce(vol, np.minimum), "vol_max": reduce(vol, np.maximum),
            "det": reduce(det_deviation(M), np.maximum), "symp": reduce(symplecticity_defect(M), np.maximum)}
    assert set(bins) == set(want)
    np.testing.assert_allclose(bins["t"], want["t"], rtol=1e-15)
    Hscale = 1e-14 * max(1.0, np.max(np.abs(tr.H)))
    for key in ("H_min", "H_max"):
        np.testing.assert_allclose(bins[key], want[key], rtol=1e-8, atol=Hscale)
    # A determinant of nearly parallel increments cancels heavily: its round-off is bounded by
    # eps times Hadamard's bound (the product of the rows' norms), not by eps times the value.
    dZ = tr.increments[1:, 1:2 * n + 2]
    rows = np.sqrt(np.sum(dZ ** 2, axis=-1) + h * h)
    hadamard = np.max(np.prod(rows, axis=-1))
    for key in ("vol_min", "vol_max"):
        np.testing.assert_allclose(bins[key], want[key], rtol=0, atol=1e-13 * hadamard)
    for key in ("det", "symp"):
        np.testing.assert_allclose(bins[key], want[key], rtol=1e-8, atol=1e-13)
    np.testing.assert_allclose(Z, tr.z[-1], rtol=0, atol=1e-12 * np.max(np.abs(tr.z)))
    # the nearby members' p_t: by member steps on a nonlinear scene, as simulate's ensemble takes
    # them; not carried on a linear one (the members take the step matrix, without its Q)
    if s.scene.kernel.linear:
        assert np.all(np.isnan(drive.PT[1:]))
        bare = Drive(s, h, z0=Z0)
        bare.advance(2)
        with pytest.raises(ValueError, match="not carried"):
            bare.record(1, 1)
    else:
        np.testing.assert_allclose(drive.PT[1:], tr.pt[-1, 1:], rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(tr.H))))


@pytest.mark.parametrize("scene,method", PAIRS)
@pytest.mark.parametrize("stride", [1, 5])
def test_comparison_figures_match_numpy_diagnostics(scene, method, stride):
    """study.compare records its run and each record's figures in the fused loop (member steps);
    the same run by simulate (an ensemble: on a linear scene it steps by the step matrix) with
    tangent maps formed afterwards and the figures taken in NumPy gives them to round-off, at
    every step and at a stride that does not divide the steps (the last record is the run's end)."""
    s = Setup.make(scene, method)
    h = s.scene.h
    n = s.scene.ndof
    c = compare(s, h, STEPS * h, stride=stride)
    tr = simulate(s, h, STEPS * h, z0=nearby_states(s.start[0], 1e-4, 2 * n + 1), stride=stride, increments=True)
    M = tangent_maps(tr)
    run = c.run
    assert run.stride == stride and run.steps == tr.steps == STEPS
    np.testing.assert_array_equal(run.t, tr.t)
    scale = np.max(np.abs(tr.z))
    np.testing.assert_allclose(run.z, tr.z, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(run.increments[1:], tr.increments[1:], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(run.H_ext, tr.H_ext, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(tr.H))))
    assert c.det_dev.shape == c.symp_dev.shape == c.paper_volume.shape == (len(tr.t) - 1,)
    np.testing.assert_allclose(c.det_dev, det_deviation(M), rtol=1e-8, atol=1e-13)
    np.testing.assert_allclose(c.symp_dev, symplecticity_defect(M), rtol=1e-8, atol=1e-13)
    dZ = tr.increments[1:, 1:2 * n + 2]
    hadamard = np.max(np.prod(np.sqrt(np.sum(dZ ** 2, axis=-1) + h * h), axis=-1))
    np.testing.assert_allclose(c.paper_volume, paper_volume_form(tr), rtol=0, atol=1e-13 * hadamard)


@pytest.mark.parametrize("scene,method", [("damped", "rk4"), ("modulated", "midpoint"), ("kapitza", "gauss4"),
                                          ("charged", "midpoint"), ("charged", "euler")])
def test_volume_estimator_is_the_determinant_of_its_increments(scene, method):
    """The fused loop's volume estimator against the exact (rational) determinant of the same
    recorded increments: within 64 eps of h times the product of the norms of the differences
    X^i - X^1 (Hadamard's bound of the determinant it takes; a margin over its round-off where the
    differences of nearby increments are exact, as Sterbenz's lemma gives them within a factor of 2,
    and the LU's growth is small; the LU of the raw rows (X^i, h) exceeded it 140, 128 and 3 times
    on the one-degree-of-freedom cases here). Charged's differences are nearly singular (det 1e-21
    of that bound), where the bound could not see a wrong sign: each value also within 1e-3
    relative of the exact one (measured 4e-7 there; the raw rows' LU 1e-2), and so is NumPy's
    diagnostics.paper_volume_form of the same run."""
    s = Setup.make(scene, method)
    h = s.scene.h
    n = s.scene.ndof
    c = compare(s, h, STEPS * h)
    X = c.run.increments[1:, 1:2 * n + 2]
    numpy_volume = paper_volume_form(c.run)
    for k in range(len(X)):
        rows = [[Fraction(float(v)) for v in (*x[:n], h, *x[n:])] for x in X[k]]
        exact = float(exact_determinant(rows))
        bound = np.prod(np.linalg.norm(X[k, 1:] - X[k, :1], axis=-1))
        assert abs(c.paper_volume[k] - exact) <= 64 * np.finfo(float).eps * h * bound, (k, c.paper_volume[k], exact)
        assert abs(c.paper_volume[k] - exact) <= 1e-3 * abs(exact), (k, c.paper_volume[k], exact)
        assert abs(numpy_volume[k] - exact) <= 1e-3 * abs(exact), (k, numpy_volume[k], exact)


def exact_determinant(rows):
    """det of a square matrix of Fractions by exact elimination."""
    A = [list(r) for r in rows]
    det = Fraction(1)
    for c in range(len(A)):
        p = next((i for i in range(c, len(A)) if A[i][c] != 0), None)
        if p is None:
            return Fraction(0)
        if p != c:
            A[c], A[p] = A[p], A[c]
            det = -det
        det *= A[c][c]
        for i in range(c + 1, len(A)):
            f = A[i][c] / A[c][c]
            A[i] = [a - f * b for a, b in zip(A[i], A[c])]
    return det


def test_chunks_keep_bins_and_sampled_maps_aligned(monkeypatch):
    """A run cut into many compiled calls gives the figures of one call: bins and the sampled
    maps are counted from the run's first step."""
    s = Setup.make("kapitza", "midpoint")
    h = s.scene.h
    Z0 = nearby_states(s.start[0], 1e-4, 3)
    one = Drive(s, h, z0=Z0, width=6, every=3)
    whole = one.run(120)
    monkeypatch.setattr(drive_module, "CHUNK", 7)
    many = Drive(s, h, z0=Z0, width=6, every=3)
    cut = many.run(120)
    assert many.unit == 6
    for key in whole:
        np.testing.assert_array_equal(cut[key], whole[key])
    np.testing.assert_array_equal(many.acc, one.acc)
    np.testing.assert_array_equal(many.Z, one.Z)


def test_sampled_maps_are_a_subset_of_every_map():
    s = Setup.make("kapitza", "rk4")
    h = s.scene.h
    M = numpy_figures(s, h, 60)[1]
    d = Drive(s, h, every=4)
    d.run(60)
    assert d.det_max_dev == pytest.approx(np.max(det_deviation(M[::4])), rel=1e-8)
    assert d.det_max_dev <= np.max(det_deviation(M))


def test_failure_keeps_the_data_before_it():
    """The damped scene's RK4 at a step past its stability overflows: the driver stops there,
    says so, and keeps the bins and maxima of the steps before; so does a long run's envelopes
    (the paper report's), and a call after the failure adds nothing."""
    s = Setup.make("damped", "rk4", {"gamma": 0.0})
    h = 3.0
    drive = long_drive(s, h, 10)
    bins = drive.advance(4000)
    assert drive.failure.startswith("overflow in step")
    assert 0 < len(bins["t"]) < 400 and len(bins["t"]) == -(-drive.done // 10)
    assert np.all(np.isfinite(bins["H_max"][:10]))  # H itself overflows before the state does
    assert len(drive.advance(100)["t"]) == 0
    env, failure = long_envelopes(s, h, 4000 * h, 400)
    assert failure == drive.failure
    for k in bins:
        np.testing.assert_array_equal(env[k], bins[k])


def test_a_nan_is_kept_by_the_reductions():
    """numba's max(a, nan) is a: the reductions use their own, which keep a NaN as NumPy does."""
    nan = math.nan
    assert math.isnan(_most(1.0, nan)) and math.isnan(_most(nan, 1.0))
    assert math.isnan(_least(1.0, nan)) and math.isnan(_least(nan, 1.0))
    assert _most(1.0, 2.0) == 2.0 and _least(1.0, 2.0) == 1.0


def test_the_map_defects_of_one_degree_of_freedom_are_the_general_ones():
    """For 2 x 2 maps `defects` forms |det M - 1| and the symplecticity defect from one pair of
    products (M^T J M = det(M) J): the general formula's defects bit for bit, det to round-off;
    a scaling by c has det c^2 and M^T J M = c^2 J; a NaN stays NaN in every figure."""
    rng = np.random.default_rng(16)
    B = np.empty((2, 2))
    one, two = Setup.make("damped", "midpoint").P, Setup.make("charged", "midpoint").P  # m = 2 and 4
    for M in [rng.normal(size=(2, 2)) for _ in range(50)] + [np.array([[0.6, -0.8], [0.8, 0.6]]), 3.0 * np.eye(2)]:
        dev, symp, rel = defects(M, B, one)
        assert (symp, rel) == symplecticity(M, 2)
        assert close(dev, abs(np.linalg.det(M) - 1.0), 1e-12, 4e-16 * (1.0 + np.abs(M).max() ** 2))
    assert defects(3.0 * np.eye(2), B, one) == (8.0, 8.0, 8.0 / 9.0)
    for m, P in ((2, one), (4, two)):
        M = np.eye(m)
        M[0, 1] = math.nan
        assert all(math.isnan(v) for v in defects(M, np.empty((m, m)), P))


def test_a_bin_without_a_sampled_map_says_so():
    s = Setup.make("kapitza", "midpoint")
    bins = Drive(s, s.scene.h, z0=nearby_states(s.start[0], 1e-4, 3), width=2, every=4).run(16)
    assert np.all(np.isfinite(bins["det"][0::2])) and np.all(np.isnan(bins["det"][1::2]))


def test_run_summary_reports_the_fused_figures():
    s = Setup.make("damped", "midpoint")
    out = run_summary(s, 0.1, 5.0, with_error=False)
    tr = numpy_figures(s, 0.1, 50)[0]
    assert out["steps"] == 50
    assert out["H_ext_max_abs"] == pytest.approx(np.max(np.abs(tr.H_ext)), rel=1e-8)
    assert out["symp_max_rel"] <= 1e-15
    assert out["H_ext_final"] == pytest.approx(tr.H_ext[-1, 0], rel=1e-8, abs=1e-15)


@pytest.mark.parametrize("scene,method,names", [("modulated", "midpoint", ("eps", "alpha")),
                                                ("kapitza", "gauss4", ("a", "q0")),
                                                ("damped", "rk4", ("gamma", "p0"))])
def test_batched_runs_match_runs_one_by_one(scene, method, names):
    """A grid's points in one compiled call (kernels.survey over parameter sets) give what each point's own run
    gives (sweep.figures: a Drive per point), with the scene's parameters and initial state from
    the batch's rows."""
    axes = [f"{names[0]}=0.1:0.6:3", f"{names[1]}=0.5:1.5:3"]
    p = sweep.plan(scene, method, axes, ["H_ext_max_abs", "det_max_dev", "growth"], T=20.0)
    assert sweep._batched(p)
    done, cols, statuses, _ = sweep.evaluate(p, range(p.size))
    assert done == list(range(p.size)) and statuses == ["ok"] * p.size
    for i in range(p.size):
        setup, h, T = p.run_of(p.point(i))
        one, status, end = sweep.figures(setup, h, T, p.measures)
        assert status == "ok" and cols["t_final"][i] == end
        for k in p.measures:
            assert cols[k][i] == pytest.approx(one[k], rel=1e-12, abs=1e-15), (i, k)


def test_a_failed_point_of_a_batch_gets_its_own_message():
    """Explicit Euler on the modulated oscillator grows like exp(n h^2 / 2): at h = 0.5 to T = 1e5
    it overflows wherever it runs; the batch's failed points are run alone for their message."""
    p = sweep.plan("modulated", "euler", ["eps=0:0.4:3"], ["H_ext_max_abs", "growth"], h=0.5, T=1e5)
    _, cols, statuses, _ = sweep.evaluate(p, range(p.size))
    for i in range(p.size):
        setup, h, T = p.run_of(p.point(i))
        assert statuses[i] == sweep.figures(setup, h, T, p.measures)[1]
        assert statuses[i].startswith("overflow in step")
    assert np.all(np.isnan(cols["growth"])) and np.all(np.isnan(cols["t_final"]))
