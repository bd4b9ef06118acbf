"""Runs that cannot go on stop with a message naming the step and the time, keeping the data."""
import numpy as np
import pytest

from conftest import setup
from cosymp.errors import RunError
from cosymp.integrate import simulate


def test_overflow_stops_and_keeps_data_up_to_there():
    """RK4 beyond its stability limit (h w = 3 > 2.83) blows up; the run says when."""
    with pytest.raises(RunError) as info:
        simulate(setup("modulated", "rk4"), 3.0, 1e5)
    err = info.value
    assert "overflow" in str(err) and f"t = {err.time:.6g}" in str(err)
    part = err.partial
    assert part.steps == err.step and np.all(np.isfinite(part.q))
    assert part.t[-1] == pytest.approx(err.step * 3.0)
    assert np.abs(part.q[-1, 0, 0]) > 1e100


def test_newton_failure_names_step_and_time():
    """Kapitza at a step far beyond the drive period: Newton does not converge, and says so."""
    s = setup("kapitza", "midpoint", a=1.0, nu=100.0, q0=3.0)
    with pytest.raises(RunError) as info:
        simulate(s, 0.3, 60.0)
    err = info.value
    assert f"Newton did not converge in step {err.step + 1} (from t = {err.time:.6g})" in str(err)
    assert err.time == pytest.approx(0.3 * err.step)
    assert np.all(np.isfinite(err.partial.q)) and err.partial.t[-1] <= err.time


def test_newton_converges_on_kapitza_at_moderate_step():
    """Implicit midpoint on the nonlinear scene converges each step (Newton path)."""
    run = simulate(setup("kapitza", "midpoint"), 0.01, 5.0)
    assert run.steps == 500 and not run.failure
