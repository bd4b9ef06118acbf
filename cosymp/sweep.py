"""Sweeps: figures of one method over a grid of parameters, on this machine or a Dask cluster.

A grid has one axis per varied name (a scene parameter, h, T or theta), each NUM values from
START to STOP, evenly spaced or (`log`) geometrically. Every grid point is one run of the method
from the scene's initial state with step h to horizon T, and gives the requested measures:

- H_ext_max_abs: max |H + p_t| over every step (0 for the exact flow of the extended system).
- det_max_dev: max |det M_k - 1| over the one-step tangent maps M_k of every step.
- error_final: ||z(T) - z_ref(T)|| / ||z_ref(T)|| over z = (q, p); z_ref the exact flow, else
  rk8 at a step of at most 2% of the scene's time scale (reference.reference_final), whose own
  uncertainty, relative as the error is, comes beside it (error_final_uncertainty: where it is
  at least as large, the error is not resolved).
- growth: ln(sigma_max(M_(N-1) ... M_0)) / T, the largest finite-time growth exponent of the
  method's own map along the run (diagnostics.MapGrowth): 0 for a bounded linear map, the
  Floquet exponent inside a Mathieu tongue, ln|R(ih)|/h for a one-step method with stability
  function R on the harmonic oscillator.

A run that fails (overflow, Newton) leaves NaN measures and its message in `status`; a run whose
reference fails keeps its other measures and t_final, error_final NaN. A run takes
T/h rounded up steps of h: where T is not a whole number of them, it ends past T, at t_final (a
column of the written rows; the summary counts such points).

Points are independent and deterministic, so the figures are identical however they are
spread: in-process, tasks run on a thread pool as wide as the machine (the compiled loops
release the GIL); `workers=N` starts a Dask LocalCluster of N single-threaded processes;
`scheduler=ADDRESS` uses a running Dask cluster. Points are grouped into tasks of about
TASK_SECONDS (timed on the first point), and into at least TASKS_PER_WORKER tasks per worker
while the grid allows, so scheduling costs a small fraction and the workers stay balanced.
"""
import csv
import dataclasses
import itertools
import math
import os
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

import numpy as np

from . import warm
from .drive import batch_runs, batchable
from .errors import CosympError, InputError, as_number, quoted
from .integrate import Setup, check_step, get_scene
from .methods import THETA_APPLIES
from .methods import method as get_method
from .reference import check_reference, is_resolved, reference_final, relative_final
from .workprecision import check_horizon, scan

MEASURES = ("H_ext_max_abs", "det_max_dev", "error_final", "growth")
BATCHED_MEASURES = {"H_ext_max_abs", "det_max_dev", "growth"}
BATCH = 256
RUN_NAMES = ("h", "T", "theta")
MAX_POINTS = 1_000_000
MAX_AXIS = 10_000
TASK_SECONDS = 0.5
TASKS_PER_WORKER = 4
FORMATS = (".csv", ".parquet")
SKIP_ERROR = "measure something other than error_final"  # how a sweep leaves the error at T out


def _number(text, label):
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{label} = {quoted(text.strip())} is not a number") from None
    return as_number(value, label)


@dataclasses.dataclass(frozen=True)
class Axis:
    """One varied name and its values (evenly spaced, or geometrically if `log`)."""

    name: str
    values: tuple
    log: bool = False

    @classmethod
    def parse(cls, text):
        """From NAME=START:STOP:NUM or NAME=START:STOP:NUM:log."""
        name, sep, spec = str(text).partition("=")
        parts = spec.split(":")
        if not sep or not name.strip() or len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] != "log"):
            raise InputError(f"--vary {quoted(text)} is not NAME=START:STOP:NUM (or NAME=START:STOP:NUM:log), "
                             "e.g. eps=0:0.5:50")
        start, stop = (_number(v, f"{name.strip()}'s {w}") for v, w in zip(parts[:2], ("start", "stop")))
        return cls.make(name.strip(), start, stop, parts[2].strip(), log=len(parts) == 4)

    @classmethod
    def make(cls, name, start, stop, num, log=False):
        try:
            num = int(num)
        except (TypeError, ValueError):
            raise InputError(f"{name}: NUM = {quoted(num)} must be a whole number of values") from None
        if not 1 <= num <= MAX_AXIS:
            raise InputError(f"{name}: NUM = {num} must be between 1 and {MAX_AXIS}")
        if num == 1 and start != stop:
            raise InputError(f"{name}: one value cannot span {start:g} to {stop:g}: give NUM >= 2 or START = STOP")
        if log:
            if not (start > 0 and stop > 0):
                raise InputError(f"{name}: a log axis needs START and STOP > 0 (got {start:g}, {stop:g})")
            values = np.geomspace(start, stop, num)
        else:
            values = np.linspace(start, stop, num)
        # to 15 significant digits of the axis (of each value on a log axis): the binary noise of the
        # spacing (0.6000000000000001 for 0:0.8:5, 1.4e-17 for the 0 of -0.1:0.2:4) is not a value anyone
        # asked for, and it was what the rows and the map's axis said; the ends as typed
        scale = max(abs(start), abs(stop))
        values = ([start] + [_significant(v, v if log else scale) for v in values[1:-1]] + [stop]) if num > 1 else [start]
        if len({f"{v:.15g}" for v in values}) < num:
            raise InputError(f"{name}: {num} values from {float(start)!r} to {float(stop)!r} are not all different "
                             "at 15 digits (the same run twice): use fewer values or a wider range")
        return cls(name, tuple(values), log)


def _significant(v, scale):
    """v rounded to 15 significant digits of scale (> 0 or 0)."""
    rounded = float(f"{v:.15g}") if scale == 0 else round(float(v), 14 - math.floor(math.log10(abs(scale))))
    return rounded + 0.0  # -1e-17 rounds to -0.0, written so


@dataclasses.dataclass(frozen=True)
class Plan:
    """A checked sweep: everything a worker needs to compute any of its points (picklable)."""

    scene: str
    method: str
    values: tuple
    theta: object
    h: float
    T: float
    axes: tuple
    measures: tuple

    @property
    def shape(self):
        return tuple(len(a.values) for a in self.axes)

    @property
    def size(self):
        return math.prod(self.shape)

    def point(self, index):
        """{name: value} of the varied names at flat index (C order: the first axis slowest)."""
        return self.points([index])[0]

    def points(self, indices):
        """point() of each flat index."""
        cols = self.columns(indices)
        return [dict(zip(cols, vals)) for vals in zip(*(c.tolist() for c in cols.values()))]

    def columns(self, indices):
        """{name: (len(indices),) array} of the varied names' values at flat indices."""
        idx = np.unravel_index(np.asarray(indices, dtype=np.int64), self.shape)
        return {a.name: np.asarray(a.values)[i] for a, i in zip(self.axes, idx)}

    def unit_keys(self):
        """The keys of the kernel units (cosymp.warm) its points need: the method's, and the
        reference's for error_final (the exact flow, else rk8)."""
        return warm.run_keys(get_scene(self.scene), [self.method], reference="error_final" in self.measures)

    def step_counts(self):
        """(steps of each (h, T) pair of the grid, how many points share each pair): from the h and
        T axes alone, without building any point's setup."""
        hs = next((a.values for a in self.axes if a.name == "h"), (self.h,))
        Ts = next((a.values for a in self.axes if a.name == "T"), (self.T,))
        steps = np.array([[check_step(h, T) for T in Ts] for h in hs])
        return steps, self.size // steps.size

    def run_of(self, point):
        """(setup, h, T) of a grid point."""
        run = {"h": self.h, "T": self.T, "theta": self.theta}
        values = dict(self.values)
        for name, v in point.items():
            (run if name in RUN_NAMES else values)[name] = v
        return Setup.make(self.scene, self.method, values, run["theta"]), run["h"], run["T"]


def variables(scene, method):
    """The names a sweep can vary: the scene's numeric parameters, h, T, and theta for the
    methods that take it."""
    numeric = [p.name for p in scene.params if not p.choices and not isinstance(p.default, str)]
    return numeric + ["h", "T"] + (["theta"] if method.takes_theta else [])


def plan(scene, method, axes, measures=("growth",), values=None, theta=None, h=None, T=None):
    """A Plan, or InputError saying what to change. axes: Axis objects or NAME=START:STOP:NUM
    texts. The grid's corners are checked here (bounds are intervals), so a sweep does not fail
    on its last point for a reason known at the start."""
    sc = get_scene(scene) if isinstance(scene, str) else scene
    m = get_method(method) if isinstance(method, str) else method
    axes = tuple(axes)
    if not axes:
        raise InputError("nothing to sweep: give at least one --vary NAME=START:STOP:NUM")
    allowed = variables(sc, m)
    for a in axes:  # the name first: an axis' values say nothing where the name cannot be varied
        n = a.name if isinstance(a, Axis) else str(a).partition("=")[0].strip()
        if n and n not in allowed:
            why = f" ({THETA_APPLIES})" if n == "theta" else ""
            raise InputError(f"cannot vary {quoted(n)} on scene '{sc.name}'{why}: choose from {', '.join(allowed)}")
    axes = tuple(a if isinstance(a, Axis) else Axis.parse(a) for a in axes)
    names = [a.name for a in axes]
    if len(set(names)) < len(names):
        raise InputError(f"{quoted(max(names, key=names.count))} is varied twice: give each name once")
    measures = tuple(dict.fromkeys([measures] if isinstance(measures, str) else measures))
    for name in measures:
        if name not in MEASURES:
            raise InputError(f"unknown measure {quoted(name)}: choose from {', '.join(MEASURES)}")
    if not measures:
        raise InputError(f"no measure given: choose from {', '.join(MEASURES)}")
    if m.name == "exact" and {"det_max_dev", "growth"} & set(measures):
        raise InputError("det_max_dev and growth need the method's one-step maps, which the exact flow does "
                         "not provide: choose another method or measure")
    size = math.prod(len(a.values) for a in axes)
    if size > MAX_POINTS:
        raise InputError(f"the grid has {size:,} points, over the cap of {MAX_POINTS:,}: use fewer values")
    fixed = dict(values or {})
    run = {"h": h, "T": T, "theta": theta}
    for n in names:
        if n in fixed or run.get(n) is not None:
            raise InputError(f"{quoted(n)} is both given a fixed value and varied: drop one")
    vals = sc.values(fixed)
    idle = [n for n in names if n in sc.unused(vals)]
    if idle:
        raise InputError(f"{quoted(idle[0])} has no effect on scene '{sc.name}' with these values (every point would "
                         f"give the same run): vary another name, or set the value that makes it act")
    p = Plan(sc.name, m.name, tuple(fixed.items()), theta,
             sc.h if h is None else as_number(h, "h"), sc.T if T is None else check_horizon(T),
             axes, measures)
    corners = itertools.product(*[(a.values[0], a.values[-1]) for a in axes])
    for corner in corners:
        setup, hh, TT = p.run_of(dict(zip(names, corner)))
        steps = check_step(hh, TT)
        check_horizon(TT)
        setup.scene.check_horizon(setup.values, steps * hh)
    if "error_final" in measures:
        # Not at the corners only: the reference's rk8 steps per step h round up to an even number, so
        # a step inside the h axis can take twice a corner's (at the longest T, where they are most).
        longest = max(next((a.values for a in axes if a.name == "T"), (p.T,)))
        for hh in next((a.values for a in axes if a.name == "h"), (p.h,)):
            try:
                check_reference(setup, hh, longest, SKIP_ERROR)
            except InputError as e:
                raise InputError(f"at h = {hh:.10g} and T = {longest:.10g}, {e}") from None
    return p


def figures(setup, h, T, measures):
    """(the measures at one point, status, t_final) for one run (see the module's definitions).
    A run that ended at its final time keeps its measures and t_final where only its reference
    failed (error_final NaN, the reference's message the status)."""
    out = dict.fromkeys(_columns(measures), math.nan)
    try:
        steps = check_step(h, T)
        s, growth = scan(setup, h, steps, with_det="det_max_dev" in measures, growth="growth" in measures,
                         energy="H_ext_max_abs" in measures)
    except CosympError as e:
        return out, str(e), math.nan
    out["H_ext_max_abs"], out["det_max_dev"] = s.H_ext_max_abs, s.det_max_dev
    if growth is not None:
        out["growth"] = growth.log_norm() / (steps * h)
    status = "ok"
    if "error_final" in measures:
        try:
            zr, spread = reference_final(setup, h, T, skip=SKIP_ERROR)
        except CosympError as e:
            status = str(e)
        else:
            out["error_final"], out[UNCERTAINTY] = relative_final(s.z, zr[0], spread[0])
    return {k: out[k] for k in _columns(measures)}, status, steps * h


UNCERTAINTY = "error_final_uncertainty"


def _columns(measures):
    """What a point gives beside t_final: its measures, and the uncertainty of error_final's."""
    return (*measures, *([UNCERTAINTY] if "error_final" in measures else []))


def evaluate(p, indices, stop=None):
    """Figures of the points at flat indices, in order: (indices, {measure: array, and t_final},
    statuses, seconds). Stops early (fewer points) once `stop` (a threading.Event) is set. Consecutive
    points that share a run (h, T, theta) and differ in scene parameters run BATCH at a time in
    one compiled call (drive.batch_runs) where the measures allow it; the others, and any point
    of a batch that failed (for its message), one by one (figures)."""
    start = time.perf_counter()
    indices = np.asarray(list(indices), dtype=np.int64)
    cols = p.columns(indices)
    out = {k: np.full(len(indices), math.nan) for k in (*_columns(p.measures), "t_final")}
    statuses = []
    batched = _batched(p)
    pos = 0
    for end in _groups(cols, len(indices), batched):
        if stop is not None and stop.is_set():
            break
        part = {name: c[pos:end] for name, c in cols.items()}
        results = _batch_figures(p, part) if batched else _each_figures(p, part)
        for k, column in out.items():
            column[pos:end] = results[0][k]
        statuses.extend(results[1])
        pos = end
    return (indices[:pos].tolist(), {k: v[:pos] for k, v in out.items()}, statuses,
            time.perf_counter() - start)


def _groups(cols, count, batched):
    """Where evaluate's compiled calls end: after BATCH points, and wherever the run (h, T,
    theta) changes (every point alone where the points cannot be batched)."""
    if not batched or count == 0:
        return list(range(1, count + 1))
    run = [cols[name] for name in RUN_NAMES if name in cols]
    changes = np.flatnonzero(np.any([c[1:] != c[:-1] for c in run], axis=0)) + 1 if run else np.empty(0, int)
    ends = []
    for a, b in zip([0, *changes.tolist()], [*changes.tolist(), count]):
        ends.extend(range(min(a + BATCH, b), b, BATCH))
        ends.append(b)
    return ends


def _point_figures(p, point):
    try:
        setup, h, T = p.run_of(point)
        return figures(setup, h, T, p.measures)
    except InputError as e:
        return dict.fromkeys(_columns(p.measures), math.nan), str(e), math.nan


def _each_figures(p, cols):
    """({measure: array, and t_final}, statuses) of the points of cols, one run each."""
    names = list(cols)
    results = [_point_figures(p, dict(zip(names, vals))) for vals in zip(*(cols[n].tolist() for n in names))]
    out = {k: np.array([r[0][k] for r in results], dtype=float) for k in _columns(p.measures)}
    out["t_final"] = np.array([r[2] for r in results], dtype=float)
    return out, [r[1] for r in results]


def _batched(p):
    """Whether the plan's points can run in batches: measures of the run alone (no reference), a
    method with maps where maps are measured, a scene whose parameters are all numbers, and
    varied scene parameters that are fields of its parameter tuple or initial conditions."""
    if not set(p.measures) <= BATCHED_MEASURES:
        return False
    setup = p.run_of(p.point(0))[0]
    scene = setup.scene
    direct = set(scene.Params._fields) | {q.name for q in scene.params if q.initial}
    return batchable(setup) and all(a.name in direct for a in p.axes if a.name not in RUN_NAMES)


def _batch_figures(p, cols):
    """({measure: array, and t_final}, statuses) of points sharing a run, from one compiled call; a failed
    point is run again on its own for its message. The parameter rows and initial states are
    the first point's, with the varied scene parameters' columns replaced (drive.batchable: the
    scene's parameter tuple holds its parameters by name); the plan checked the grid's corners
    against the parameters' bounds, which are intervals."""
    size = len(next(iter(cols.values())))
    first = {name: float(c[0]) for name, c in cols.items()}
    setup, h, T = p.run_of(first)
    scene = setup.scene
    vals = scene.values({**dict(p.values), **{k: v for k, v in first.items() if k not in RUN_NAMES}})
    R = np.tile(np.array(scene.pack(vals), dtype=float), (size, 1))
    Z0 = np.tile(np.concatenate(scene.initial(vals)), (size, 1))
    starts = [q.name for q in scene.params if q.initial]
    for name, c in cols.items():
        if name in scene.Params._fields:
            R[:, scene.Params._fields.index(name)] = c
        elif name in starts:
            Z0[:, starts.index(name)] = c
    steps = check_step(h, T)
    out = batch_runs(setup, h, steps, R, Z0, with_det="det_max_dev" in p.measures,
                     growth="growth" in p.measures, energy="H_ext_max_abs" in p.measures)
    values = {"H_ext_max_abs": out["H_ext_max_abs"], "det_max_dev": out["det_max_dev"]}
    if "growth" in p.measures:
        values["growth"] = out["growth"] / (steps * h)
    values = {k: np.array(values[k], dtype=float) for k in p.measures}
    values["t_final"] = np.full(size, steps * h)
    statuses = ["ok"] * size
    names = list(cols)
    for j in np.flatnonzero(out["failed"]):
        figs, statuses[j], values["t_final"][j] = _point_figures(p, {n: float(cols[n][j]) for n in names})
        for k in p.measures:
            values[k][j] = figs[k]
    return values, statuses


@dataclasses.dataclass
class Result:
    """A finished sweep: measures as arrays of the grid's shape, the status of every point, and
    how it ran: wall time in all; the parallel phase (every point after the first two, which run
    here first to load the compiled code and time a point): its tasks' compute seconds and its
    wall time from submitting the tasks to the last result."""

    plan: Plan
    values: dict
    status: np.ndarray
    ends: np.ndarray
    wall_s: float
    where: str
    workers: int
    task_seconds: list
    spread_s: float

    def columns(self):
        """{name: list} over the points in C order: the varied names, t_final (where each run ended:
        T rounded up to a whole number of steps of h; NaN where the run failed), the measures (with
        error_final, its reference's uncertainty), status."""
        cols = {name: c.tolist() for name, c in self.plan.columns(np.arange(self.plan.size)).items()}
        cols["t_final"] = self.t_final().tolist()
        cols.update({k: self.values[k].ravel().tolist() for k in _columns(self.plan.measures)})
        cols["status"] = self.status.ravel().tolist()
        return cols

    def t_final(self):
        """(points,) array of where each point's run ended, steps * h: past T where T is not a whole
        number of steps of h (a row labelled T = 49.61 at h = 0.1 ran to 49.7); NaN where the run
        failed (its status says where it stopped; a point whose reference failed ran to its end)."""
        return self.ends.ravel()

    def failures(self):
        """(how many runs failed, the first one's message or None) and the same of the points whose run
        ended but whose reference failed (error_final NaN, the run's other measures kept)."""
        status, ended = self.status.ravel(), np.isfinite(self.ends.ravel())
        runs = [s for s, e in zip(status, ended) if s != "ok" and not e]
        references = [s for s, e in zip(status, ended) if s != "ok" and e]
        return (len(runs), runs[0] if runs else None), (len(references), references[0] if references else None)

    @property
    def overhead_per_task_s(self):
        """(parallel wall x workers - compute) / tasks: what scheduling, transfer and idle workers
        cost each task of the parallel phase."""
        return max(0.0, self.spread_s * self.workers - sum(self.task_seconds)) / max(1, len(self.task_seconds))


def split(size, per_task):
    """Consecutive index ranges of at most per_task points covering range(size)."""
    return [range(a, min(size, a + per_task)) for a in range(0, size, per_task)]


def task_size(p, seconds_per_point, workers, remaining):
    """Points per task: about TASK_SECONDS each, but at least TASKS_PER_WORKER tasks per worker
    while there are that many points."""
    by_time = max(1, math.ceil(TASK_SECONDS / max(seconds_per_point, 1e-6)))
    by_balance = max(1, remaining // (TASKS_PER_WORKER * workers))
    return min(by_time, by_balance)


def run(p, workers=None, scheduler=None, progress=None):
    """Compute every point of plan p; returns a Result.

    Default: in this process on os.cpu_count() threads. workers=N: a Dask LocalCluster of N
    processes (started and stopped here). scheduler=ADDRESS: a running Dask cluster.
    progress(done, total, label) is called as points finish; an exception raised from it stops
    the sweep (running tasks finish their current point) and propagates.
    """
    if workers is not None and scheduler is not None:
        raise InputError("give --workers or --scheduler, not both")
    if workers is not None and (not isinstance(workers, int) or not 1 <= workers <= 256):
        raise InputError(f"workers = {quoted(workers)} must be a whole number from 1 to 256")
    report = progress or (lambda done, total, label: None)
    start = time.perf_counter()
    report(0, p.size, "first points (loading the compiled code, timing a point)")
    parts = [evaluate(p, range(1)), evaluate(p, range(1, min(2, p.size)))]
    seconds = parts[1][3]
    report(min(2, p.size), p.size, "points")
    spread = time.perf_counter()
    if workers is None and scheduler is None:
        width = os.cpu_count() or 1
        more = _threads(p, tasks_for(p, seconds, width), width, report)
        where = f"this process, {width} threads"
    else:
        more, where, width, spread = _dask(p, seconds, workers, scheduler, report)
    end = time.perf_counter()
    return _assemble(p, parts + more, end - start, where, width, [m[3] for m in more], end - spread)


def tasks_for(p, seconds_per_point, workers):
    """Tasks for the points after the first two (computed first, the second one timed)."""
    per = task_size(p, seconds_per_point, workers, p.size - 2)
    return [range(2 + r.start, 2 + r.stop) for r in split(max(0, p.size - 2), per)]


def _threads(p, tasks, width, report):
    stop = threading.Event()
    parts = []
    done = 2
    with ThreadPoolExecutor(max_workers=width, thread_name_prefix="cosymp-sweep") as pool:
        pending = {pool.submit(evaluate, p, t, stop) for t in tasks}
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in finished:
                    parts.append(f.result())
                    done += len(parts[-1][0])
                report(done, p.size, "points")
        except BaseException:
            stop.set()
            for f in pending:
                f.cancel()
            raise
    return parts


def _dask(p, seconds_per_point, workers, scheduler, report):
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise InputError("--workers and --scheduler need Dask: pip install 'dask[distributed]'") from None
    import logging

    cluster = None
    try:
        if scheduler is None:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.ERROR)
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout=10)
            except (OSError, TimeoutError, ValueError) as e:
                raise InputError(f"cannot reach a Dask scheduler at {quoted(scheduler)}: {e}; start one "
                                 "(dask scheduler) or check the address") from None
        with client:
            width = max(1, sum(client.nthreads().values()))
            where = (f"Dask LocalCluster, {workers} worker process{'es' if workers > 1 else ''}" if cluster is not None
                     else f"Dask cluster at {scheduler}, {width} worker threads")
            tasks = tasks_for(p, seconds_per_point, width)
            spread = time.perf_counter()
            futures = client.map(evaluate, [p] * len(tasks), tasks, pure=False)
            parts = []
            done = 2
            try:
                for f in as_completed(futures):
                    parts.append(f.result())
                    done += len(parts[-1][0])
                    report(done, p.size, "points")
            except BaseException:
                client.cancel(futures)
                raise
    finally:
        if cluster is not None:
            cluster.close()
    return parts, where, width, spread


def _assemble(p, parts, wall, where, width, task_seconds, spread_s):
    values = {k: np.full(p.size, np.nan) for k in (*_columns(p.measures), "t_final")}
    status = np.full(p.size, "not computed", dtype=object)
    for indices, cols, statuses, _ in parts:
        idx = np.asarray(indices, dtype=np.intp)
        for k, column in values.items():
            column[idx] = cols[k]
        status[idx] = statuses
    ends = values.pop("t_final")
    return Result(p, {k: v.reshape(p.shape) for k, v in values.items()}, status.reshape(p.shape), ends.reshape(p.shape),
                  wall, where, width, task_seconds, spread_s)


def write(result, path):
    """Write the sweep as tidy rows (one per point) to FILE.csv or FILE.parquet."""
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in FORMATS:
        raise InputError(f"-o {quoted(path)}: the file must end in .csv or .parquet")
    cols = result.columns()
    if suffix == ".csv":
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(cols)
            w.writerows(zip(*cols.values()))
        return
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError("writing .parquet needs pyarrow: pip install pyarrow, or write .csv") from None
    table = pa.table(cols)
    meta = {"scene": result.plan.scene, "method": result.plan.method, "h": repr(result.plan.h),
            "T": repr(result.plan.T), "fixed": repr(dict(result.plan.values))}
    pq.write_table(table.replace_schema_metadata({f"cosymp.{k}": v for k, v in meta.items()}), path)


def read(path):
    """{column: list} of a sweep written by `write` (csv or parquet)."""
    path = os.fspath(path)
    if path.lower().endswith(".parquet"):
        import pyarrow.parquet as pq

        return pq.read_table(path).to_pydict()
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    cols = {k: [r[k] for r in rows] for k in (rows[0] if rows else {})}
    return {k: (v if k == "status" else [float(x) for x in v]) for k, v in cols.items()}


def summary(result):
    """A few lines on what ran, how, and the range of each measure."""
    p = result.plan
    grid = " x ".join(f"{a.name} {len(a.values)}" for a in p.axes)
    (failed, first), (unmeasured, why) = result.failures()
    tasks = len(result.task_seconds)
    varied = {a.name for a in p.axes}
    fixed = ", ".join(f"{k} = {v:g}" for k, v in (("h", p.h), ("T", p.T)) if k not in varied)
    lines = [f"{p.scene} with {p.method}: {p.size} points ({grid})" + (f", {fixed}" if fixed else ""),
             f"  {result.wall_s:.2f} s on {result.where}; {tasks} tasks after the first two points"
             + (f", {sum(result.task_seconds) / tasks:.3g} s of compute each, overhead "
                f"{1e3 * result.overhead_per_task_s:.3g} ms per task" if tasks else "")]
    for k in p.measures:
        v = result.values[k]
        if np.all(np.isnan(v)):
            lines.append(f"  {k}: no finite value")
            continue
        hi = np.unravel_index(np.nanargmax(v), v.shape)
        at = ", ".join(f"{a.name} = {a.values[i]:.4g}" for a, i in zip(p.axes, hi))
        lines.append(f"  {k}: min {np.nanmin(v):.4g}, max {np.nanmax(v):.4g} (at {at})")
    if "error_final" in p.measures:
        error, own = result.values["error_final"], result.values[UNCERTAINTY]
        unresolved = int(np.sum(~is_resolved(error, own)))
        if unresolved:
            lines.append(f"  {unresolved} point{'s' if unresolved > 1 else ''} with error_final at most its reference's "
                         f"own uncertainty: not resolved (the column {UNCERTAINTY})")
    cols = {name: c.tolist() for name, c in p.columns(np.arange(p.size)).items()}
    T = np.asarray(cols.get("T", [p.T] * p.size), float)
    past = result.t_final() - T
    beyond = past > 1e-9 * T  # NaN, a failed point, is not
    if beyond.any():
        lines.append(f"  {beyond.sum()} point{'s' if beyond.sum() > 1 else ''} ran past T, up to {past[beyond].max():.4g} "
                     "beyond it (T is not a whole number of steps of h there): their figures are at t_final, a "
                     "column of the written rows")
    if failed:
        lines.append(f"  {failed} point{'s' if failed > 1 else ''} failed, e.g.: {first}")
    if unmeasured:
        lines.append(f"  {unmeasured} point{'s' if unmeasured > 1 else ''} without error_final, the run's other measures "
                     f"kept: its reference failed, e.g.: {why}")
    return "\n".join(lines) + "\n"
