"""Reference solutions: the exact flow where a scene has one, else a fine fixed-step RK8 run."""
import math
from typing import NamedTuple

import numpy as np

from . import warm
from .diagnostics import distance, norm, reference_size, relative_error
from .drive import Drive
from .errors import InputError, RunError
from .integrate import MAX_STEPS, Setup, check_step, exact_flow, initial_states, simulate
from .kernels.loops import energies, vector_field

REFERENCE_FRACTION = 0.02
SEGMENT = 1 << 16  # rk8 steps of reference_states's compiled calls (about 50 ms on kapitza)


def check_reference(setup, h, T, skip=""):
    """InputError, before anything runs, if the fine rk8 reference of a run of setup with step h
    to T (scenes without an exact flow) passes the step cap. skip: how the caller leaves the error
    at T out (the run's --no-error), said after "shorten T"."""
    fine = fine_steps(setup, h, T)
    if not fine <= MAX_STEPS:
        count = f"{fine:.3g}" if math.isfinite(fine) else "more than 1.8e+308"
        raise InputError(f"the reference for this run would take {count} steps of rk8 (at most "
                         f"{REFERENCE_FRACTION:g} of the scene's time scale and half of h each), over the cap "
                         f"of {MAX_STEPS:.0e}: shorten T" + (f", or {skip}" if skip else ""))


def refinement(setup, h):
    """k, the reference's rk8 steps per step h: each no larger than 2% of the scene's time scale,
    and k even and at least 2. The reference is never the run itself (rk8 at h was measured against
    itself, an error of 0), and its check at twice its step ends on the same final time. Infinite
    only where h over 2% of the time scale passes floating point."""
    ratio = h / (REFERENCE_FRACTION * setup.scene.time_scale)
    if not math.isfinite(ratio):
        return math.inf
    k = max(2, math.ceil(ratio))
    return k + k % 2


def fine_steps(setup, h, T):
    """How many rk8 steps the reference of a run of setup with step h to T takes (0 with an exact
    flow): refinement(setup, h) of them per step h. A float: inf past floating point (an exact
    count of steps that large has no float to be compared or printed as)."""
    if setup.scene.has_flow:
        return 0
    return check_step(h, T) * float(refinement(setup, h))


class Reference(NamedTuple):
    """A reference run at every multiple of h: states (steps + 1, 2n); label, which reference it
    is; spread (steps + 1,), its own uncertainty at each of them (`uncertainty`)."""

    states: np.ndarray
    label: str
    spread: np.ndarray


def reference_states(setup, h, T, z0=None, progress=None):
    """The Reference of a run of setup with step h to T: a fine rk8 run of its scene and parameters
    from z0 (the scene's initial condition by default), at every multiple of h up to the run's final
    time steps*h, its step h/k no larger than 2% of the scene's time scale, and its check at twice
    that step (reference_final's uncertainty, at each of them; infinite from where the check
    overflows). For the scenes without an exact flow; failures as for reference_final.

    Both runs go in compiled calls of about SEGMENT rk8 steps, continued as one run (the states
    are one call's to the bit), each followed by progress(done, steps) in steps of h where given:
    a caller stops the reference there by raising from it. Only the states at the multiples of h
    are kept."""
    steps = check_step(h, T)
    check_reference(setup, h, T)
    k = refinement(setup, h)
    fine = Setup.make(setup.scene, "rk8", setup.values)
    a = Drive(fine, h / k, z0=z0, every=0, energy=False, maps=False)
    b = Drive(fine, 2 * h / k, z0=z0, every=0, energy=False, maps=False)
    states = np.empty((steps + 1, a.Z.shape[1]))
    spread = np.full(steps + 1, np.inf)
    states[0], spread[0] = a.Z[0], 0.0
    each = max(1, SEGMENT // k)
    for start in range(0, steps, each):
        n = min(each, steps - start)
        rows = slice(start, start + n + 1)
        try:
            states[rows] = a.record(n * k, k)[0].z[:, 0]
        except RunError as e:
            raise _failed(f"rk8 at h/{k}, {OVERFLOWS}", e, h, "") from None
        if not b.failure:
            try:
                check = b.record(n * k // 2, k // 2)[0]
            except RunError as e:  # up to where it overflowed; unbounded from there
                check = e.partial
            reached = slice(start, start + len(check.t))
            spread[reached] = uncertainty(states[reached], check.z[:, 0], k * np.arange(reached.start, reached.stop))
        if progress is not None:
            progress(start + n, steps)
    return Reference(states, f"rk8 at h/{k}", spread)


def uncertainty(a, b, fine):
    """The uncertainty of the reference states a (rows) after `fine` rk8 steps each: their
    distance from their checks b, rk8 at twice their step, or the round-off of their steps,
    eps sqrt(fine) |a|, where that is larger (see reference_final)."""
    return np.maximum(distance(a, b), np.finfo(float).eps * np.sqrt(fine) * norm(a))


OVERFLOWS = "leaves floating-point range (|z| > 1.8e308)"


def _fine_run(fine, h, k, t_final, z0, stride, skip):
    """simulate the rk8 setup `fine` at h/k to t_final. rk8 is explicit: its one failure is
    overflow, a RunError said to be the reference's (skip as for check_reference)."""
    try:
        return simulate(fine, h / k, t_final, z0=z0, stride=stride)
    except RunError as e:
        raise _failed(f"rk8 at h/{k}, {OVERFLOWS}", e, h, skip) from None


def _failed(what, e, h, skip):
    """The RunError of a reference that failed as e did, worded as the reference's (a run's step
    count and "reduce h" are not its words), with the longest T whose whole steps of h end
    before it failed (T is rounded up to whole steps: a T below the failure can still reach it)."""
    whole = math.floor(e.time / h * (1 + 1e-12))
    shorten = f"shorten T to at most {whole * h:.10g}" if whole >= 1 else f"shorten h and T below t = {e.time:.6g}"
    return RunError(f"the reference for the error at T, {what} at t ≈ {e.time:.6g}: {shorten}"
                    + (f", or {skip}" if skip else ""), e.time, e.step)


def reference_final(setup, h, T, z0=None, skip=""):
    """(z at the run's final time steps*h, uncertainty) for a run of setup with step h to T.

    Exact flow: one exact step over the whole horizon, split where a step fails down to 2^-30 of it
    (integrate.exact_flow: the damped oscillator's one-step map passes floating point at γ T = 709,
    its state only at γ T = 1420; a step of h could fail where the state did not), uncertainty 0.
    Otherwise rk8 at the step h/k of `refinement`, and its uncertainty: its distance from its check,
    rk8 at twice that step, or the round-off of its steps, eps sqrt(steps) |z|, where that is larger.
    That distance bounds the reference's error wherever halving rk8's step at least halves its error;
    Richardson's estimate, the distance / (2^8 - 1), assumes rk8's asymptotic range, where halving
    divides it by 256, and is 100x short outside it (charged, beta = exp(t), h = 0.001, T = 8: 4.1e-3
    of |z| where the reference is 0.31 off, its step too long for the gyration 2e^t had by then).
    Infinite where the check overflows. RunError, saying it is the reference's, where the reference
    itself cannot go on; skip as for check_reference.
    """
    steps = check_step(h, T)
    t_final = steps * h
    if setup.scene.has_flow:
        exact = Setup.make(setup.scene, "exact", setup.values)
        try:
            z, _ = exact_flow(exact, initial_states(setup, z0), None, 0.0, t_final, t_final * 2.0 ** -30)
        except RunError as e:
            raise _failed(f"the exact flow, {OVERFLOWS}", e, h, skip) from None
        return z, np.zeros(z.shape[0])
    check_reference(setup, h, T, skip)
    k = refinement(setup, h)
    fine = Setup.make(setup.scene, "rk8", setup.values)
    a = _fine_run(fine, h, k, t_final, z0, steps * k, skip)
    try:
        b = simulate(fine, 2 * h / k, t_final, z0=z0, stride=steps * k // 2)
    except RunError:  # the check left rk8's stability region: nothing bounds the reference's error
        return a.z[-1], np.full(a.z.shape[1], np.inf)
    return a.z[-1], uncertainty(a.z[-1], b.z[-1], steps * k)


def is_resolved(error, spread):
    """Whether relative errors at T (a number or an array, with their spreads) are resolved: above
    their reference's own relative uncertainty (spread; None or 0: the exact flow's). Not at
    equality: rk8 at h measured against rk8 at h/2, its reference, is that reference's check, and
    its error the uncertainty itself."""
    return spread is None or ~((np.asarray(spread) > 0) & (np.asarray(error) <= spread))


def unresolved(error, spread):
    """What a table says after a relative error at T that is not resolved (`is_resolved`; spread
    inf: unbounded; spread above 1: the reference has lost the solution), worded as `cosymp
    run` words an unbounded one; else ''."""
    if error is None or is_resolved(error, spread):
        return ""
    own = ("unbounded, its check at twice its step overflowed" if math.isinf(spread) else
           f"{spread:.1e}, more than |z_ref| itself: the reference has lost the solution" if spread > 1 else
           f"{spread:.1e}")
    return f" (not resolved: the reference's own uncertainty is {own})"


def relative_final(z, z_ref, spread):
    """(|z - z_ref| / |z_ref|, spread / |z_ref|): the error at T and its reference's uncertainty,
    relative as the run, sweeps, the app and reports give them."""
    return relative_error(z, z_ref)[0], float(spread) / reference_size(z_ref)


def scipy_reference(setup, T, z0=None, rtol=1e-13, atol=1e-13, t_eval=None, method="DOP853"):
    """scipy's solve_ivp (DOP853 at tight tolerance by default) on the extended ODE (q, p, p_t)
    from p_t(0) = -H(z0, 0): an independent check, and the work-precision peers."""
    from scipy.integrate import solve_ivp

    Z = initial_states(setup, z0)
    warm.ensure(setup)
    P = setup.P
    m = Z.shape[1]
    H0 = np.empty((1, 1))
    energies(P, np.zeros(1), Z[:1][None], H0)

    def f(t, y):
        out = np.empty(m + 1)
        vector_field(P, t, np.ascontiguousarray(y[:m]), out)
        return out

    y0 = np.concatenate([Z[0], [-H0[0, 0]]])
    return solve_ivp(f, (0.0, T), y0, method=method, rtol=rtol, atol=atol, t_eval=t_eval)
