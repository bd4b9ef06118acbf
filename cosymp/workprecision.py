"""Work against precision: what each method costs for the error and the invariants it delivers.

`measure` runs cosymp's methods over step sizes and, with `peers=True`, scipy's `solve_ivp`
(RK45, DOP853, LSODA) over tolerances, on one scene to one horizon, and returns tidy rows
(one per run, ROW_FIELDS). `drift` runs each method at one step size to growing horizons and
returns the error and |H + p_t| as T grows. A run that fails (overflow, Newton, a peer that
gives up) is a row with NaN figures and its message in `status`.

Definitions (also the CSV's):
- error: ||z(T) - z_ref(T)|| / ||z_ref(T)|| over z = (q, p); error_abs without the division.
  z_ref: the scene's exact flow, else scipy DOP853 at rtol = atol = 3e-14, computed once per
  call; reference_uncertainty is its distance from cosymp's rk8 at a fine step (0 for a flow).
- wall_s: the minimum over repeats of one call (cosymp's `simulate` recording the final state,
  or `solve_ivp`), after one untimed warm-up call (which also compiles), repeated while the
  repeats take under `budget` seconds in all (at most MAX_REPEATS).
- rhs_evals: vector-field evaluations (scipy's nfev; stages x steps for explicit methods);
  for implicit methods on linear scenes the stage evaluations of the time coefficients (once a
  step: the stages' equations are linear), NaN where a Newton iteration makes it run-dependent (nonlinear scenes).
- H_ext_max_abs: max |H + p_t| over every step (cosymp) or every accepted step (peers).
- H_scale (drift): the largest |H| at the start and at the horizons so far, the scale of the
  rounding in H + p_t (see `at_roundoff`).
- det_max_dev: max |det M_k - 1| of the one-step tangent maps over every step, or over
  DIAG_MAPS evenly spaced steps for longer runs; NaN for peers (no step map to differentiate).
"""
import csv
import dataclasses
import json
import math
import time
from functools import partial

import numpy as np

from . import warm
from .diagnostics import relative_error
from .drive import CHUNK, Drive, map_every
from .errors import InputError, RunError
from .integrate import MAX_STEPS, Setup, check_step, exact_flow, get_scene, simulate
from .kernels.loops import energies
from .kernels.registry import family
from .methods import THETA_APPLIES, applicable
from .methods import method as get_method
from .reference import scipy_reference

ROW_FIELDS = ("scene", "solver", "kind", "order", "preserves", "h", "rtol", "T", "steps", "rhs_evals",
              "wall_s", "error", "error_abs", "H_ext_max_abs", "det_max_dev", "reference",
              "reference_uncertainty", "status")
DRIFT_FIELDS = ("scene", "solver", "order", "preserves", "h", "T", "steps", "error", "error_abs",
                "H_ext_abs", "H_ext_max_abs", "H_scale", "reference", "reference_uncertainty", "status")
PEERS = ("RK45", "DOP853", "LSODA")
PEER_RTOLS = tuple(10.0 ** -k for k in range(3, 14))
# The splitting family by its cheapest and its best member: with all five a plot held 17 curves
# (its legend outgrew the plot, and yoshida4 and blanes-moan4 were hard to tell apart). aba864
# applies to the near-integrable scene alone, where it is the fastest method: 15 curves there.
DEFAULT_METHODS = ("euler", "rk4", "rk8", "midpoint", "symplectic-euler", "gauss4", "gauss6",
                   "composition4", "composition6", "boris", "leapfrog", "blanes-moan6", "aba864")
DRIFT_METHODS = ("rk4", "midpoint", "symplectic-euler", "gauss4", "gauss6")
DRIFT_HORIZONS = tuple(float(m * 10 ** e) for e in range(2, 6) for m in (1, 2, 5)) + (1e6,)
DRIFT_MAX_STEPS = 10_000_000
REFERENCE_SHORT = "reference not finite"
REFERENCE_RTOL = 3e-14
MAX_REPEATS = 50
ERROR_FLOOR = 1e-13
STEP_GROWTH = math.sqrt(2.0)
ROUNDOFF = 10.0
"""A value is at round-off level within ROUNDOFF ε scale √steps (see `at_roundoff`)."""


def _setups(scene, methods, values, theta):
    scene = get_scene(scene) if isinstance(scene, str) else scene
    names = applicable(DEFAULT_METHODS, scene) if methods is None else list(methods)
    if not names:
        raise InputError("no methods given: pass at least one method name")
    if "exact" in names:
        raise InputError("'exact' is the reference these runs are measured against: leave it out of the methods")
    if theta is not None and not any(get_method(m).takes_theta for m in names):
        raise InputError(f"theta = {theta} is given, but {THETA_APPLIES} only: add one or drop theta")
    return scene, [Setup.make(scene, m, values, theta if get_method(m).takes_theta else None)
                   for m in dict.fromkeys(names)]


def check_horizon(T):
    """T as a float, or InputError saying what to change."""
    if not isinstance(T, (int, float)) or not math.isfinite(T) or T <= 0:
        raise InputError(f"T = {T} must be a positive finite horizon: pass T > 0")
    return float(T)


def solver_name(setup):
    return setup.method.name + (f"({setup.theta:g})" if setup.theta is not None else "")


def rhs_per_step(setup):
    """Vector-field evaluations per step (see the module's definitions), NaN if run-dependent:
    as the method's family declares it (kernels.registry)."""
    return family(setup.data).evaluations(setup.data, setup.scene.kernel.linear)


def timed(call, budget):
    """(result of the warm-up call, minimum wall time of the repeats after it)."""
    result = call()
    best = math.inf
    spent = 0.0
    for _ in range(MAX_REPEATS):
        start = time.perf_counter()
        call()
        took = time.perf_counter() - start
        best = min(best, took)
        spent += took
        if spent >= budget:
            break
    return result, best


def peer_solve(setup, solver, T, rtol):
    """scipy's solve_ivp with `solver` at rtol = atol on the extended ODE."""
    return scipy_reference(setup, T, rtol=rtol, atol=rtol, method=solver)


def reference_steps(scene, T):
    """Steps of the rk8 run that checks the reference to T (scenes without an exact flow), or
    InputError past the step cap."""
    steps = max(1, math.ceil(T / (0.01 * scene.time_scale)))
    if steps > MAX_STEPS:
        raise InputError(f"T = {T:g} is too long for a reference solution ({steps:.3g} steps of rk8 beyond the "
                         f"cap of {MAX_STEPS:.0e}): shorten T")
    return steps


def reference(setup, T):
    """(z_ref at T, label, uncertainty): the exact flow, else scipy DOP853 at 3e-14 (tighter
    than any peer run) checked against cosymp's rk8 at a step of 1% of the scene's time scale."""
    scene = setup.scene
    if scene.has_flow:
        try:
            z, _ = exact_flow(Setup.make(scene, "exact", setup.values), None, None, 0.0, T, 0.01 * scene.time_scale)
        except RunError as e:
            raise RunError(_beyond("the exact flow", T, e.time, T) + ", or a shorter T", T, 0) from None
        return z[0], "exact flow", 0.0
    steps = reference_steps(scene, T)
    sol = peer_solve(setup, "DOP853", T, REFERENCE_RTOL)
    if sol.status != 0:
        raise RunError(f"reference DOP853 failed: {sol.message}", T, 0)
    z_ref = sol.y[:-1, -1]
    rk8 = simulate(Setup.make(scene, "rk8", setup.values), T / steps, T, stride=steps)
    return z_ref, f"scipy DOP853 rtol {REFERENCE_RTOL:g}", relative_error(rk8.z[-1, 0], z_ref)[0]


@dataclasses.dataclass
class Scan:
    """Figures of one run over every step: final state and time, max |H + p_t|, sampled det."""

    z: np.ndarray
    pt: float
    t: float
    H_ext_max_abs: float
    det_max_dev: float


def scan(setup, h, steps, z0=None, pt0=None, t0=0.0, with_det=True, tick=None, growth=False,
         energy=True):
    """Run steps of h from t0 by the fused driver: max |H + p_t| over every step (NaN without
    `energy`) and max |det M_k - 1| over every step or over DIAG_MAPS evenly spaced ones (RunError
    on failure). growth: also multiply every step's tangent map (then det is over every step
    too); returns (Scan, the driver's diagnostics.MapGrowth or None). tick() is called after
    each chunk."""
    every = map_every(steps, with_det, growth)
    drive = Drive(setup, h, z0=z0, pt0=pt0, t0=t0, every=every, growth=growth, energy=energy, maps=with_det)
    drive.run(steps, tick and (lambda done, total: tick()))
    det = drive.det_max_dev if with_det else math.nan
    return Scan(drive.Z[0], float(drive.PT[0]), drive.t, drive.H_ext_max_abs, det), drive.growth


def _base_row(scene, name, kind, order, preserves, T, ref, unc):
    row = dict.fromkeys(ROW_FIELDS, math.nan)
    row.update(scene=scene.name, solver=name, kind=kind, order=order, preserves=preserves, T=T,
               reference=ref, reference_uncertainty=unc, status="ok")
    return row


def method_point(setup, h, T, z_ref, ref, unc, budget):
    """One row: setup's method with step h to T (T/h whole steps)."""
    steps = check_step(h, T)
    row = _base_row(setup.scene, solver_name(setup), "cosymp", setup.method.order_at(setup.theta),
                    setup.method.preserves_at(setup.theta), T, ref, unc)
    row.update(h=h, steps=steps, rhs_evals=rhs_per_step(setup) * steps)
    try:
        run, row["wall_s"] = timed(lambda: simulate(setup, h, T, stride=steps), budget)
        row["error"], row["error_abs"] = relative_error(run.z[-1, 0], z_ref)
        s = scan(setup, h, steps, with_det=setup.method.name != "exact")[0]
        row["H_ext_max_abs"], row["det_max_dev"] = s.H_ext_max_abs, s.det_max_dev
    except RunError as e:
        row.update(wall_s=math.nan, error=math.nan, error_abs=math.nan, status=str(e))
    return row


def peer_point(setup, solver, rtol, T, z_ref, ref, unc, budget):
    """One row: scipy's solve_ivp with `solver` at rtol = atol to T."""
    row = _base_row(setup.scene, f"scipy-{solver}", "scipy", {"RK45": 5, "DOP853": 8}.get(solver, math.nan),
                    "none", T, ref, unc)
    row["rtol"] = rtol
    sol, wall = timed(lambda: peer_solve(setup, solver, T, rtol), budget)
    row.update(steps=len(sol.t) - 1, rhs_evals=sol.nfev)
    if sol.status != 0 or not np.all(np.isfinite(sol.y[:, -1])):
        row["status"] = f"solve_ivp failed: {sol.message}"
        return row
    m = 2 * setup.scene.ndof
    row["wall_s"] = wall
    row["error"], row["error_abs"] = relative_error(sol.y[:m, -1], z_ref)
    H = np.empty((len(sol.t), 1))
    energies(setup.P, np.ascontiguousarray(sol.t), np.ascontiguousarray(sol.y[:m].T[:, None, :]), H)
    row["H_ext_max_abs"] = float(np.max(np.abs(H[:, 0] + sol.y[m])))
    return row


def step_counts(first, last):
    """Whole step counts from first to last, growing by about STEP_GROWTH each."""
    counts = [first]
    while counts[-1] * STEP_GROWTH <= last:
        counts.append(max(counts[-1] + 1, round(counts[-1] * STEP_GROWTH)))
    return counts


def measure(scene, methods=None, values=None, T=None, hs=None, theta=None, peers=False,
            rtols=PEER_RTOLS, max_steps=1 << 20, budget=0.2, progress=None, partial=None, prepare=None):
    """Work-precision rows for a scene (see the module's definitions).

    hs: step sizes for every method (rounded so T/h is whole); by default each method starts at
    the scene's time scale and refines by STEP_GROWTH until its error is below ERROR_FLOOR,
    stops decreasing for two refinements (round-off), or max_steps is reached.
    progress(done, total, label) is called before each run; total counts methods and peers.
    partial(rows), if given, is called with a copy of the rows so far after each run.
    The input is checked before the first progress report; prepare(keys), if given, is called
    then, before any run, with the keys of the kernel units the runs and their reference need (`warm.run_keys`): the
    command line compiles the missing ones there.
    """
    scene, setups = _setups(scene, methods, values, theta)
    T = scene.T if T is None else check_horizon(T)
    scene.check_horizon(setups[0].values, T)
    if hs is not None:
        counts = sorted({check_step(h, T) for h in hs})
    else:
        first = max(1, math.ceil(T / scene.time_scale))
        if first > max_steps:
            raise InputError(f"max_steps = {max_steps} is below the first run's {first} steps (T over the "
                             "scene's time scale): raise it or shorten T")
        counts = step_counts(first, max_steps)
    if not scene.has_flow:
        reference_steps(scene, T)
    if prepare is not None:
        prepare(warm.run_keys(scene, [s.method.name for s in setups]))
    solvers = [solver_name(s) for s in setups] + (list(PEERS) if peers else [])
    total = len(solvers)
    report = progress or (lambda done, total, label: None)
    report(0, total, "reference")
    z_ref, ref, unc = reference(setups[0], T)
    rows = []
    for i, s in enumerate(setups):
        worse = 0
        best = math.inf
        for N in counts:
            report(i, total, f"{solvers[i]} h = {T / N:.3g}")
            row = method_point(s, T / N, T, z_ref, ref, unc, budget)
            rows.append(row)
            if partial is not None:
                partial(list(rows))
            if hs is None:
                err = row["error"]
                worse = worse + 1 if not err < best else 0
                best = best if math.isnan(err) else min(best, err)
                if err < ERROR_FLOOR or (worse >= 2 and best < 1e-6):
                    break
    for j, solver in enumerate(PEERS if peers else ()):
        for rtol in rtols:
            report(len(setups) + j, total, f"scipy {solver} rtol = {rtol:.0e}")
            rows.append(peer_point(setups[0], solver, rtol, T, z_ref, ref, unc, budget))
            if partial is not None:
                partial(list(rows))
    report(total, total, "done")
    return rows


def drift(scene, methods=DRIFT_METHODS, values=None, h=None, horizons=None, theta=None, progress=None,
          prepare=None):
    """Error and |H + p_t| at growing horizons, each method at one step size h (default the
    scene's), continuing one run through the horizons. The reference: the exact flow, else rk8
    at h/2 through the same horizons, with rk8 at h for its uncertainty. Default horizons:
    DRIFT_HORIZONS up to DRIFT_MAX_STEPS steps of h. Horizons the reference cannot reach (it
    overflows) are NaN rows whose status says so; progress is reported at least every CHUNK
    steps, so raising from it stops the run within a fraction of a second. prepare: as measure's."""
    scene, setups = _setups(scene, methods, values, theta)
    h = scene.h if h is None else h
    check_step(h, h)
    if horizons is None:
        horizons = [T for T in DRIFT_HORIZONS if T <= h * DRIFT_MAX_STEPS] or [h * DRIFT_MAX_STEPS]
    horizons = sorted({check_horizon(T) for T in horizons})
    if h >= horizons[0]:
        raise InputError(f"h = {h:g} is not below the shortest horizon {horizons[0]:g}: choose a smaller h")
    counts = [check_step(h, T) for T in horizons]
    if counts[-1] > DRIFT_MAX_STEPS:
        raise InputError(f"T = {horizons[-1]:g} takes {counts[-1]:.3g} steps of h = {h:g}, over this study's "
                         f"{DRIFT_MAX_STEPS:.0e}: increase h or shorten the horizons")
    scene.check_horizon(setups[0].values, counts[-1] * h)
    if prepare is not None:
        prepare(warm.run_keys(scene, [s.method.name for s in setups]))
    total = len(setups) + (0 if scene.has_flow else 1)
    report = progress or (lambda done, total, label: None)
    refs, unc, label, ref_failure = _drift_reference(setups[0], h, counts, report, total)
    rows = []
    for i, s in enumerate(setups):
        where = f"{solver_name(s)} to T = {horizons[-1]:g}"
        tick = partial(report, i + total - len(setups), total, where)
        tick()
        z, pt, done, H_max = None, None, 0, 0.0
        H = np.empty((1, 1))
        energies(s.P, np.array([0.0]), s.start[None], H)
        scale = abs(H[0, 0])
        failure = ""
        for k, (T, N) in enumerate(zip(horizons, counts)):
            row = dict.fromkeys(DRIFT_FIELDS, math.nan)
            row.update(scene=scene.name, solver=solver_name(s), order=s.method.order_at(s.theta),
                       preserves=s.method.preserves_at(s.theta), h=h, T=N * h, steps=N, reference=label,
                       status=failure or "ok")
            if k >= len(refs):
                row["status"] = ref_failure
            elif not failure:
                try:
                    sc = scan(s, h, N - done, z0=z, pt0=pt, t0=done * h, with_det=False, tick=tick)[0]
                except RunError as e:
                    failure = row["status"] = str(e)
                else:
                    z, pt, done = sc.z[None], np.array([sc.pt]), N
                    H_max = max(H_max, sc.H_ext_max_abs)
                    energies(s.P, np.array([N * h]), z[None], H)
                    scale = max(scale, abs(H[0, 0]))
                    row["error"], row["error_abs"] = relative_error(z[0], refs[k])
                    row.update(H_ext_abs=abs(H[0, 0] + pt[0]), H_ext_max_abs=H_max, H_scale=scale,
                               reference_uncertainty=unc[k])
            rows.append(row)
    report(total, total, "done")
    return rows


def _drift_reference(setup, h, counts, report, total):
    """Reference states at counts[i] * h as far as the reference reaches, their uncertainties,
    the reference's label and why it stopped short ('' if it did not)."""
    scene = setup.scene
    if scene.has_flow:
        exact = Setup.make(scene, "exact", setup.values)
        refs, z, pt, t = [], None, None, 0.0
        for N in counts:
            try:
                z, pt = exact_flow(exact, z, pt, t, N * h, h)
            except RunError as e:
                return refs, [0.0] * len(refs), "exact flow", _beyond("the exact flow", N * h, e.time, counts[-1] * h)
            refs.append(z[0])
            t = N * h
        return refs, [0.0] * len(refs), "exact flow", ""
    tick = partial(report, 0, total, "reference (rk8)")
    rk8 = Setup.make(scene, "rk8", setup.values)
    fine, failed = _checkpoints(rk8, h / 2, [2 * N for N in counts], tick)
    coarse, _ = _checkpoints(rk8, h, counts[:len(fine)], tick)
    why = _beyond("the rk8 reference", counts[len(fine)] * h, failed.time, counts[-1] * h) if failed else ""
    return fine, [relative_error(c, f)[0] for f, c in zip(fine, coarse)], "rk8 at h/2", why


def _beyond(what, T, t, top):
    """Why the reference stops before T: where the state left floating point, and how much more
    slowly it must grow to reach `top`, the largest horizon asked for (a state that passes 1e308
    grows exponentially: log |z| grows in proportion to t)."""
    return (f"{REFERENCE_SHORT} at T = {T:g}: {what} leaves floating point at t ≈ {t:.4g} (|z| > 1.8e308), so no "
            f"error can be measured beyond it at these parameters; T = {top:g} needs parameters with a growth rate "
            f"{math.ceil(10 * top / t) / 10:g}× smaller")


def _checkpoints(setup, h, counts, tick):
    """States at counts[i] steps of h, run in pieces of at most CHUNK steps (tick after each),
    and the RunError that stopped it before the last count (None if it did not)."""
    z, pt, done, out = None, None, 0, []
    for N in counts:
        while done < N:
            n = min(CHUNK, N - done)
            try:
                run = simulate(setup, h, n * h, z0=z, pt0=pt, t0=done * h, stride=n)
            except RunError as e:
                return out, e
            z, pt, done = run.z[-1], run.pt[-1], done + n
            tick()
        out.append(z[0])
    return out, None


def _growth_points(rows, solver, key):
    """(T, value, round-off bound) of the drift rows a growth exponent is fitted over. For the
    error: the horizons before it first reaches 0.1 (where it saturates at the orbit's size, and a
    phase error can wrap back below it) and above ten times the reference's uncertainty."""
    pts = []
    for r in sorted((r for r in rows if r["solver"] == solver), key=lambda r: r["T"]):
        v = r[key]
        if key == "error" and not v < 0.1:
            break
        if v > 0 and (key != "error" or v > 10 * r["reference_uncertainty"]):
            scale = 1.0 if key == "error" else r.get("H_scale", math.nan)
            pts.append((r["T"], v, roundoff_bound(scale, r["steps"])))
    return pts


def roundoff_bound(scale, steps):
    """ROUNDOFF eps scale sqrt(steps): how far unbiased rounding of a value of size `scale` goes in
    `steps` steps, by `at_roundoff`'s rule."""
    return ROUNDOFF * np.finfo(float).eps * scale * math.sqrt(steps)


def growth_exponent(rows, solver, key="error"):
    """Slope of log(key) against log(T) for one solver's drift rows (over `_growth_points`), NaN
    with fewer than 3 points."""
    pts = _growth_points(rows, solver, key)
    if len(pts) < 3:
        return math.nan
    T, v = np.log(np.array([(T, v) for T, v, _ in pts])).T
    return float(np.polyfit(T, v, 1)[0])


def at_roundoff(rows, solver, key="error"):
    """Whether every value a growth exponent of `key` is fitted over is at round-off level: within
    ROUNDOFF ε s √N at a horizon of N steps, s the scale of the value's rounding (|H|, `H_scale`,
    for |H + p_t|; 1 for the relative error). The slope of such values measures the rounding, not
    the method. False with no such values.

    Each step rounds H + p_t by about ε |H|; unbiased roundings add up to about ε |H| √N. Measured
    (max |H + p_t| / ε |H| √N): gauss4, gauss6 and rk8 on charged (h = 0.001, 1e5 to 1e6 steps),
    gauss6 and rk8 on modulated and on damped at γ = 2e-4, rk8 on decaying (h = 0.1, 1e3 to 1e5
    steps): 0.6 to 6.4, growing like T^0 to T^1.2 (rk8 has no truncation drift at these steps: its
    growth is the rounding's); the smallest value that is not rounding, rk8's on damped at
    γ = 0.2 and T = 5000 (e^(γt) spanning 434 decades), 47; every method's drift at the scenes'
    default steps, 190 and more. ROUNDOFF = 10 lies between. RK4 on charged at h = 0.001 (4.5 to 7,
    growing like T) is at round-off by this rule: rk8's rounding there is as large and grows as fast."""
    pts = _growth_points(rows, solver, key)
    return bool(pts) and all(v <= bound for _, v, bound in pts)


def growth_text(rows, solver, key="error"):
    """The growth exponent as a table or a legend shows it: '0.97'; 'round-off' where the values
    are at round-off level (`at_roundoff`); '–' with fewer than 3 horizons to fit."""
    if at_roundoff(rows, solver, key):
        return "round-off"
    g = growth_exponent(rows, solver, key)
    return f"{g:.2f}".replace("-0.00", "0.00") if math.isfinite(g) else "–"


def cost_at(rows, solver, error):
    """Wall time at which `solver` reaches `error`: log-log interpolation between its cheapest
    run below it and the run before (by cost); an upper bound (that run's time) when its
    cheapest run is already below; NaN if it never gets there."""
    pts = sorted((r["wall_s"], r["error"]) for r in rows if r["solver"] == solver
                 and r["wall_s"] == r["wall_s"] and r["error"] == r["error"])
    for k, (w, e) in enumerate(pts):
        if e <= error:
            if k == 0:
                return w
            w0, e0 = pts[k - 1]
            f = math.log(error / e0) / math.log(e / e0)
            return math.exp(math.log(w0) + f * math.log(w / w0))
    return math.nan


def targets(rows, errors=(1e-6, 1e-9)):
    """Cost of every solver at each target error, and the issue's ratios: DOP853 over cosymp's
    fastest, and cosymp's best structure-preserving method over cosymp's rk4."""
    solvers = list(dict.fromkeys(r["solver"] for r in rows))
    kinds = {r["solver"]: (r["kind"], r["preserves"]) for r in rows}
    out = {"cost": {e: {s: cost_at(rows, s, e) for s in solvers} for e in errors}, "ratios": {}}
    for e in errors:
        cost = out["cost"][e]
        ours = {s: c for s, c in cost.items() if kinds[s][0] == "cosymp" and not math.isnan(c)}
        sp = {s: c for s, c in ours.items() if kinds[s][1] == "symplectic"}
        fastest = min(ours, key=ours.get) if ours else None
        best_sp = min(sp, key=sp.get) if sp else None
        out["ratios"][e] = {
            "fastest": fastest,
            "dop853_over_fastest": cost.get("scipy-DOP853", math.nan) / ours[fastest] if fastest else math.nan,
            "best_symplectic": best_sp,
            "symplectic_over_rk4": sp[best_sp] / cost.get("rk4", math.nan) if best_sp else math.nan,
        }
    return out


def write_rows(rows, path, fields=ROW_FIELDS):
    """Tidy rows to CSV or JSON (by the file's extension)."""
    path = str(path)
    if path.endswith(".json"):
        with open(path, "w") as f:
            json.dump([{k: _json_value(r[k]) for k in fields} for r in rows], f, indent=1, ensure_ascii=False)
            f.write("\n")
    elif path.endswith(".csv"):
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fields, extrasaction="ignore")
            w.writeheader()
            w.writerows({k: repr(float(v)) if isinstance(v, float) else v for k, v in r.items()} for r in rows)
    else:
        raise InputError(f"cannot write '{path}': name a .csv or .json file")


def _json_value(v):
    if isinstance(v, float):
        return float(v) if math.isfinite(v) else None
    return v


def read_rows(path):
    """Rows written by write_rows (CSV or JSON), numbers as floats and ints again."""
    path = str(path)
    if path.endswith(".json"):
        with open(path) as f:
            return [{k: math.nan if v is None else v for k, v in r.items()} for r in json.load(f)]
    with open(path, newline="") as f:
        return [{k: _parse(v) for k, v in r.items()} for r in csv.DictReader(f)]


def _parse(text):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text
