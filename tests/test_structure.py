"""Volume and symplecticity of the one-step maps, against known values."""
import numpy as np
import pytest

from conftest import case_id, pairs, setup, structure_preserving
from cosymp.diagnostics import det_deviation, symplecticity_defect, tangent_maps
from cosymp.integrate import records, simulate
from cosymp.scenes import SCENES

ROUNDOFF = 1e-13
LONG = 100_000
# Parameters that keep 1e5 steps of each linear scene finite and time-dependent.
LONG_VALUES = {"decaying": {"lam": 1e-3}, "damped": {"gamma": 2e-4}}


NONLINEAR = 10_000  # steps on a nonlinear scene: each tangent map is a complex step of a Newton solve
NONLINEAR_ROUNDOFF = 1e-12  # Newton's tolerance, relative to the state (kernels.families.NEWTON_TOL)


def long_maps(scene, method, theta, steps=LONG):
    s = setup(scene, method, theta, **LONG_VALUES.get(scene, {}))
    run = simulate(s, s.scene.h, steps * s.scene.h)
    assert run.steps == steps
    return tangent_maps(run)


@pytest.mark.parametrize("case", [c for c in pairs(linear_only=True) if structure_preserving(c[1], c[2])],
                         ids=case_id)
def test_structure_preserved_at_roundoff(case):
    M = long_maps(*case)
    assert len(M) == LONG
    assert np.max(det_deviation(M)) < ROUNDOFF
    assert np.max(symplecticity_defect(M)) < ROUNDOFF


@pytest.mark.parametrize("case", [c for c in pairs() if structure_preserving(c[1], c[2])
                                  and not SCENES[c[0]].kernel.linear], ids=case_id)
def test_structure_preserved_on_nonlinear_scenes(case):
    M = long_maps(*case, steps=NONLINEAR)
    assert len(M) == NONLINEAR
    assert np.max(det_deviation(M)) < NONLINEAR_ROUNDOFF
    assert np.max(symplecticity_defect(M)) < NONLINEAR_ROUNDOFF


def test_boris_preserves_volume():
    M = long_maps("charged", "boris", None)
    assert np.max(det_deviation(M)) < ROUNDOFF


@pytest.mark.parametrize("lam", [1.0, 0.02, 0.3, 2.5])
@pytest.mark.parametrize("h", [0.05, 0.1, 0.3])
def test_euler_determinant_on_opening_example(h, lam):
    """The paper's Sec. 1 (lambda = 1), and the scene's text for any lambda: M = [[1, h a], [-h a, 1]]
    with a = e^{-lambda t_k}, so det = 1 + h^2 e^{-2 lambda t_k} > 1."""
    run = simulate(setup("decaying", "euler", lam=lam), h, 40 * h)
    M = tangent_maps(run)
    expected = 1 + h ** 2 * np.exp(-2 * lam * run.t[:-1])
    assert np.allclose(np.linalg.det(M), expected, rtol=1e-14, atol=0)


@pytest.mark.parametrize("lam", [1.0, 0.02, 0.3, 2.5])
def test_opening_example_exact_step_is_the_stated_rotation(lam):
    """q' = a p, p' = -a q with a = e^{-lambda t}: each exact step rotates (q, p) clockwise by the
    integral of a over the step, (e^{-lambda t_k} - e^{-lambda t_(k+1)}) / lambda."""
    h = 0.2
    run = simulate(setup("decaying", "exact", lam=lam), h, 30 * h, z0=[[1.0, 0.0]])
    q, p = run.z[:, 0, 0], run.z[:, 0, 1]
    angles = np.diff(np.unwrap(np.arctan2(-p, q)))
    t = run.t[:-1]
    assert np.allclose(angles, (np.exp(-lam * t) - np.exp(-lam * (t + h))) / lam, rtol=0, atol=1e-13)


def _rk4_factor(h, a1, a2, a3):
    """RK4's one-step map for z' = a(t) J z as a complex number (J acts as i)."""
    k1 = 1j * a1
    k2 = 1j * a2 * (1 + h / 2 * k1)
    k3 = 1j * a2 * (1 + h / 2 * k2)
    k4 = 1j * a3 * (1 + h * k3)
    return 1 + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


@pytest.mark.parametrize("h", [0.1, 0.5, 1.0])
def test_rk4_determinant_follows_stability_function(h):
    """Constant coefficients: det = |R(ih)|^2 = 1 - h^6/72 + h^8/576. Time-dependent (opening
    example): det = |R|^2 with RK4's stage coefficients e^{-t_k}, e^{-t_k - h/2}, e^{-t_k - h}."""
    run = simulate(setup("modulated", "rk4", eps=0.0), h, 20 * h)
    det = np.linalg.det(tangent_maps(run))
    assert np.allclose(det, 1 - h ** 6 / 72 + h ** 8 / 576, rtol=1e-14, atol=0)
    assert np.all(det < 1)
    run = simulate(setup("decaying", "rk4"), h, 20 * h)
    t = run.t[:-1]
    R = _rk4_factor(h, np.exp(-t), np.exp(-t - h / 2), np.exp(-t - h))
    assert np.allclose(np.linalg.det(tangent_maps(run)), np.abs(R) ** 2, rtol=1e-14, atol=0)


@pytest.mark.parametrize("theta", [0.0, 0.25, 0.75, 1.0])
@pytest.mark.parametrize("scene", ["decaying", "damped"])
def test_naive_theta_is_not_symplectic_by_its_formula(scene, theta):
    """det M = (1 + h^2 (1-theta)^2 det S) / (1 + h^2 theta^2 det S), S = Hessian at t_k + theta h;
    in one degree of freedom ||M^T J M - J||_max = |det M - 1|."""
    h = 0.2
    run = simulate(setup(scene, "theta-naive", theta), h, 30 * h)
    M = tangent_maps(run)
    tt = run.t[:-1] + theta * h
    detS = np.exp(-2 * tt) if scene == "decaying" else np.full_like(tt, run.setup.values["w0"])
    expected = (1 + h ** 2 * (1 - theta) ** 2 * detS) / (1 + h ** 2 * theta ** 2 * detS)
    assert np.allclose(np.linalg.det(M), expected, rtol=1e-14, atol=0)
    assert np.min(det_deviation(M)) > 1e-8
    assert np.allclose(symplecticity_defect(M), det_deviation(M), rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("case", pairs(linear_only=True), ids=case_id)
def test_matrix_path_agrees_with_member_path(case):
    """Linear scenes step by one matrix per step; the general member step (Newton, here one linear
    solve, refined once for Gauss) is an independent implementation of the same method: they agree
    to round-off."""
    from cosymp.integrate import initial_states
    from cosymp.kernels.loops import propagate_matrix

    s = setup(*case)
    h = s.scene.h
    K = 200
    run = simulate(s, h, K * h)
    assert run.z.shape[1] == 1, "simulate steps one trajectory by member steps"
    Z = initial_states(s).copy()
    PT = -run.H[:1, 0].copy()
    rec = (np.empty(K + 1), np.empty((K + 1, 1, Z.shape[1])), np.empty((K + 1, 1)), np.empty((0, 1, Z.shape[1])))
    status, done = propagate_matrix(s.data, s.P, 0.0, h, Z, PT, K, 1, *rec, np.empty((0, 1)), True, False)
    assert status == 0 and done == K
    scale = np.max(np.abs(run.z[:, 0]))
    assert np.max(np.abs(rec[1][:, 0] - run.z[:, 0])) < 1e-12 * scale * K
    assert np.max(np.abs(rec[2][:, 0] - run.pt[:, 0])) < 1e-12 * K


@pytest.mark.parametrize("scene", ["damped", "kapitza"])
def test_the_last_record_is_the_state_at_T_whatever_the_stride(scene):
    """Record j is step j*stride, and the final step is always recorded: with stride 3 and 10
    steps the records are steps 0, 3, 6, 9 and 10, each bit-identical to the every-step run's."""
    s = setup(scene, "midpoint")
    every = simulate(s, 0.01, 0.1, stride=1)
    strided = simulate(s, 0.01, 0.1, stride=3)
    assert every.steps == strided.steps == 10 and records(10, 3) == len(strided.t) == 5
    assert np.array_equal(strided.t, every.t[[0, 3, 6, 9, 10]])
    assert np.array_equal(strided.z, every.z[[0, 3, 6, 9, 10]]) and np.array_equal(strided.pt, every.pt[[0, 3, 6, 9, 10]])
