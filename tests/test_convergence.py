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

FLOOR = {True: 5e-14, False: 1e-12}  # exact-flow reference, scipy DOP853 reference
BASE = {1: 0.05, 2: 0.2, 4: 0.2, 6: 0.15, 8: 0.8}
BASE_METHOD = {"gauss6": 0.6, "blanes-moan6": 0.6}  # error constants far below the order's usual
_refs = {}


def reference(scene):
    """z(T) from the exact flow (one step over the horizon) or scipy's DOP853 at tight tolerance."""
    if scene not in _refs:
        s = SCENES[scene]
        T = 2 * s.time_scale
        if s.has_flow:
            z = simulate(setup(scene, "exact"), T, T).z[-1, 0]
        else:
            z = scipy_reference(setup(scene, "rk4"), T, rtol=1e-14, atol=1e-14).y[:-1, -1]
        _refs[scene] = (T, z)
    return _refs[scene]


@pytest.mark.parametrize("case", [c for c in pairs() if c[1] != "exact"], ids=case_id)
def test_fitted_order(case):
    scene, method, theta = case
    order = METHODS[method].order_at(0.5 if theta is None else theta)
    T, z_ref = reference(scene)
    s = setup(scene, method, theta)
    steps = np.round(T / (SCENES[scene].time_scale * BASE_METHOD.get(method, BASE[order]) * 2.0 ** -(np.arange(7) / 2)))
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
