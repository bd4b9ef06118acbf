"""Fitted convergence order of every method on every scene it applies to.

Step sizes divide the horizon and shrink by sqrt(2); the slope of log(error) against log(h) is
fitted on the four smallest steps whose error stays above the round-off floor (the asymptotic
regime) and must be within 0.3 of the declared order.
"""
import numpy as np
import pytest

from conftest import case_id, pairs, setup
from cosymp.integrate import simulate
from cosymp.methods import METHODS
from cosymp.reference import scipy_reference
from cosymp.scenes import SCENES

# Errors below these are round-off (exact-flow reference) or the reference's own: DOP853 at
# rtol = atol = 1e-14 follows the sixth- and eighth-order methods down to 1e-14 over T = 2 time
# scales on kapitza, charged and a driven Duffing scene. At 1e-12, with seven steps, the fit of a
# sixth-order method could hold only points before its error settles to its order (the Duffing
# scene's blanes-moan6: local orders 9.5, 6.4, 4.9, 5.5, 5.8, 5.9, 6.0 down the ten steps).
FLOOR = {True: 5e-14, False: 2e-13}
STEPS = 10  # step sizes in the fit, each 2^(-1/2) of the last
BASE = {1: 0.05, 2: 0.2, 4: 0.2, 6: 0.15, 8: 0.8}
BASE_METHOD = {"gauss6": 0.6, "blanes-moan6": 0.6}  # error constants far below the order's usual
_refs = {}


def reference(scene, values):
    """z(T) from the exact flow (one step over the horizon) or scipy's DOP853 at tight tolerance."""
    key = (scene, tuple(sorted(values.items())))
    if key not in _refs:
        s = SCENES[scene]
        T = 2 * s.time_scale
        if s.has_flow:
            z = simulate(setup(scene, "exact", **values), T, T).z[-1, 0]
        else:
            z = scipy_reference(setup(scene, "rk4", **values), T, rtol=1e-14, atol=1e-14).y[:-1, -1]
        _refs[key] = (T, z)
    return _refs[key]


def order_values(scene, method):
    """The scene's values for the fit: a near-integrable splitting's error is a series in the size of
    H - H0 too, so it shows its order in h where H - H0 is as large as H0 (the scene's `strong`)."""
    return SCENES[scene].strong if METHODS[method].requires == "integrable" else {}


@pytest.mark.parametrize("case", [c for c in pairs() if c[1] != "exact"], ids=case_id)
def test_fitted_order(case):
    scene, method, theta = case
    order = METHODS[method].order_at(0.5 if theta is None else theta)
    values = order_values(scene, method)
    T, z_ref = reference(scene, values)
    s = setup(scene, method, theta, **values)
    steps = np.round(T / (SCENES[scene].time_scale * BASE_METHOD.get(method, BASE[order]) * 2.0 ** -(np.arange(STEPS) / 2)))
    hs = T / steps
    errs = np.array([np.linalg.norm(simulate(s, h, T).z[-1, 0] - z_ref) for h in hs])
    keep = np.flatnonzero(errs > FLOOR[SCENES[scene].has_flow])[-4:]
    assert keep.size >= 3, f"errors {errs} reach the round-off floor too soon"
    slope = np.polyfit(np.log(hs[keep]), np.log(errs[keep]), 1)[0]
    assert abs(slope - order) <= 0.3, f"fitted order {slope:.2f}, declared {order}; errors {errs}"


@pytest.mark.parametrize("scene", [s for s in SCENES if SCENES[s].has_flow])
def test_exact_flow_matches_dop853(scene):
    """The closed-form flow against an independent scipy DOP853 solution, along the run."""
    s = setup(scene, "exact")
    T = 5.0
    run = simulate(s, 0.25, T)
    sol = scipy_reference(s, T, rtol=1e-13, atol=1e-13, t_eval=run.t)
    assert np.allclose(run.z[:, 0], sol.y[:2].T, rtol=1e-10, atol=1e-10)
    assert np.max(np.abs(run.H_ext)) < 1e-12


def test_a_near_integrable_splitting_errs_only_through_the_perturbation():
    """ABA864 on the modulated oscillator (H0 = (q² + p²)/2 turned exactly, H - H0 = ε sin(αt) q²/2
    kicked) at a fixed h = 0.5 to T = 50: without modulation it is the exact flow (round-off), and
    halving ε divides its error by about 4 (the published O(ε h^8 + ε² h^6 + ε³ h^4): here the
    ε² h^6 term leads). A generic splitting of the same order 4 errs as on the unperturbed
    oscillator, whatever ε."""
    def error(method, eps):
        values = {"eps": eps, "alpha": 0.3}
        z_ref = scipy_reference(setup("modulated", "rk4", **values), 50.0, rtol=1e-13, atol=1e-14).y[:-1, -1]
        return np.linalg.norm(simulate(setup("modulated", method, **values), 0.5, 50.0).z[-1, 0] - z_ref)

    plain = simulate(setup("modulated", "aba864", eps=0.0), 0.5, 50.0).z[-1, 0]  # from (q, p) = (1, 1)
    assert np.linalg.norm(plain - [np.cos(50.0) + np.sin(50.0), np.cos(50.0) - np.sin(50.0)]) < 1e-13
    errs = [error("aba864", eps) for eps in (0.2, 0.1, 0.05)]
    assert all(3.3 < errs[i] / errs[i + 1] < 4.5 for i in range(2)), errs
    generic = [error("blanes-moan4", eps) for eps in (0.2, 0.1)]
    assert generic[0] / generic[1] < 1.3 and errs[-1] < 0.3 * generic[-1], (errs, generic)
