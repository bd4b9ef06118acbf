"""Everything a comparison view shows about one method on one scene, computed without any UI.

`compare` runs the method on the scene's initial condition together with the nearby states of
the paper's estimators in one pass of the fused driver (cosymp.drive), which records the states
and forms each recorded step's tangent map, its determinant and symplecticity defect and the
paper's volume estimator as it steps; optionally a small loop of initial conditions (the
carried cloud) runs in one more compiled loop; the other diagnostics of PHYSICS.md section 4
come from the records.
"""
import dataclasses
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .diagnostics import (
    errors_over_time,
    loop_action,
    nearby_states,
    paper_symplectic_form,
    relative_over_time,
    ring_states,
    separation_omega,
)
from .drive import CHUNK, Drive
from .errors import InputError, RunError
from .integrate import Setup, check_step, default_stride, initial_states, simulate
from .summary import transport


@dataclass
class Comparison:
    """One method's picture. Arrays are over recorded steps (every `stride`-th).

    run: members 0 (the trajectory) and 1..2n+1 (nearby states, delta apart).
    det_dev, symp_dev: |det M_k - 1| and ||M_k^T J M_k - J|| of the one-step maps (rigorous).
    paper_omega, paper_volume: the paper's estimators from one-step increments (as printed).
    separation_omega: omega(z_q1 - z0, z_p1 - z0) / delta^2 of the members perturbed along q_1 and p_1
        (1 for a symplectic map).
    cloud, cloud_area: the carried loop and its enclosed area over its initial area.
    error: the relative error |z - z_ref| / |z_ref| against the exact flow where the scene has one,
        or against a reference run given to `with_reference`; else None. against: which of them.
    orbit_error: |z - z_ref| relative to the largest |z_ref| so far, the orbit's size
        (diagnostics.errors_over_time): what the trajectory error plots show.
    uncertainty, orbit_uncertainty: a reference run's own uncertainty, relative as error and
        orbit_error are (an error at most as large is not resolved); None against the exact flow.
    Pi: mechanical momentum of the trajectory where the scene defines one, else None.
    """

    setup: Setup
    run: object
    det_dev: np.ndarray
    symp_dev: np.ndarray
    paper_omega: np.ndarray
    paper_volume: np.ndarray
    separation_omega: np.ndarray
    cloud: object
    cloud_area: np.ndarray
    error: np.ndarray
    Pi: np.ndarray
    cpu_s: float
    against: str = None
    orbit_error: np.ndarray = None
    uncertainty: np.ndarray = None
    orbit_uncertainty: np.ndarray = None

    @property
    def summary(self):
        """The numbers panel, from the full-resolution data."""
        return {
            "max |H + p_t|": finite_max(np.abs(self.run.H_ext[:, 0])),
            "max |det M_k − 1|": finite_max(self.det_dev) if self.det_dev.size else 0.0,
            "max |M_kᵀ J M_k − J|": finite_max(self.symp_dev) if self.symp_dev.size else 0.0,
            "final relative error": None if self.error is None else float(self.error[-1]),
            "steps": int(self.run.steps),
            "integration time, wall clock (s)": self.run.wall_s,
            "CPU time with diagnostics, its thread (s)": self.cpu_s,
        }


CLOUD_SAMPLES = 500


def finite_max(x):
    """The largest finite value (NaN if there is none): a run's maxima up to where it stopped."""
    x = np.asarray(x, float)
    ok = x[np.isfinite(x)]
    return float(ok.max()) if ok.size else float("nan")


def compare(setup, h, T, delta=1e-4, cloud_points=0, cloud_radius=0.05, stride=None, z0=None):
    """Run `setup` and derive its diagnostics; see Comparison. The cloud is recorded at about
    CLOUD_SAMPLES times (a multiple of the run's stride)."""
    start = time.thread_time()  # this computation's own: comparisons run side by side in threads
    steps = check_step(h, T)
    base = initial_states(setup, z0)[0]
    n = setup.scene.ndof
    members = nearby_states(base, delta, 2 * n + 1)
    if stride is None:
        stride = default_stride(steps, len(members), 2 * n, increments=True)
    elif not isinstance(stride, (int, np.integer)) or stride < 1:
        raise InputError(f"stride = {stride} must be a positive whole number")
    stride = int(stride)
    run, figures = Drive(setup, h, z0=members, every=stride, energy=False).record(steps, stride, increments=True)
    cloud = None
    area = np.empty(0)
    if cloud_points:
        cloud, area = carried_loop(setup, h, run.steps, loop_stride(run.steps, run.stride), base, cloud_points, cloud_radius)
    error = orbit_error = None
    if setup.scene.has_flow:
        exact = simulate(Setup.make(setup.scene, "exact", setup.values), h, run.steps * h, z0=base[None],
                         stride=run.stride)
        error, orbit_error = errors_over_time(run.z[:, 0], exact.z[: len(run.t), 0])
    Pi = setup.scene.momentum(setup.P, run.t, run.q[:, 0], run.p[:, 0])
    with np.errstate(over="ignore"):  # inf, as it should be, near a run's overflow (rk4 on charged, beta = exp(t))
        omega = separation_omega(run) / delta ** 2
    return Comparison(setup, run, figures[:, 0], figures[:, 1], paper_symplectic_form(run),
                      figures[:, 2], omega, cloud, area, error, Pi,
                      time.thread_time() - start, "the exact flow" if error is not None else None, orbit_error)


def loop_stride(steps, stride):
    """The stride at which a carried loop beside a run of `steps` steps recorded every `stride`-th is
    recorded: about CLOUD_SAMPLES times, a multiple of the run's stride."""
    return stride * max(1, steps // (stride * CLOUD_SAMPLES))


def carried_loop(setup, h, steps, stride, base, points, radius=0.05, progress=None):
    """The loop of `points` initial states around base (`ring_states`, of the given radius) carried
    by setup's method over `steps` steps of h, recorded every stride-th step and at the last: (its
    Trajectory, the area it encloses over its initial area, `loop_action`). A nonlinear scene's
    loop goes in compiled calls of about CHUNK member steps, each followed by progress(done, steps)
    where given: a caller stops it by raising from it (a linear one's, one matrix a step for every
    member, in one call, with no progress). The records are one call's to the bit. A member's failure (Newton,
    overflow) raises RunError carrying the loop up to it, as simulate's does."""
    ring = ring_states(base, radius, points)
    if setup.scene.kernel.linear:
        cloud = simulate(setup, h, steps * h, z0=ring, stride=stride)
    else:
        drive = Drive(setup, h, z0=ring, every=0, energy=False, maps=False)
        each = stride * max(1, CHUNK // (stride * points))
        parts = []
        for start in range(0, steps, each):
            try:
                part = drive.record(min(each, steps - start), stride)[0]
            except RunError as err:
                err.partial = joined(parts + [err.partial], drive.done)
                raise
            parts.append(part)
            if progress is not None:
                progress(drive.done, steps)
        cloud = joined(parts, steps)
    area = loop_action(cloud)
    return cloud, area / area[0]


def joined(parts, steps):
    """Consecutive records of one run (each part's first record is the previous part's last) as one
    Trajectory of `steps` steps."""
    first = parts[0]
    if len(parts) == 1:
        return dataclasses.replace(first, steps=steps)
    cut = [first] + [dataclasses.replace(p, t=p.t[1:], z=p.z[1:], pt=p.pt[1:], H=p.H[1:]) for p in parts[1:]]
    return dataclasses.replace(first, t=np.concatenate([p.t for p in cut]), z=np.concatenate([p.z for p in cut]),
                               pt=np.concatenate([p.pt for p in cut]), H=np.concatenate([p.H for p in cut]),
                               steps=steps, wall_s=sum(p.wall_s for p in parts), failure=parts[-1].failure)


def with_reference(comparison, reference, h):
    """The comparison with its error measured against a reference run (`reference.Reference`, its
    states at every multiple of h), and that run's own uncertainty: for the scenes without an
    exact flow."""
    run = comparison.run
    at = np.rint(run.t / h).astype(np.int64)
    states = reference.states[at]
    error, orbit_error = errors_over_time(run.z[:, 0], states)
    spread, orbit_spread = relative_over_time(reference.spread[at], states)
    return dataclasses.replace(comparison, error=error, orbit_error=orbit_error, against=reference.label,
                               uncertainty=spread, orbit_uncertainty=orbit_spread)


UNCERTAINTY_OVER = 10.0  # how far above the errors the reference's uncertainty is drawn (above it: a gap)
OWN = ("the reference's own uncertainty, relative as the trajectory error is (its distance from rk8 at twice its step, "
       "or its round-off where larger)")


class DrawnUncertainty(NamedTuple):
    """The reference run's own uncertainty as the trajectory error plots draw it (`drawn_uncertainty`):
    t, y (NaN where not drawn); side: "" where some of it is drawn, else "below" or "above" where all
    of it is (every error resolved by far, or none), or "across" (it passes from below them to above
    between two records); largest, its largest value."""

    t: np.ndarray
    y: np.ndarray
    side: str
    largest: float

    @property
    def text(self):
        """What a plot of the errors says of it: the app under its plots, a report in its caption."""
        if self.side == "below":
            return f"Below every error drawn: {OWN}, at most {self.largest:.1g} of the orbit's size; every error is resolved."
        if self.side == "above":
            return f"Above every error drawn: {OWN}; no error here is resolved."
        if self.side == "across":
            return (f"{OWN[0].upper()}{OWN[1:]} passes from below every error drawn to above them all between two "
                    "records: the errors after that are not resolved.")
        return (f"The grey line is {OWN}, drawn where it reaches the errors' range: an error below it is not resolved "
                "(the table says so of the final error).")


def drawn_uncertainty(comparisons):
    """The DrawnUncertainty of the comparisons' reference, relative to the orbit's size, from the
    first step (0 at t = 0), of the comparison that reached furthest (they share the reference; a
    stopped run is rerun at a finer stride, so more records do not mean further). Drawn only within
    the errors' own range, from the smallest positive error drawn to UNCERTAINTY_OVER times the
    largest, a gap elsewhere: a plot's axis follows every curve, and the uncertainty rose to 1e96
    where the reference's check overflows (charged, beta(t) = exp(t), T = 8.2: 110 decades, the
    errors squeezed into a few), and lay eight decades below both errors in the app's first view (they
    took the plot's top third). None without a reference run, or where no error drawn is positive
    and finite."""
    measured = [c for c in comparisons if c.orbit_uncertainty is not None]
    errors = np.concatenate([c.orbit_error[1:] for c in measured] or [np.empty(0)])
    errors = errors[np.isfinite(errors) & (errors > 0)]
    if not measured or not errors.size:
        return None
    c = max(measured, key=lambda c: c.run.t[-1])
    y = c.orbit_uncertainty[1:]
    low, high = errors.min(), UNCERTAINTY_OVER * errors.max()
    inside = (y >= low) & (y <= high)
    side = "" if inside.any() else "below" if np.all(y < low) else "above" if np.all(y > high) else "across"
    return DrawnUncertainty(c.run.t[1:], np.where(inside, y, np.nan), side, float(np.max(y)))


def compare_until_failure(setup, h, T, **options):
    """compare(), or, for a run that stops early, compare() up to the last completed step with
    the failure message. Returns (Comparison or None, message)."""
    try:
        return compare(setup, h, T, **options), ""
    except RunError as err:
        message = str(err)
        steps = err.step
    for _ in range(3):
        if steps < 1:
            return None, message
        try:
            return compare(setup, h, steps * h, **options), message
        except RunError as again:  # a companion run (the carried loop) failed sooner: that is what shows
            message = str(again)
            steps = min(steps - 1, again.step)
    return None, message


def gauge_study(scene, method, values, h, T, theta=None):
    """A scene with gauges (Scene.gauges) in each of them: per-gauge runs (the method applied in
    each gauge) and transported runs (the original-gauge run mapped by G_chi), with q, p and Pi each."""
    out = {}
    base = Setup.make(scene, method, {**values, "gauge": "original"}, theta)
    source = simulate(base, h, T)
    for g in base.scene.gauges:
        s = base.with_values(gauge=g)
        naive = simulate(s, h, T)
        moved = transport(source, s)
        out[g] = {kind: (r.t, r.q[:, 0], r.p[:, 0], s.scene.momentum(s.P, r.t, r.q[:, 0], r.p[:, 0]))
                  for kind, r in (("per-gauge", naive), ("transported", moved))}
    return out
