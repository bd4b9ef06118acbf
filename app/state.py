"""The app's state: inputs, their validation and the derived data, without any UI.

Every object here is a `param.Parameterized` that can be created, changed and inspected in a
plain Python session (the tests do). Computation runs through `param`'s async executor: under
`panel serve` it is a task on the session's event loop whose numerical work runs in threads
(`asyncio.to_thread`; the kernels release the GIL, so the two methods of a comparison run at
once); without a server the same code runs to completion before the assignment returns.

Requests are coalesced: while one computation runs, further changes only mark the inputs as
newer, and the loop computes again with the latest inputs once it is done. That is the
throttle of the live views: they update as fast as the server computes, never queueing stale
work. Bad input never reaches the derived data: it becomes a `Note` in `Study.message` that
says what to change, and the last good results stay.
"""
import asyncio
import dataclasses
import logging
import math
import os
import threading
import time
import weakref
from concurrent.futures import ThreadPoolExecutor
from functools import cache, partial

import numpy as np
import param

from cosymp import sweep
from cosymp import workprecision as wp
from cosymp.diagnostics import (
    det_deviation,
    nearby_states,
    symplecticity_defect,
    tangent_maps,
)
from cosymp.errors import InputError, RunError
from cosymp.integrate import Setup, check_step, default_stride, simulate
from cosymp.methods import METHODS
from cosymp.report import render
from cosymp.report.scene import command as report_command
from cosymp.report.scene import scene_report
from cosymp.scenes import SCENES
from cosymp.study import compare_until_failure as study_until_failure
from cosymp.study import gauge_study
from cosymp.summary import long_chunk, max_chunk

from .allocator import give_back
from .presets import long_horizon
from .warmup import FIRST_VIEW

LIVE_MAX_STEPS = 2_000_000
DENSE_RECORDS = 100_000
CLOUD_POINTS = {True: 32, False: 64}
DELTA = 1e-4
VIEWS = {"Orbits": "compare", "Structure": "structure", "Cloud": "cloud", "Gauges": "gauges",
         "Theta lesson": "theta", "Play": "play", "Long run": "long", "Work–precision": "workprecision",
         "Stability map": "map"}
URL_NAMES = {"scene": "scene", "method": "method", "other": "vs", "theta": "theta", "h": "h", "T": "T",
             "values": "p", "view": "view"}
LONG_URL_NAMES = {"T_long": "T_long"}
SWEEP_THETAS = np.linspace(0.0, 1.0, 21)
SWEEP_STEPS = 200
LONG_BINS = 20_000
LONG_CHUNK_SECONDS = 0.3
LONG_DRAW_SECONDS = 1.0  # the long run's plots are redrawn at most this often (each redraw costs the event loop)


# Memory: every computation leases its peak memory from one budget per server process before it
# starts and holds it while its results are kept; a lease that would pass the cap is refused with
# a message. Peaks were measured with tracemalloc (tests/test_app_state.py checks the comparison bound):
# a comparison peaks at <= 39 bytes per value its runs record (damped 39, charged 31, kapitza
# 28), a long run at 179 MB (chunked, any horizon), a work-precision measurement at 43 MB and
# long horizons at 29 MB.
MEMORY_CAP_MB = float(os.environ.get("COSYMP_MEMORY_CAP_MB", "4096"))
BYTES_PER_RECORDED = 48
LONG_RUN_BYTES = 256 << 20
MEASURE_BYTES = 96 << 20


class MemoryBudget:
    """Bytes leased by the computations of all sessions, and the cap they may not pass."""

    def __init__(self, cap_bytes):
        self.cap = cap_bytes
        self.used = 0
        self._lock = threading.Lock()

    def lease(self, nbytes, what):
        """A Lease of nbytes, or InputError saying what to change when the cap would be passed."""
        mb = 1 << 20
        with self._lock:
            if nbytes > self.cap:
                raise InputError(f"{what} needs about {nbytes / mb:.0f} MB, more than this server's cap of "
                                 f"{self.cap / mb:.0f} MB (COSYMP_MEMORY_CAP_MB): increase h or shorten T")
            if self.used + nbytes > self.cap:
                raise InputError(f"{what} needs about {nbytes / mb:.0f} MB and only "
                                 f"{(self.cap - self.used) / mb:.0f} MB of this server's "
                                 f"{self.cap / mb:.0f} MB are free while other runs hold the rest: "
                                 "try again in a moment, or increase h or shorten T")
            self.used += nbytes
        return Lease(self, nbytes)

    def _give_back(self, nbytes):
        with self._lock:
            self.used -= nbytes


class Lease:
    """Memory held from a MemoryBudget until released (releasing twice is harmless)."""

    def __init__(self, budget, nbytes):
        self._budget = budget
        self.nbytes = nbytes

    def release(self):
        if self.nbytes:
            self._budget._give_back(self.nbytes)
            self.nbytes = 0


BUDGET = MemoryBudget(int(MEMORY_CAP_MB * (1 << 20)))


# Logged (under Panel's logger: PANEL_LOG_LEVEL=info shows it beside Panel's session lines) when
# a page's App is garbage-collected, so an operator (and the load test) can see closed pages freed.
LOG = logging.getLogger("panel.cosymp")
FREED = "cosymp: a page's state was freed"


def log_when_freed(app):
    """Log FREED once `app` has been garbage-collected and its memory given back to the system.
    Its objects are freed after the collection's finalizers (this is one), so that happens in a
    callback on the server's event loop once the collection is over (without a loop, at once).
    (Not in the app's script: Panel clears a session's script globals when the session ends.)"""
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        loop = None
    weakref.finalize(app, _freed, loop)


def _freed(loop):
    if loop is not None:
        try:
            loop.call_soon_threadsafe(_give_back_freed)
            return
        except RuntimeError:  # the loop has closed: the server is stopping
            pass
    _give_back_freed()


def _give_back_freed():
    give_back()
    LOG.info(FREED)


def comparison_bytes(setups, h, T):
    """Peak memory of comparing the setups (study.compare: 2n + 2 members with increments, and
    their tangent maps), from the values the runs record."""
    steps = check_step(h, T)
    total = 0
    for s in setups:
        m = 2 * s.scene.ndof
        members = m + 2
        records = steps // default_stride(steps, members, m, increments=True) + 1
        total += records * members * (m + 1)
    return BYTES_PER_RECORDED * total


@dataclasses.dataclass(frozen=True)
class Note:
    """A message for the user: level is 'error', 'warning' or 'info'."""

    level: str
    text: str


@dataclasses.dataclass(frozen=True)
class Entry:
    """One method's run in a comparison: label, Comparison (None if nothing could be computed),
    and the failure message of a run that stopped early ('' if it reached T)."""

    label: str
    method: str
    comparison: object
    failure: str


@dataclasses.dataclass(frozen=True)
class Runs:
    """The derived data of a comparison: the scene, step and horizon, and one Entry per method."""

    scene: str
    h: float
    T: float
    entries: tuple

    @property
    def ok(self):
        return [e for e in self.entries if e.comparison is not None]


def soft_range(p):
    """Slider range of a numeric scene parameter: its bounds when they are narrow, else a range
    around the default within them (any value within the bounds can still be typed)."""
    lo, hi = p.bounds
    if hi - lo <= 2.0:
        return lo, hi
    x = float(p.default)
    s = max(2.0 * abs(x), 2.5)
    return max(lo, x - s), min(hi, x + s)


@cache
def inputs_class(scene_name):
    """A Parameterized class mirroring the scene's parameters (bounds, docs, choices)."""
    scene = SCENES[scene_name]
    params = {}
    for p in scene.params:
        if p.choices:
            params[p.name] = param.Selector(default=p.default, objects=list(p.choices), doc=p.doc,
                                            label=p.name)
        elif isinstance(p.default, str):
            params[p.name] = param.String(default=p.default, doc=p.doc, label=p.name)
        else:
            lo, hi = soft_range(p)
            bounds = tuple(None if math.isinf(b) else b for b in p.bounds)
            params[p.name] = param.Number(default=float(p.default), bounds=bounds, softbounds=(lo, hi),
                                          step=(hi - lo) / 500, doc=p.doc, label=p.name)
    return param.parameterized_class(f"{scene_name.title()}Inputs", params)


def theta_for(method, theta):
    return theta if METHODS[method].takes_theta else None


def compare_until_failure(setup, h, T):
    """cosymp.study.compare_until_failure with this app's loop size and separation: the carried
    loop has CLOUD_POINTS[linear] points (a linear map carries a polygon to a polygon: fewer suffice)."""
    return study_until_failure(setup, h, T, delta=DELTA, cloud_points=CLOUD_POINTS[setup.scene.kernel.linear])


def study_report(study):
    """The HTML report of the study's comparison (the views' own runs when they match the
    inputs, else computed afresh), or InputError saying what to change."""
    setups = study.setups()
    study.check_horizon()
    h, T = float(study.h), float(study.T)
    runs = study.results
    computed = None
    if runs is not None and (runs.scene, runs.h, runs.T) == (study.scene, h, T) and all(
            e.comparison is None or e.comparison.setup.values == s.values for e, s in zip(runs.entries, setups)) \
            and [e.method for e in runs.entries] == [s.method.name for s in setups]:
        computed = [(e.comparison, e.failure) for e in runs.entries]
    report = scene_report(setups, h, T, report_command(setups, h, T, "cosymp-report.html"), computed=computed)
    return render(report)


def run_pair(scene, setups, h, T):
    """Compare the setups (both at once, in threads) and return Runs."""
    with ThreadPoolExecutor(len(setups)) as pool:
        done = list(pool.map(lambda s: compare_until_failure(s, h, T), setups))
    entries = []
    for s, (comparison, failure) in zip(setups, done):
        label = s.method.label(s.theta)
        if any(e.label == label for e in entries):
            label += " (2)"
        entries.append(Entry(label, s.method.name, comparison, failure))
    return Runs(scene, h, T, tuple(entries))


def failure_note(runs):
    texts = [f"{e.label}: {e.failure}" + (f"; showing data up to t = {e.comparison.run.t[-1]:.6g}"
                                          if e.comparison is not None else "")
             for e in runs.entries if e.failure]
    return Note("warning", " | ".join(texts)) if texts else None


class Derived(param.Parameterized):
    """Coalesced recomputation. `_schedule()` asks for fresh data (computed off the event loop;
    requests made meanwhile merge into one), `refresh()` computes now. Subclasses give `_job()`
    (the validated inputs, None for nothing to do, or InputError), `_footprint(job)` (its peak
    memory, leased from BUDGET before it runs and held while its result is kept), `_compute(job)`
    (pure, run in a thread), `_apply(result)` and `_say(note)`."""

    busy = param.Boolean(default=False, doc="A computation is under way.")
    WHAT = "this comparison"

    def __init__(self, **params):
        super().__init__(**params)
        self._wanted = 0
        self._done = 0
        self._draining = False
        self._lease = None
        self._closed = False

    def _schedule(self):
        self._wanted += 1
        if not self._draining and not self._closed:
            self._draining = True
            param.parameterized.async_executor(self._drain)

    def refresh(self):
        """Compute from the current inputs now, in this thread (no event loop needed)."""
        self._wanted += 1
        target = self._wanted
        leased = self._lease_job()
        if leased is not None:
            job, lease = leased
            self._keep(lease, self._run(job, lease))
        self._done = max(self._done, target)

    def _lease_job(self):
        """(job, Lease of its memory), or None for nothing to do or bad input (said)."""
        try:
            job = self._job()
            if job is None:
                return None
            return job, BUDGET.lease(self._footprint(job), self.WHAT)
        except InputError as err:
            self._say(Note("error", str(err)))
            return None

    def _run(self, job, lease):
        try:
            return self._compute(job)
        except BaseException:
            lease.release()
            raise

    def _keep(self, lease, result):
        """Show the result and hold its memory instead of the previous result's (or, once the
        page is gone, drop it and its memory)."""
        if self._closed:
            lease.release()
            return
        previous, self._lease = self._lease, lease
        if previous is not None:
            previous.release()
        self._apply(result)

    def release(self):
        """The page is gone: give back the memory of the kept result, and drop any result still
        being computed instead of showing it. (Shown after the session ends, a result would
        build new plots for its destroyed document, which Panel then keeps for good, and with
        it the whole session.)"""
        self._closed = True
        if self._lease is not None:
            self._lease.release()

    async def _drain(self):
        self.busy = True
        try:
            while self._done < self._wanted and not self._closed:
                target = self._wanted
                leased = self._lease_job()
                if leased is None:
                    self._done = target
                    continue
                job, lease = leased
                result = await asyncio.to_thread(self._run, job, lease)
                self._done = target
                self._keep(lease, result)
        finally:
            self._draining = False
            self.busy = False

    def _footprint(self, job):
        raise NotImplementedError

    def _say(self, note):
        raise NotImplementedError

    def _job(self):
        raise NotImplementedError

    def _compute(self, job):
        raise NotImplementedError

    def _apply(self, result):
        raise NotImplementedError


class Study(Derived):
    """Scene, methods and parameters of a comparison, and its results.

    `values` holds the scene parameters that differ from the scene's defaults (the URL carries
    it); `inputs` is a Parameterized mirroring the scene's parameters, for the controls. Either
    can be changed; the other follows.
    """

    scene = param.Selector(default=FIRST_VIEW["scene"], objects={s.title: k for k, s in SCENES.items()},
                           doc="The time-dependent Hamiltonian system.")
    method = param.Selector(default=FIRST_VIEW["method"], objects={m.title: k for k, m in METHODS.items()},
                            doc="The method under study.")
    other = param.Selector(default=FIRST_VIEW["other"], objects={m.title: k for k, m in METHODS.items()},
                           doc="The method it is compared with.", label="Compared with")
    theta = param.Number(default=0.5, bounds=(0.0, 1.0), step=0.01, label="θ",
                         doc="θ of the theta methods (θ = 1/2: midpoint; θ = 0: the paper's scheme).")
    h = param.Number(default=SCENES[FIRST_VIEW["scene"]].h, doc="Step size h > 0.")
    T = param.Number(default=SCENES[FIRST_VIEW["scene"]].T, doc="Horizon T of the live views.")
    values = param.Dict(default={}, doc="Scene parameters that differ from the scene's defaults.")
    view = param.Selector(default="compare", objects=VIEWS, doc="The active view.")
    inputs = param.Parameter(doc="The scene's parameters as a Parameterized (for the controls).")
    results = param.ClassSelector(class_=Runs, doc="The last good comparison.")
    shown = param.String(default="", doc="What the views are laid out for: 'scene/sparse', or 'scene/dense' "
                                         "when a run has more than DENSE_RECORDS records.")
    message = param.ClassSelector(class_=Note, doc="The last message for the user.")

    def __init__(self, **params):
        super().__init__(**params)
        scene = self.scene_obj
        self.param.update({k: getattr(scene, k) for k in ("h", "T") if k not in params})
        self._nested = False
        self._syncing = False
        try:
            self.inputs = self._make_inputs()
        except InputError as err:
            self.say(Note("error", str(err)))
            self.values = {}
            self.inputs = self._make_inputs()
        self.param.watch(self._on_change, ["scene", "method", "other", "theta", "h", "T", "values"])
        self.refresh()

    def say(self, note):
        """Post a message, once (a repeated message is posted again)."""
        with param.parameterized.discard_events(self):
            self.message = note
        self.param.trigger("message")

    _say = say

    @property
    def scene_obj(self):
        return SCENES[self.scene]

    def setups(self):
        """The two checked setups, or InputError saying what to change."""
        scene = self.scene_obj
        return tuple(Setup.make(scene, m, self.values, theta_for(m, self.theta))
                     for m in (self.method, self.other))

    def check_horizon(self):
        steps = check_step(self.h, self.T)
        if steps > LIVE_MAX_STEPS:
            raise InputError(f"T/h = {steps:.3g} steps is beyond the live views' limit of "
                             f"{LIVE_MAX_STEPS:.0e}: increase h, shorten T, or use the Long run view")
        return steps

    def _make_inputs(self):
        inputs = inputs_class(self.scene)(**self.scene_obj.values(self.values))
        inputs.param.watch(self._on_inputs, [p.name for p in self.scene_obj.params])
        return inputs

    def _on_inputs(self, *events):
        if self._syncing:
            return
        defaults = {p.name: p.default for p in self.scene_obj.params}
        current = {name: getattr(self.inputs, name) for name in defaults}
        self.values = {k: v for k, v in current.items() if v != defaults[k]}

    def _on_change(self, *events):
        if self._nested:
            return
        changed = {e.name for e in events}
        scene = self.scene_obj
        if "scene" in changed:
            updates = {k: getattr(scene, k) for k in ("h", "T") if k not in changed}
            if "values" not in changed:
                updates["values"] = {}
            for name, fallback in (("method", "midpoint"), ("other", "rk4")):
                reason = METHODS[getattr(self, name)].refusal(scene)
                if reason:
                    updates[name] = fallback
                    self.say(Note("info", f"{reason}; switched to {fallback}"))
            try:
                scene.values(updates.get("values", self.values))
            except InputError as err:
                self.say(Note("error", str(err)))
                updates["values"] = {}
            self._nested = True
            try:
                self.param.update(**updates)
            finally:
                self._nested = False
            self.inputs = self._make_inputs()
        elif "values" in changed:
            try:
                vals = scene.values(self.values)
            except InputError as err:
                self.say(Note("error", str(err)))
                return
            self._syncing = True
            try:
                self.inputs.param.update(**vals)
            finally:
                self._syncing = False
        self._schedule()

    def _job(self):
        setups = self.setups()
        self.check_horizon()
        return self.scene, setups, float(self.h), float(self.T)

    def _footprint(self, job):
        return comparison_bytes(*job[1:4])

    def _compute(self, job):
        scene, setups, h, T = job
        return run_pair(scene, setups, h, T)

    def _apply(self, runs):
        dense = any(len(c.run.t) > DENSE_RECORDS for c in (e.comparison for e in runs.ok))
        self.param.update(results=runs, shown=f"{runs.scene}/{'dense' if dense else 'sparse'}")
        note = failure_note(runs)
        if note:
            self.say(note)


class Follower(Derived):
    """A derived view of a Study: recomputed when the study's WATCHED inputs change, while
    `active` (its tab is shown); its notes go to the study's."""

    study = param.ClassSelector(class_=Study)
    WATCHED = ()

    def __init__(self, **params):
        super().__init__(**params)
        self.study.param.watch(self._on_study, list(self.WATCHED))
        if self.active:
            self.refresh()

    @property
    def active(self):
        raise NotImplementedError

    def _say(self, note):
        self.study.say(note)

    def _on_study(self, *events):
        if self.active:
            self._schedule()


class ThetaLesson(Follower):
    """The lifted theta-method against the naive one at the study's θ, on the study's scene,
    and a θ sweep of their one-step defects (max over the first SWEEP_STEPS steps)."""

    WHAT = "the θ lesson"
    WATCHED = ("scene", "theta", "h", "T", "values", "view")
    results = param.ClassSelector(class_=Runs, doc="Lifted and naive runs at the study's θ.")
    sweep = param.Dict(default=None, allow_None=True,
                       doc="'thetas', and per method name {'det': max |det M - 1|, 'symp': max "
                           "|M^T J M - J|} at each θ.")

    def __init__(self, **params):
        self._sweep_key = None
        super().__init__(**params)

    @property
    def active(self):
        return self.study.view == "theta"

    def _job(self):
        s = self.study
        setups = tuple(Setup.make(s.scene, m, s.values, s.theta) for m in ("theta", "theta-naive"))
        s.check_horizon()
        key = (s.scene, tuple(sorted(s.values.items())), float(s.h))
        return s.scene, setups, float(s.h), float(s.T), key

    def _footprint(self, job):
        return comparison_bytes(*job[1:4])

    def _compute(self, job):
        scene, setups, h, T, key = job
        sweep = None if key == self._sweep_key else theta_sweep(setups, h, T)
        return run_pair(scene, setups, h, T), sweep, key

    def _apply(self, result):
        runs, sweep, key = result
        self.results = runs
        if sweep is not None:
            self._sweep_key = key
            self.sweep = sweep
        note = failure_note(runs)
        if note:
            self.study.say(note)


def theta_sweep(setups, h, T):
    """max |det M - 1| and max ||M^T J M - J|| over the first steps, for each θ of SWEEP_THETAS."""
    steps = min(SWEEP_STEPS, check_step(h, T))
    out = {"thetas": SWEEP_THETAS}
    for s in setups:
        det, symp = [], []
        for th in SWEEP_THETAS:
            try:
                run = simulate(Setup.make(s.scene, s.method, s.values, float(th)), h, steps * h)
                M = tangent_maps(run)
                det.append(float(np.max(det_deviation(M))))
                symp.append(float(np.max(symplecticity_defect(M))))
            except RunError:
                det.append(np.nan)
                symp.append(np.nan)
        out[s.method.name] = {"det": np.array(det), "symp": np.array(symp)}
    return out


class GaugeStudy(Follower):
    """The charged particle in all five gauges with the study's method, h, T and parameters."""

    WHAT = "the gauge study"
    WATCHED = ("scene", "method", "theta", "h", "T", "values", "view")
    results = param.Dict(default=None, allow_None=True,
                         doc="{gauge: {'per-gauge': (t, q, p, Pi), 'transported': ...}}.")
    method = param.String(default="", doc="The method of the results.")

    @property
    def active(self):
        return self.study.view == "gauges" and self.study.scene == "charged"

    def _job(self):
        s = self.study
        if s.scene != "charged":
            return None
        s.check_horizon()
        values = {k: v for k, v in s.values.items() if k != "gauge"}
        theta = theta_for(s.method, s.theta)
        Setup.make("charged", s.method, values, theta)
        return s.method, values, float(s.h), float(s.T), theta

    def _footprint(self, job):
        method, values, h, T, theta = job
        # bounded above: six single-member runs and five transports use less than one comparison
        return comparison_bytes([Setup.make("charged", method, values, theta)], h, T)

    def _compute(self, job):
        method, values, h, T, theta = job
        try:
            return METHODS[method].label(theta), gauge_study(method, values, h, T, theta), ""
        except RunError as err:
            return METHODS[method].label(theta), None, str(err)

    def _apply(self, result):
        label, data, failure = result
        if failure:
            self.study.say(Note("warning", f"gauge study with {label}: {failure}"))
            return
        self.method = label
        self.results = data


class Playback(param.Parameterized):
    """The animation's position (frame of FRAMES) and speed (frames per second)."""

    FRAMES = 200
    frame = param.Integer(default=200, bounds=(0, 200), doc="Current frame; FRAMES shows the whole run.")
    fps = param.Selector(default=20, objects={"5 frames/s": 5, "10 frames/s": 10, "20 frames/s": 20,
                                              "40 frames/s": 40}, doc="Playback speed.")

    @property
    def fraction(self):
        return self.frame / self.FRAMES


@dataclasses.dataclass
class LongSeries:
    """Per-bin envelopes of one method's long run: t (bin starts), H~ min/max, the paper's volume
    estimator min/max, and the max per bin of |det M - 1| and ||M^T J M - J||."""

    label: str
    t: list
    H_min: list
    H_max: list
    vol_min: list
    vol_max: list
    det: list
    symp: list
    failure: str = ""

    def arrays(self):
        return {k: np.concatenate(getattr(self, k)) if getattr(self, k) else np.empty(0)
                for k in ("t", "H_min", "H_max", "vol_min", "vol_max", "det", "symp")}


class LongRun(param.Parameterized):
    """A long run of the study's two methods, computed in chunks off the event loop, with
    progress, cancellation and per-bin envelopes (at most LONG_BINS bins) as data arrives."""

    study = param.ClassSelector(class_=Study)
    T_long = param.Number(default=long_horizon(FIRST_VIEW["scene"]), label="Long horizon T",
                          doc="Horizon of the long run (chunked; capped at 1e8 steps).")
    progress = param.Number(default=0.0, bounds=(0.0, 1.0), doc="Fraction of the steps done.")
    running = param.Boolean(default=False)
    status = param.String(default="", doc="What the run is doing or how it ended.")
    data = param.Dict(default={}, doc="{label: envelope arrays and failure} of the run so far.")
    setting = param.String(default="", doc="What is (or was last) run.")

    def __init__(self, **params):
        super().__init__(**params)
        if "T_long" not in params:
            self.T_long = long_horizon(self.study.scene)
        self._cancel = False
        self._closed = False
        self.study.param.watch(self._on_scene, ["scene"])

    def _on_scene(self, event):
        if not self.running:
            self.T_long = long_horizon(self.study.scene)

    def start(self):
        """Validate and start (no-op while running); bad input becomes a message."""
        if self.running:
            return
        s = self.study
        try:
            setups = s.setups()
            steps = check_step(s.h, self.T_long)
            lease = BUDGET.lease(LONG_RUN_BYTES, "a long run")
        except InputError as err:
            s.say(Note("error", str(err)))
            return
        self._cancel = False
        self.running = True
        param.parameterized.async_executor(partial(self._run, setups, float(s.h), steps, lease))

    def cancel(self):
        self._cancel = True

    def release(self):
        """The page is gone: stop after the current chunk and publish nothing more (drawn after the
        session ended, new data would keep the destroyed document alive)."""
        self._closed = True
        self._cancel = True

    @staticmethod
    def _envelopes(series):
        return {x.label: {**x.arrays(), "failure": x.failure} for x in series}

    async def _run(self, setups, h, steps, lease):
        s = self.study
        width = max(1, math.ceil(steps / LONG_BINS))
        cap = width * max(1, min(max_chunk(x) for x in setups) // width)
        labels = [x.method.label(x.theta) for x in setups]
        values = ", ".join(f"{k} = {v}" for k, v in s.values.items())
        self.setting = (f"{s.scene}: {' vs '.join(labels)}, h = {h:g}, T = {steps * h:g}"
                        + (f", {values}" if values else ""))
        series = [LongSeries(lab, [], [], [], [], [], [], []) for lab in labels]
        states = []
        for x in setups:
            q0, p0 = x.scene.initial(x.values)
            states.append((nearby_states(np.concatenate([q0, p0]), DELTA, 2 * x.scene.ndof + 1), None))
        active = [True] * len(setups)
        done = 0
        chunk = min(cap, width * max(1, 4096 // width))
        self.param.update(progress=0.0, data={}, status="running")
        started = time.perf_counter()
        shown = -math.inf
        stale = False
        try:
            while done < steps and any(active) and not self._cancel:
                n = min(chunk, steps - done)
                tick = time.perf_counter()
                running = [i for i, a in enumerate(active) if a]
                outs = await asyncio.gather(*(asyncio.to_thread(long_chunk, setups[i], h, n, *states[i], done,
                                                                width) for i in running))
                if self._cancel:
                    break
                for i, (red, Z, PT, failure) in zip(running, outs):
                    states[i] = (Z, PT)
                    if red is not None:
                        for k, v in red.items():
                            getattr(series[i], k).append(v)
                    if failure:
                        active[i] = False
                        series[i].failure = failure
                        s.say(Note("warning", f"long run, {labels[i]}: {failure}; showing data up to there"))
                done += n
                now = time.perf_counter()
                chunk = min(cap, width * max(1, round(n * LONG_CHUNK_SECONDS / max(now - tick, 1e-3) / width)))
                self.progress = done / steps
                stale = True
                if now - shown >= LONG_DRAW_SECONDS:
                    self.data, stale, shown = self._envelopes(series), False, now
            if self._closed:
                return
            elapsed = time.perf_counter() - started
            if self._cancel:
                self.status = f"cancelled at t = {done * h:.6g} after {elapsed:.1f} s"
            elif not all(active):
                self.status = f"stopped early (see the message) after {elapsed:.1f} s"
            else:
                self.status = f"done: {done} steps per method in {elapsed:.1f} s"
        finally:
            if stale and not self._closed:
                self.data = self._envelopes(series)
            lease.release()
            self.running = False
            give_back()


# ---------------------------------------------------------------- work against precision

WP_MAX_STEPS = 1 << 17
WP_BUDGET = 0.05
WP_RTOLS = tuple(10.0 ** -k for k in range(3, 13))
DRIFT_TOPS = (1e3, 1e4, 1e5, 1e6)
DRIFT_DEFAULT_STEPS = 1_000_000
POLL_S = 0.1


# What a measurement may raise besides cosymp's own errors (InputError is a ValueError, RunError a
# RuntimeError): each becomes a message and the session goes on.
FAILURES = (ArithmeticError, AttributeError, LookupError, MemoryError, OSError, RuntimeError, TypeError,
            ValueError)


class Cancelled(Exception):
    """Raised from a progress callback to stop a measurement at its next run."""


class Worker:
    """One background computation: `fn(*args, progress=...)` in a daemon thread. Its progress
    callback records (done, total, label), and raises Cancelled once `cancelled` is set, which
    stops cosymp's measurements before their next run."""

    def __init__(self, fn, *args, lease=None):
        self.lease = lease
        self.cancelled = False
        self.latest = (0, 1, "starting")
        self.result = None
        self.error = None
        self.finished = threading.Event()
        self.thread = threading.Thread(target=self._main, args=(fn, args), daemon=True, name="cosymp-measure")

    def report(self, done, total, label):
        if self.cancelled:
            raise Cancelled
        self.latest = (done, total, label)

    def _main(self, fn, args):
        try:
            self.result = fn(*args, progress=self.report)
        except Cancelled:
            pass
        except FAILURES as err:
            self.error = err
        finally:
            if self.result is None and self.error is None and not self.cancelled:
                self.error = RuntimeError("the computation stopped without a result (see the server's log)")
            if self.lease is not None:
                self.lease.release()
            give_back()
            self.finished.set()


def failure_text(err):
    """A user-facing text for an exception: cosymp's own messages as they are, others with their type."""
    return str(err) if isinstance(err, (InputError, RunError)) else f"{type(err).__name__}: {err}"


class Background(param.Parameterized):
    """A measurement of the study's scene in a worker thread, started by `start()`, with its
    progress (fraction and the current run's label) published every POLL_S from the event loop,
    and `cancel()`, which ends it at once in the UI (the worker stops before its next run, its
    rows are dropped, the last results stay). Subclasses give `_job()` (the validated inputs, or
    InputError), `_describe(job)`, `_compute(job, progress)` (run in the worker) and may adjust
    `_finish(job, result)`; without a server `start()` returns when the work is done."""

    study = param.ClassSelector(class_=Study)
    progress = param.Number(default=0.0, bounds=(0.0, 1.0), doc="Fraction of the runs done.")
    label = param.String(default="", doc="The run under way.")
    running = param.Boolean(default=False)
    status = param.String(default="", doc="What the measurement is doing or how it ended.")
    rows = param.List(default=[], doc="The rows of the last completed measurement.")
    setting = param.String(default="", doc="What the rows were measured on.")
    KIND = "measurement"

    def __init__(self, **params):
        super().__init__(**params)
        self._worker = None
        self.job = None

    def start(self):
        """Validate and start (no-op while running); bad input becomes a message."""
        if self.running:
            return
        try:
            job = self._job()
            lease = BUDGET.lease(self._bytes(job), "this measurement")
        except InputError as err:
            self.study.say(Note("error", f"{self.KIND}: {err}"))
            return
        self._worker = Worker(self._compute, job, lease=lease)
        self.param.update(running=True, progress=0.0, label="starting", status=f"running: {self._describe(job)}")
        param.parameterized.async_executor(partial(self._watch, self._worker, job))

    def cancel(self):
        if self._worker is not None:
            self._worker.cancelled = True

    async def _watch(self, worker, job):
        started = time.perf_counter()
        try:
            worker.thread.start()
            while not worker.finished.is_set() and not worker.cancelled:
                done, total, label = worker.latest
                self.param.update(progress=min(1.0, done / max(total, 1)), label=label)
                await asyncio.sleep(POLL_S)
            elapsed = time.perf_counter() - started
            if worker.cancelled:
                self.status = f"cancelled after {elapsed:.1f} s ({self.label})"
            elif worker.error is not None:
                text = failure_text(worker.error)
                self.status = f"failed after {elapsed:.1f} s: {text}"
                self.study.say(Note("error", f"{self.KIND} failed: {text}"))
            else:
                self._finish(job, worker.result)
                self.param.update(progress=1.0, label="done", status=f"done in {elapsed:.1f} s")
        except FAILURES as err:
            self.status = f"failed: {failure_text(err)}"
            self.study.say(Note("error", f"{self.KIND} failed: {failure_text(err)}"))
        finally:
            self.running = False

    def _finish(self, job, result):
        self.job = job
        self.param.update(rows=result, setting=self._describe(job))

    def _job(self):
        raise NotImplementedError

    def _bytes(self, job):
        """The memory the computation leases while it runs."""
        return MEASURE_BYTES

    def _describe(self, job):
        raise NotImplementedError

    def _compute(self, job, progress):
        raise NotImplementedError


def applicable(scene, names):
    """The names of the methods that apply to the scene (never the exact flow: it is the reference)."""
    return [m for m in names if m != "exact" and METHODS[m].refusal(SCENES[scene]) is None]


@dataclasses.dataclass(frozen=True)
class Measured:
    """What a measurement ran: scene, its parameter values, θ, the methods (name, θ or None per
    solver name), h (drift) or T (work-precision)."""

    scene: str
    values: dict
    theta: float
    solvers: dict
    h: float = None
    T: float = None
    horizons: tuple = ()
    peers: bool = False

    @property
    def method_theta(self):
        """θ for the methods that take one, None when none of them does."""
        return next((th for _, th in self.solvers.values() if th is not None), None)

    def describe(self):
        values = ", ".join(f"{k} = {v}" for k, v in self.values.items())
        what = [f"T = {self.T:g}"] if self.T is not None else [f"h = {self.h:g}", f"T up to {self.horizons[-1]:g}"]
        if any(th is not None for _, th in self.solvers.values()):
            what.append(f"θ = {self.theta:g}")
        return f"{self.scene}" + (f" ({values})" if values else "") + ": " + ", ".join(what)


def solvers_of(scene, methods, values, theta):
    """{solver name as cosymp.workprecision names it: (method, θ or None)}, or InputError."""
    if not methods:
        raise InputError("no methods chosen: choose at least one method")
    out = {}
    for m in methods:
        s = Setup.make(scene, m, values, theta_for(m, theta))
        out[wp.solver_name(s)] = (m, s.theta)
    return out


class WorkPrecision(Background):
    """Error at T against wall time for the chosen methods over step sizes (and scipy's
    solve_ivp over tolerances), on the study's scene, parameters, θ and T. A cosymp point can be
    opened in the Orbits view (`open_row`)."""

    methods = param.ListSelector(default=[], objects=list(METHODS), doc="cosymp's methods to measure.")
    peers = param.Boolean(default=True, label="with scipy's solve_ivp (RK45, DOP853, LSODA)",
                          doc="Also measure scipy's adaptive solvers over tolerances 1e-3 ... 1e-12.")
    KIND = "work–precision"

    def __init__(self, **params):
        super().__init__(**params)
        self.param.methods.objects = applicable(self.study.scene, METHODS)
        if "methods" not in params:
            self.methods = applicable(self.study.scene, wp.DEFAULT_METHODS)
        self.study.param.watch(self._on_scene, ["scene"])

    def _on_scene(self, event):
        self.param.methods.objects = applicable(self.study.scene, METHODS)
        self.methods = applicable(self.study.scene, wp.DEFAULT_METHODS)

    def _job(self):
        s = self.study
        wp.check_horizon(s.T)
        first = math.ceil(s.T / s.scene_obj.time_scale)
        if first > WP_MAX_STEPS:
            raise InputError(f"T = {s.T:g} takes at least {first} steps per run at the scene's time scale, beyond "
                             f"this view's {WP_MAX_STEPS} steps per run: shorten T (the long horizons below go "
                             "further at one h)")
        return Measured(s.scene, dict(s.values), float(s.theta), solvers_of(s.scene, self.methods, s.values, s.theta),
                        T=float(s.T), peers=bool(self.peers))

    def _describe(self, job):
        peers = ", scipy's RK45, DOP853, LSODA" if job.peers else ""
        return f"{job.describe()}; {len(job.solvers)} methods{peers}"

    def _compute(self, job, progress):
        return wp.measure(job.scene, [m for m, _ in job.solvers.values()], job.values, job.T, theta=job.method_theta,
                          peers=job.peers, rtols=WP_RTOLS, max_steps=WP_MAX_STEPS, budget=WP_BUDGET,
                          progress=progress)

    def open_row(self, row):
        """Open a cosymp run in the Orbits view: the measured scene and parameters, the run's
        method (and θ), its h and the measured T. A scipy run cannot be opened there: a note says so."""
        if row["kind"] != "cosymp":
            self.study.say(Note("info", f"{row['solver']} at rtol = {row['rtol']:.0e} is scipy's solve_ivp, which "
                                        "the main view does not run: click a point of a cosymp method to open it"))
            return
        job = self.job
        method, theta = job.solvers[row["solver"]]
        updates = {"scene": job.scene, "values": dict(job.values), "method": method, "h": float(row["h"]),
                   "T": float(row["T"]), "view": "compare"}
        if theta is not None:
            updates["theta"] = theta
        self.study.param.update(**updates)


def default_top(h):
    """The largest horizon of DRIFT_TOPS with at most DRIFT_DEFAULT_STEPS steps of h (at least the first)."""
    fits = [T for T in DRIFT_TOPS if T / h <= DRIFT_DEFAULT_STEPS * (1 + 1e-9)]
    return fits[-1] if fits else DRIFT_TOPS[0]


class LongHorizons(Background):
    """Error and max |H~| at growing horizons (DRIFT_HORIZONS up to `T_max`), each chosen method
    at one step h, on the study's scene, parameters and θ. If the reference itself fails beyond
    some horizon (a scene whose state grows past floating point), the horizons below it are shown
    and a note says so."""

    methods = param.ListSelector(default=[], objects=list(METHODS), doc="cosymp's methods to run.")
    h = param.Number(default=0.1, label="Step h", doc="The step of every method (default: the scene's).")
    T_max = param.Selector(default=1e4, objects={f"{T:.0e}": T for T in DRIFT_TOPS}, label="Largest horizon",
                           doc="The horizons are 1e2, 2e2, 5e2, 1e3, ... up to this one.")
    KIND = "long horizons"

    def __init__(self, **params):
        super().__init__(**params)
        self.param.methods.objects = applicable(self.study.scene, METHODS)
        self.param.update({k: v for k, v in self._defaults().items() if k not in params})
        self.study.param.watch(self._on_scene, ["scene"])

    def _defaults(self):
        scene = self.study.scene_obj
        return {"methods": applicable(scene.name, wp.DRIFT_METHODS), "h": scene.h, "T_max": default_top(scene.h)}

    def _on_scene(self, event):
        self.param.methods.objects = applicable(self.study.scene, METHODS)
        self.param.update(self._defaults())

    def _job(self):
        s = self.study
        h = float(self.h)
        steps = check_step(h, self.T_max)
        if steps > wp.DRIFT_MAX_STEPS:
            raise InputError(f"T/h = {steps:.3g} steps per method is beyond this view's limit of "
                             f"{wp.DRIFT_MAX_STEPS:.0e}: increase h or choose a smaller largest horizon")
        horizons = tuple(T for T in wp.DRIFT_HORIZONS if h < T <= self.T_max)
        if not horizons:
            raise InputError(f"h = {h:g} is not below the horizons: choose h < {self.T_max:g}")
        return Measured(s.scene, dict(s.values), float(s.theta), solvers_of(s.scene, self.methods, s.values, s.theta),
                        h=h, horizons=horizons)

    def _describe(self, job):
        return f"{job.describe()}; {', '.join(job.solvers)}"

    def _compute(self, job, progress):
        return wp.drift(job.scene, [m for m, _ in job.solvers.values()], job.values, job.h, list(job.horizons),
                        theta=job.method_theta, progress=progress)

    def _finish(self, job, rows):
        short = [r for r in rows if r["status"].startswith(wp.REFERENCE_SHORT)]
        if short:
            top = max((r["T"] for r in rows if not r["status"].startswith(wp.REFERENCE_SHORT)), default=0.0)
            job = dataclasses.replace(job, horizons=tuple(T for T in job.horizons if T <= top * (1 + 1e-9)))
            self.study.say(Note("warning", f"long horizons shown up to T = {top:g} only: {short[0]['status']}"))
            rows = [r for r in rows if r not in short]
        super()._finish(job, rows)


MAP_MAX_SIDE = 100
MAP_MAX_STEPS = 200_000_000
# Default axes per scene: (x name, start, stop, log), (y name, start, stop, log).
MAP_AXES = {
    "decaying": (("h", 0.05, 3.0, True), ("lam", 0.1, 5.0, False)),
    "damped": (("h", 0.05, 3.0, True), ("gamma", -0.5, 0.5, False)),
    "modulated": (("alpha", 0.5, 4.5, False), ("eps", 0.0, 0.8, False)),
    "charged": (("h", 0.001, 0.1, True), ("B0", 0.0, 2.0, False)),
    "kapitza": (("nu", 5.0, 80.0, False), ("a", 0.0, 0.5, False)),
}


def map_axes(scene):
    """The Stability map's first axes for a scene: its MAP_AXES entry, else h on a log axis around
    the scene's step by its first parameter that is not an initial condition, over its slider range."""
    if scene.name in MAP_AXES:
        return MAP_AXES[scene.name]
    p = next(p for p in scene.params if not p.initial and not p.choices and not isinstance(p.default, str))
    return ("h", scene.h / 4, 8 * scene.h, True), (p.name, *soft_range(p), False)


def map_bytes(scene, points_steps, threads):
    """What a sweep holds at once: per thread one chunk of every-step records (t, z, p_t, H), its
    copy for the tangent maps and the maps (2n x 2n each), plus the grid's results."""
    m = 2 * scene.ndof
    per_step = 8 * (2 * (m + 3) + m * m)
    return threads * min(wp.CHUNK, points_steps + 1) * per_step + (8 << 20)


class StabilityMap(Background):
    """A measure of the study's method over a grid of two varied names (scene parameters, h, T or θ)
    with the study's other values, computed by cosymp.sweep on this machine's cores in the worker
    thread. A cell can be opened in the Orbits view (`open_cell`)."""

    measure = param.Selector(default="growth", objects=list(sweep.MEASURES), doc="What each cell shows.")
    x = param.Selector(default="h", objects=["h"], label="x axis")
    x_start = param.Number(default=0.05, label="from")
    x_stop = param.Number(default=3.0, label="to")
    x_log = param.Boolean(default=True, label="log x")
    nx = param.Integer(default=30, bounds=(2, MAP_MAX_SIDE), label="cells in x")
    y = param.Selector(default="gamma", objects=["gamma"], label="y axis")
    y_start = param.Number(default=-0.5, label="from")
    y_stop = param.Number(default=0.5, label="to")
    y_log = param.Boolean(default=False, label="log y")
    ny = param.Integer(default=30, bounds=(2, MAP_MAX_SIDE), label="cells in y")
    result = param.Parameter(doc="The last completed sweep (cosymp.sweep.Result).")
    KIND = "stability map"

    def __init__(self, **params):
        super().__init__(**params)
        self._on_scene()
        self.study.param.watch(self._on_scene, ["scene", "method"])

    def _on_scene(self, *events):
        names = sweep.variables(self.study.scene_obj, METHODS[self.study.method])
        self.param.x.objects = self.param.y.objects = names
        if events and all(e.name == "method" for e in events) and {self.x, self.y} <= set(names):
            return
        (xn, x0, x1, xl), (yn, y0, y1, yl) = map_axes(self.study.scene_obj)
        self.param.update(x=xn, x_start=x0, x_stop=x1, x_log=xl, y=yn, y_start=y0, y_stop=y1, y_log=yl)

    def _job(self):
        s = self.study
        if self.x == self.y:
            raise InputError(f"x and y both vary {self.x}: choose two different names")
        axes = [sweep.Axis.make(self.x, self.x_start, self.x_stop, self.nx, self.x_log),
                sweep.Axis.make(self.y, self.y_start, self.y_stop, self.ny, self.y_log)]
        varied = {self.x, self.y}
        fixed = {k: v for k, v in s.values.items() if k not in varied}
        run = {k: None if k in varied else v for k, v in
               (("theta", theta_for(s.method, s.theta)), ("h", s.h), ("T", s.T))}
        plan = sweep.plan(s.scene, s.method, axes, (self.measure,), fixed, **run)
        counts, shared = plan.step_counts()
        steps = int(counts.sum()) * shared
        if steps > MAP_MAX_STEPS:
            raise InputError(f"this map takes {steps:.3g} steps in all, beyond this view's {MAP_MAX_STEPS:.0e}: "
                             "use fewer cells, larger h or a shorter T (or run `cosymp sweep` on a cluster)")
        return plan

    def _bytes(self, plan):
        return map_bytes(SCENES[plan.scene], int(plan.step_counts()[0].max()), os.cpu_count() or 1)

    def _describe(self, plan):
        (ax, ay) = plan.axes
        fixed = ", ".join(f"{k} = {v}" for k, v in plan.values)
        return (f"{plan.measures[0]} of {plan.method} on {plan.scene}" + (f" ({fixed})" if fixed else "")
                + f": {ax.name} {ax.values[0]:g}…{ax.values[-1]:g} × {ay.name} {ay.values[0]:g}…{ay.values[-1]:g}, "
                f"{plan.size} cells, h = {plan.h:g}, T = {plan.T:g} where not varied")

    def _compute(self, plan, progress):
        return sweep.run(plan, progress=progress)

    def _finish(self, plan, result):
        self.job = plan
        self.param.update(result=result, setting=self._describe(plan))

    def release(self):
        """The page is gone: drop the map without redrawing it (see Derived.release)."""
        with param.parameterized.discard_events(self):
            self.result = None

    def open_cell(self, i, j):
        """Open cell (i along x, j along y) of the last map in the Orbits view: the map's scene,
        method and values with that cell's varied values."""
        plan = self.job
        point = {plan.axes[0].name: plan.axes[0].values[i], plan.axes[1].name: plan.axes[1].values[j]}
        values = dict(plan.values)
        updates = {"method": plan.method, "view": "compare"}
        for name, v in point.items():
            if name in sweep.RUN_NAMES:
                updates[name] = v
            else:
                values[name] = v
        if plan.theta is not None and "theta" not in point:
            updates["theta"] = plan.theta
        updates.update(h=point.get("h", plan.h), T=point.get("T", plan.T))
        if plan.scene != self.study.scene:
            self.study.scene = plan.scene
        self.study.param.update(values=values, **updates)
