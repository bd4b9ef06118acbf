"""The sidebar's study: scene, methods, θ, h, T and the scene's parameters, and their comparison.

`Study` holds the inputs every view shares and computes the comparison of its two methods (both
at once, in threads) whenever an input changes, through the app's one job mechanism: changes
made while it computes are merged into one more computation with the latest inputs. Bad input
never reaches the results: it becomes a `Note` in `message` saying what to change, the input
goes back to its last good value and the last good results stay. The views below it (the
controls, the scene's description, the preset links) are shared by every tab.
"""
import collections
import dataclasses
import html
import math
from concurrent.futures import ThreadPoolExecutor
from functools import cache
from typing import NamedTuple
from urllib.parse import urlencode

import panel as pn
import param

from cosymp import warm
from cosymp.diagnostics import loop_action
from cosymp.errors import InputError, RunError
from cosymp.integrate import Setup, check_step, default_stride
from cosymp.methods import METHODS
from cosymp.reference import SEGMENT, fine_steps, reference_states, refinement
from cosymp.report import render
from cosymp.report.scene import command as report_command
from cosymp.report.scene import scene_report
from cosymp.scenes import SCENES, first
from cosymp.study import carried_loop, loop_stride, with_reference
from cosymp.study import compare_until_failure as study_until_failure

from .jobs import Job, Note
from .plotting import equation, note, push, typeset
from .presets import HARD, PAPER, PRESETS, URL_NAMES, first_state, query_items, rounded
from .warmup import first_view
from .widgets import bound, empty

LIVE_MAX_STEPS = 2_000_000
# A comparison expected to take at most this long is computed in the change's handler: its results
# then reach the page with the change's other effects, in one message. Charged's and kapitza's first
# views (40-50 ms) took two at 0.03, the page laid out and painted between them.
QUICK_S = 0.06
SECONDS_PER_STEP = {}  # (scene, method, other, loops) -> what its last comparison in this server took per step
LIVE_REFERENCE_STEPS = 200_000  # a fine rk8 reference computed with its comparison takes at most this many steps (~0.15 s)
# A longer one is computed after its comparison is shown (LateReference), up to this many steps (about 15 s here).
LATE_REFERENCE_STEPS = 20_000_000
CLOUD_POINTS = {True: 32, False: 64}
LOOP_RADIUS = 0.05
# The tabs that draw the carried loop (Comparison.cloud): a comparison started while one of them is
# shown computes its runs' loops with them; otherwise they follow the runs (LateLoops).
LOOP_VIEWS = frozenset({"structure", "cloud", "play"})
DELTA = 1e-4
# A comparison peaks at 20-28 bytes per value its runs record (charged 20; 28-39 before compare ran on
# the fused driver, which forms no array of tangent maps; tracemalloc, tests/test_app_state.py checks
# that the lease is at least the peak and at most twice it).
BYTES_PER_RECORDED = 40
BYTES_PER_REFERENCE_VALUE = 12  # a reference's peak (`reference_bytes`) per value it keeps,
BYTES_PER_SEGMENT_VALUE = 64  # and per value of a segment's records
BYTES_PER_LOOP_VALUE = 20  # carried loops' peak per value they record (tracemalloc: 11-17 on four scenes, short and long)


def expected_quick(rate, h, T):
    """Whether a computation costing `rate` seconds per step (None: not known) is expected to take at
    most QUICK_S over T/h steps."""
    try:
        return rate is not None and rate * check_step(h, T) <= QUICK_S
    except InputError:
        return False


def note_rate(rates, key, run, steps):
    """Note in rates[key] what a completed run cost per step (`expected_quick` reads it). A run
    computed in the change's handler had the server's thread to itself: its cost is noted as it
    was. One computed in its own thread shared the interpreter with the loop's work meanwhile (the
    change's other effects written to the page), which slowed it: modulated's first view, at most
    30 ms alone, took 91 ms there, charged's 50 ms took 234, and neither was computed in the
    handler again. Such a run only lowers the cost noted (or notes a first one)."""
    rate = run.computed_s / steps
    if not run.threaded or rate < rates.get(key, math.inf):
        rates[key] = rate


def comparison_bytes(setups, h, T):
    """Peak memory of comparing the setups (study.compare: 2n + 2 members with increments, and
    their tangent maps), from the values the runs record, and of their reference where it is
    computed with them (`takes_reference`, `reference_bytes`)."""
    steps = check_step(h, T)
    total = 0
    for s in setups:
        m = 2 * s.scene.ndof
        members = m + 2
        records = steps // default_stride(steps, members, m, increments=True) + 1
        total += records * members * (m + 1)
    own = reference_bytes(setups[0], h, T) if setups and takes_reference(setups[0], h, T) else 0
    return BYTES_PER_RECORDED * total + own


def loops_bytes(setups, h, T):
    """Peak memory of the setups' carried loops (`carried_loops`), from the values they record:
    each point's state, p_t and H at each record (`loop_stride` of a run with `default_stride`)."""
    steps = check_step(h, T)
    total = 0
    for s in setups:
        m = 2 * s.scene.ndof
        every = loop_stride(steps, default_stride(steps, m + 2, m, increments=True))
        total += (steps // every + 1) * CLOUD_POINTS[s.scene.kernel.linear] * (m + 2)
    return BYTES_PER_LOOP_VALUE * total


def reference_bytes(setup, h, T):
    """Peak memory of the reference of a run of setup (`cosymp.reference.reference_states`): a
    state and its uncertainty (2n + 1 values) at every step h, which it keeps, and the records of
    its two rk8 runs over one segment, which it does not (tracemalloc: 8.6-10.4 bytes per value
    kept on long runs, 38-44 per value of a segment's records on short ones, kapitza and charged)."""
    steps = check_step(h, T)
    segment = min(steps, SEGMENT // refinement(setup, h)) + 1
    return (2 * setup.scene.ndof + 1) * (BYTES_PER_REFERENCE_VALUE * (steps + 1) + BYTES_PER_SEGMENT_VALUE * segment)


@dataclasses.dataclass(frozen=True)
class Entry:
    """One method's run in a comparison: label, method name, Comparison (None if nothing could be
    computed), and the failure message of a run that stopped early ('' if it reached T)."""

    label: str
    method: str
    comparison: object
    failure: str
    final_error: float = None  # relative, against the exact flow or the fine rk8 reference; None if neither
    # the reference run's own, relative as final_error (inf: unbounded); None against the exact flow
    final_uncertainty: float = None


@dataclasses.dataclass(frozen=True)
class Runs:
    """A comparison: the scene, step and horizon, and one Entry per method."""

    scene: str
    h: float
    T: float
    entries: tuple
    reference_failure: str = ""  # where and why the reference run stopped (run_pair)
    awaits: object = None  # the Awaited reference computed after these runs are shown (LateReference)
    loops_pending: bool = False  # their carried loops are computed after them (LateLoops)
    loops_failure: str = ""  # where and why a carried loop stopped before its run's end

    def with_loops(self, loops):
        """These runs with their carried loops (`carried_loops`'s result) in their comparisons."""
        def carried(e):
            if e.label not in loops.loops:
                return e
            cloud, area = loops.loops[e.label]
            return dataclasses.replace(e, comparison=dataclasses.replace(e.comparison, cloud=cloud, cloud_area=area))

        entries = tuple(carried(e) for e in self.entries)
        return dataclasses.replace(self, entries=entries, loops_pending=False, loops_failure=loops.failure)

    def same_runs(self, other):
        """Whether these and `other` hold the same runs (measured or given their loops since)."""
        run = lambda e: None if e.comparison is None else e.comparison.run
        return len(self.entries) == len(other.entries) and all(run(a) is run(b) for a, b in zip(self.entries, other.entries))

    def only_loops_differ(self, other):
        """Whether these runs are `other` but for their carried loops (added, or asked for again)."""
        return (other is not None and len(other.entries) == len(self.entries)
                and same_but(self, other, ("entries", "loops_pending", "loops_failure"))
                and all(same_but(a, b, ("comparison",)) and (a.comparison is b.comparison or same_but(
                    a.comparison, b.comparison, ("cloud", "cloud_area"))) for a, b in zip(self.entries, other.entries)))

    @property
    def ok(self):
        return [e for e in self.entries if e.comparison is not None]

    def against(self, kept):
        """These runs measured against a LateReference's Kept where they await it (and no longer
        awaiting it), else these runs themselves."""
        if self.awaits is None or self.awaits.key != kept.key:
            return self
        return dataclasses.replace(measured(self, kept.reference, kept.failure), awaits=None)

    @property
    def dense(self):
        """Whether a run recorded more states than a portrait draws as lines."""
        from .plotting import DENSE

        return any(len(e.comparison.run.t) > DENSE for e in self.ok)


def theta_for(method, theta):
    return theta if METHODS[method].takes_theta else None


def same_but(a, b, names):
    """Whether the dataclasses a and b hold the same objects in every field but `names`."""
    return type(a) is type(b) and all(getattr(a, f.name) is getattr(b, f.name)
                                      for f in dataclasses.fields(a) if f.name not in names)


def compare_until_failure(setup, h, T):
    """cosymp.study.compare_until_failure with this app's separation, without the carried loop
    (`carried_loops` computes it for the runs)."""
    return study_until_failure(setup, h, T, delta=DELTA)


class Loops(NamedTuple):
    """The carried loops of a comparison's runs: {label: (Trajectory, area over initial area)},
    and where and why one stopped before its run's end ('' if none did)."""

    loops: dict
    failure: str


def carried_loops(runs, progress=None):
    """The Loops of the runs (`cosymp.study.carried_loop`: a loop of CLOUD_POINTS[linear] states
    around each run's start, a linear map carrying a polygon to a polygon, so fewer suffice there),
    each method's in a thread of its own; progress(done, total) in steps over both. A loop that
    stops (Newton, overflow) is kept up to there, and said in `failure`: its run still shows to its end."""
    ok = runs.ok
    done = dict.fromkeys(e.label for e in ok)
    total = sum(e.comparison.run.steps for e in ok)

    def one(e):
        c = e.comparison

        def told(n, _):
            done[e.label] = n
            if progress is not None:
                progress(sum(v or 0 for v in done.values()), total)

        try:
            return carried_loop(c.setup, runs.h, c.run.steps, loop_stride(c.run.steps, c.run.stride), c.run.z[0, 0],
                                CLOUD_POINTS[c.setup.scene.kernel.linear], LOOP_RADIUS, told), ""
        except RunError as err:
            cloud = err.partial
            area = loop_action(cloud)
            return (cloud, area / area[0]), f"{e.label}'s carried loop: {err}; drawn up to t = {cloud.t[-1]:.6g}"

    with ThreadPoolExecutor(max(1, len(ok))) as pool:
        results = list(pool.map(one, ok))
    return Loops({e.label: loop for e, (loop, _) in zip(ok, results)}, " | ".join(f for _, f in results if f))


def takes_reference(setup, h, T):
    """Whether a comparison of setup computes the reference its errors are measured against with
    its runs: where the scene has no exact flow and the reference (rk8 at a fine step, as in the
    report) takes at most LIVE_REFERENCE_STEPS steps."""
    return not setup.scene.has_flow and fine_steps(setup, h, T) <= LIVE_REFERENCE_STEPS


@dataclasses.dataclass(frozen=True)
class Awaited:
    """A reference computed after its comparison is shown: key (`reference_key`), label (which run it
    is), the rk8 steps it takes, and the setup, h and T it is computed for."""

    key: tuple
    label: str
    steps: float
    setup: object = dataclasses.field(compare=False, repr=False)
    h: float = dataclasses.field(compare=False)
    T: float = dataclasses.field(compare=False)


def awaited(setup, h, T, state):
    """The Awaited reference of a comparison of setup with these inputs (study.Study's `state`), or
    None: where the scene has no exact flow and the reference is longer than a live one
    (`takes_reference`) and at most LATE_REFERENCE_STEPS steps."""
    if setup.scene.has_flow:
        return None
    steps = fine_steps(setup, h, T)
    if not LIVE_REFERENCE_STEPS < steps <= LATE_REFERENCE_STEPS:
        return None
    return Awaited(reference_key(state), f"rk8 at h/{refinement(setup, h)}", steps, setup, h, T)


def reference_key(state):
    """What a comparison's reference depends on, from the study's inputs: the scene, its values, h and
    T (not the methods)."""
    return state["scene"], tuple(sorted(state["values"].items())), state["h"], state["T"]


def live_reference(setup, h, T):
    """The Reference (`cosymp.reference.reference_states`) the scene's errors are measured against
    (`takes_reference`), or None."""
    return reference_states(setup, h, T) if takes_reference(setup, h, T) else None


def final_error(comparison, failure):
    """(the relative error at T, against the exact flow or the reference run, and that run's own
    uncertainty): (None, None) without either, the uncertainty None against the exact flow."""
    if comparison is None or failure or comparison.error is None:
        return None, None
    spread = comparison.uncertainty
    return float(comparison.error[-1]), None if spread is None else float(spread[-1])


def run_pair(scene, setups, h, T, awaits=None, loops=False):
    """Compare the setups and compute the reference (all at once, in threads) and return Runs; with
    `awaits` (an Awaited), the reference is left to be computed after the runs are shown; their
    carried loops are computed with them where `loops` is true, else left pending (LateLoops)."""
    with ThreadPoolExecutor(len(setups) + 1) as pool:
        reference = pool.submit(live_reference, setups[0], h, T)
        done = list(pool.map(lambda s: compare_until_failure(s, h, T), setups))
        # A reference run that stops (overflow) leaves the runs shown without errors: it failed the
        # whole comparison (charged with beta(t) = exp(t): the fine rk8 run overflows at t = 8.87,
        # RK4 at 7.6, and midpoint reaches T).
        try:
            reference, stopped = reference.result(), ""
        except RunError as err:
            reference, stopped = None, str(err)
    entries = []
    for s, (comparison, failure) in zip(setups, done):
        label = s.method.label(s.theta)
        if any(e.label == label for e in entries):
            label += " (2)"
        entries.append(Entry(label, s.method.name, comparison, failure))
    runs = measured(Runs(scene, h, T, tuple(entries), awaits=awaits, loops_pending=True), reference, stopped)
    return runs.with_loops(carried_loops(runs)) if loops else runs


def measured(runs, reference, stopped=""):
    """The runs with their errors measured against the reference (None: the exact flow's, already
    in their comparisons, or none, `stopped` saying why the reference failed, if it did)."""
    entries = []
    for e in runs.entries:
        comparison = e.comparison
        if comparison is not None and reference is not None:
            comparison = with_reference(comparison, reference, runs.h)
        error, spread = final_error(comparison, e.failure)
        entries.append(dataclasses.replace(e, comparison=comparison, final_error=error, final_uncertainty=spread))
    return dataclasses.replace(runs, entries=tuple(entries), reference_failure=stopped)


def waiting_text(study):
    """What a comparison that runs long computes, while the plots show the last results ('' for
    inputs it will refuse), or what it waits for while the server compiles kernels (a cold cache).
    No time is guessed: this server's rate per step (SECONDS_PER_STEP), noted from shorter runs,
    holds their fixed costs (kapitza at T = 2000 was said to take 16 s, and took 8)."""
    try:
        steps = check_step(study.h, study.T)
    except InputError:
        return ""
    if warm.compiling():
        return (f"Computing h = {study.h:g} to T = {study.T:g} ({steps:,} steps) once this scene's kernels are "
                "compiled: the server's first start compiles them in the background and serves other pages "
                "meanwhile.")
    return f"Computing h = {study.h:g} to T = {study.T:g} ({steps:,} steps): the plots show the last results until then."


def failure_note(runs):
    texts = [f"{e.label}: {e.failure}" + (f"; showing data up to t = {e.comparison.run.t[-1]:.6g}"
                                          if e.comparison is not None else "")
             for e in runs.entries if e.failure]
    if runs.reference_failure:
        texts.append(f"no error is measured: {runs.reference_failure}")
    return Note("warning", " | ".join(texts)) if texts else None


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
    """A Parameterized class mirroring the scene's parameters (docs, choices, slider ranges). Its
    numbers take any value: the scene checks them (Study says what is wrong and puts the last good
    value back)."""
    scene = SCENES[scene_name]
    params = {}
    for p in scene.params:
        if p.choices:
            params[p.name] = param.Selector(default=p.default, objects=list(p.choices), doc=p.doc, label=p.name)
        elif isinstance(p.default, str):
            params[p.name] = param.String(default=p.default, doc=p.doc, label=p.name)
        else:
            lo, hi = soft_range(p)
            params[p.name] = param.Number(default=float(p.default), softbounds=(lo, hi), step=(hi - lo) / 500,
                                          doc=p.doc, label=p.name)
    return param.parameterized_class(f"{scene_name.title()}Inputs", params)


class Kept(NamedTuple):
    """What a LateReference computed for a key: the Reference, or None and why not (failure); final
    where the same inputs give the same (a reference, or its own overflow), not where the server
    refused or failed it (memory), which is tried again."""

    key: tuple
    reference: object
    failure: str
    final: bool


class ForRuns(Job):
    """A computation for the study's runs, beside or after their comparison: it computes what it
    was last asked (`asked`), in its thread with progress and cancel, and keeps the words of a
    failure (`say`) for the study to show with the runs they are about, not as a notice. Its memory
    is held while its result is shown."""

    HOLD = True

    def __init__(self, study, **params):
        super().__init__(**params)
        self.study = study
        self.asked = None
        self._said = ""

    def say(self, note):
        self._said = note.text

    def _inputs(self):
        return self.asked


class LateReference(ForRuns):
    """The reference of a comparison too long to compute with it (`awaited`), computed in its thread
    from the moment the comparison starts (beside it), with progress and cancel, and kept for the
    study's runs that await it: a change of method measures the new runs against the kept one at
    once. Its memory is held while it is kept."""

    KIND = "reference run"
    WHAT = "this reference run"

    def __init__(self, study, **params):
        super().__init__(study, **params)
        self.kept = None  # the Kept of the last one computed (`asked`: the Awaited asked for last)

    def ask(self, awaits):
        """Compute the reference `awaits` (an Awaited; None: none is awaited now) unless it is being
        computed or kept. One being computed for other inputs is stopped; one kept for other inputs,
        or refused, goes, and its memory with it (the runs measured against it keep their errors)."""
        if awaits is not None and self.busy and self.asked is not None and self.asked.key == awaits.key:
            return
        self.discard()
        if self.kept is not None and (awaits is None or self.kept.key != awaits.key or not self.kept.final):
            self.drop()
        self.asked = awaits
        if awaits is not None and self.kept is None:
            self.progress = 0.0  # the runs awaiting it may be shown before it starts
            self.request()

    def drop(self):
        """The kept reference goes, and its memory."""
        self.kept = None
        self.let_go()

    def _bytes(self, a):
        return reference_bytes(a.setup, a.h, a.T)

    def _compute(self, a, run):
        try:
            return reference_states(a.setup, a.h, a.T, progress=run.report), ""
        except RunError as err:  # its own overflow: the same inputs overflow again
            return None, str(err)

    def _finish(self, a, result):
        self._settle(Kept(a.key, *result, final=True))

    def _refused(self):
        self._settle(Kept(self.asked.key, None, self._said, final=False))

    def _failed(self, a):
        self._settle(Kept(a.key, None, self._said, final=False))

    def _settle(self, kept):
        self.kept = kept
        if kept.reference is None:  # nothing is kept to hold memory for
            self.let_go()
        self.study.arrived(kept)


class LateLoops(ForRuns):
    """The carried loops of the runs shown, computed after them (in its thread, with progress and
    cancel) where the comparison did not compute them (no tab drawing them was shown at its start,
    LOOP_VIEWS): the Orbits view's runs come without waiting for loops it does not draw (kapitza's
    first view: gauss4's comparison 8 ms, its 64-point loop 47 ms more). Its memory is held while
    they are shown."""

    KIND = "carried loop"
    WHAT = "computing the carried loops"

    def __init__(self, study, **params):
        super().__init__(study, **params)
        self.missed = None  # the Runs whose loops were refused memory or failed as a whole (`_settle`)

    def ask(self, runs):
        """Compute the loops of `runs` if they are pending (None: none now); what is under way for
        other runs stops, and the memory of loops no longer shown goes."""
        if runs is not None and runs is self.asked and self.busy:
            return
        self.discard()
        self.let_go()
        self.missed = None
        self.asked = runs if runs is not None and runs.loops_pending else None
        if self.asked is not None:
            self.request()

    def _refused(self):
        self._settle(self.asked)

    def _failed(self, runs):
        self._settle(runs)

    def _settle(self, runs):
        """The runs are shown without loops, saying why; a tab drawing them asks again when it is
        shown (Study._on_view): the memory may be free by then."""
        self.missed = runs
        self.study.loops_arrived(runs, Loops({}, f"The carried loops were not computed: {self._said}"))

    def _bytes(self, runs):
        return loops_bytes([e.comparison.setup for e in runs.ok], runs.h, runs.T)

    def _compute(self, runs, run):
        return carried_loops(runs, run.report)

    def _finish(self, runs, loops):
        self.study.loops_arrived(runs, loops)


FIRST_VIEW = first_view()

class Study(Job):
    """Scene, methods and parameters of a comparison, and its results.

    `values` holds the scene parameters that differ from the scene's defaults (the URL carries
    it); `inputs` is a Parameterized mirroring the scene's parameters, for the controls. Either
    can be changed; the other follows. `view` names the shown tab (main.py checks it).

    A change of scene (the Scene menu) opens the scene's first view (Case.first): its methods, h, T
    and values, but for those changed with it; the shown tab stays. A study made with a scene (a
    link) takes the scene's defaults, the paper's values, for whatever the link does not name.
    """

    scene = param.Selector(default=FIRST_VIEW["scene"], objects={s.title: k for k, s in SCENES.items()},
                           doc="The time-dependent Hamiltonian system.")
    method = param.Selector(default=FIRST_VIEW["method"], objects={m.title: k for k, m in METHODS.items()},
                            doc="The method under study.")
    other = param.Selector(default=FIRST_VIEW["other"], objects={m.title: k for k, m in METHODS.items()},
                           doc="The method it is compared with.", label="Compared with")
    theta = param.Number(default=0.5, bounds=(0.0, 1.0), step=0.01, label="θ",
                         doc="θ of the theta methods (θ = 1/2: midpoint; θ = 0: the paper's scheme).")
    h = param.Number(default=FIRST_VIEW["h"], doc="Step size h > 0.")
    T = param.Number(default=FIRST_VIEW["T"], doc="Horizon T of the live views.")
    values = param.Dict(default=dict(FIRST_VIEW["values"]), doc="Scene parameters that differ from the scene's defaults.")
    view = param.String(default="compare", doc="The shown tab.")
    inputs = param.Parameter(doc="The scene's parameters as a Parameterized (for the controls).")
    results = param.ClassSelector(class_=Runs, doc="The last good comparison.")
    message = param.ClassSelector(class_=Note, doc="The last message for the user.")

    KIND = "comparison"
    WHAT = "this comparison"
    HOLD = True
    INPUTS = ("scene", "method", "other", "theta", "h", "T", "values")

    def __init__(self, **params):
        super().__init__(**params)
        scene = self.scene_obj
        chosen = "scene" in params  # a chosen scene opens on its own h, T and values, the first view on its own
        if chosen:
            self.param.update({k: getattr(scene, k) for k in ("h", "T") if k not in params})
            if "values" not in params:
                self.values = {}
        self._nested = False
        self._syncing = False
        self.late = LateReference(self)
        self.carry = LateLoops(self)
        try:
            self.inputs = self._make_inputs()
        except InputError as err:
            self.say(Note("error", str(err)))
            self.values = {}
            self.inputs = self._make_inputs()
        self._good = None
        self.param.watch(self._on_change, list(self.INPUTS))
        self.param.watch(self._on_view, "view")
        self.refresh()
        if self.results is None and not self.running:  # refused (a link's h or T, say): the scene's own run instead
            h, T, values = (scene.h, scene.T, {}) if chosen else (FIRST_VIEW["h"], FIRST_VIEW["T"], FIRST_VIEW["values"])
            self._set({"h": h, "T": T, "values": dict(values), "method": FIRST_VIEW["method"],
                       "other": FIRST_VIEW["other"]})
            self.inputs = self._make_inputs()
            self.refresh()

    def release(self):
        super().release()
        self.late.release()
        self.carry.release()

    def arrived(self, kept):
        """A LateReference's Kept: the runs shown that await it are measured against it."""
        runs = self.results
        shown = runs.against(kept) if runs is not None else None
        if shown is runs:
            return
        self.results = shown
        if kept.failure:
            self.say(failure_note(self.results))

    def loops_arrived(self, runs, loops):
        """A LateLoops' result for `runs`: added to the runs shown if they are those runs (a late
        reference may have measured them meanwhile)."""
        shown = self.results
        if shown is not None and shown.loops_pending and shown.same_runs(runs):
            self.results = shown.with_loops(loops)

    def _on_view(self, event):
        if not self.running:  # else its end asks (`_finish`, `_failed`)
            self._ask_missed_loops()

    def _ask_missed_loops(self):
        """Where a tab drawing the carried loops is shown, ask again for those of the runs shown that
        were refused memory or failed as a whole (LateLoops.missed)."""
        runs, missed = self.results, self.carry.missed
        if (self.view in LOOP_VIEWS and runs is not None and missed is not None
                and not runs.loops_pending and runs.same_runs(missed)):
            self.results = dataclasses.replace(runs, loops_pending=True, loops_failure="")
            self.carry.ask(self.results)

    def say(self, note):
        """Post a message (a repeated message is posted again)."""
        with param.parameterized.discard_events(self):
            self.message = note
        self.param.trigger("message")

    @property
    def scene_obj(self):
        return SCENES[self.scene]

    def checked_values(self):
        """Every scene parameter's value, checked, or None while a refused one is in `values`."""
        try:
            return self.scene_obj.values(self.values)
        except InputError:
            return None

    def state(self):
        """The inputs as the URL holds them."""
        return {k: rounded(getattr(self, k)) for k in URL_NAMES}

    def setups(self):
        """The two checked setups, or InputError saying what to change."""
        scene = self.scene_obj
        for m in (self.method, self.other):
            reason = METHODS[m].refusal(scene, titles=True)  # named as the menus name them
            if reason:
                raise InputError(reason)
        return tuple(Setup.make(scene, m, self.values, theta_for(m, self.theta)) for m in (self.method, self.other))

    def check_horizon(self):
        """The live views' number of steps T/h (rounded up), or InputError saying what to change: a
        step longer than T (a single step far past T, judged as a run to T) or more steps than the live
        views take."""
        steps = check_step(self.h, self.T)
        if steps > LIVE_MAX_STEPS:
            raise InputError(f"T/h = {steps:.3g} steps is beyond the live views' limit of "
                             f"{LIVE_MAX_STEPS:.0e}: increase h, shorten T, or use the Long run view")
        vals = self.checked_values()
        if vals is not None:
            self.scene_obj.check_horizon(vals, steps * self.h)  # a typed beta(t)'s pole (the runs end there)
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
        if "scene" in changed:  # the scene's first view, but for what was changed with it
            updates = {k: v for k, v in first_state(scene).items() if k not in changed}
            try:
                scene.values(updates.get("values", self.values))
            except InputError as err:
                self.say(Note("error", str(err)))
                updates["values"] = {}
            self._set(updates)
            self.inputs = self._make_inputs()
        elif "values" in changed:
            try:
                vals = scene.values(self.values)
            except InputError as err:
                self.say(Note("error", str(err)))
                self._restore()
                return
            self._syncing = True
            try:
                self.inputs.param.update(**vals)
            finally:
                self._syncing = False
        self.request()

    def _set(self, updates):
        self._nested = True
        try:
            self.param.update(**updates)
        finally:
            self._nested = False

    def _restore(self):
        """Put the inputs of the last good comparison back (after bad input was refused)."""
        if self._good is None:
            return
        self._set({k: v for k, v in self._good.items() if getattr(self, k) != v})
        if not isinstance(self.inputs, inputs_class(self.scene)):  # refused with a change of scene
            self.inputs = self._make_inputs()
        else:
            self._syncing = True
            try:
                self.inputs.param.update(**self.scene_obj.values(self.values))
            finally:
                self._syncing = False

    def _refused(self):
        self._restore()

    def _failed(self, inputs):
        """A comparison that failed as a whole leaves the last good one shown: its inputs are put
        back too, unless they changed meanwhile (the box held beta(t) = exp(t) while every plot showed
        the previous beta)."""
        if {k: getattr(self, k) for k in self.INPUTS} == inputs[4]:
            self._restore()
        # Its start stopped the reference the runs shown await, and their pending loops: asked for again
        # (loops computed stay, with their memory).
        runs = self.results
        self.late.ask(runs.awaits if runs is not None else None)
        if runs is not None and runs.loops_pending:
            self.carry.ask(runs)
        self._ask_missed_loops()

    def _inputs(self):
        """(scene, setups, h, T, the inputs as the study holds them, the Awaited reference or None,
        whether its runs' loops are computed with them: a tab drawing them is shown)."""
        setups = self.setups()
        self.check_horizon()
        h, T, state = float(self.h), float(self.T), {k: getattr(self, k) for k in self.INPUTS}
        return self.scene, setups, h, T, state, awaited(setups[0], h, T, state), self.view in LOOP_VIEWS

    def _bytes(self, inputs):
        return comparison_bytes(*inputs[1:4]) + (loops_bytes(*inputs[1:4]) if inputs[6] else 0)

    def _started(self, inputs):
        """The reference awaited by this comparison starts beside it (or the one under way stops);
        the loops being computed for the runs shown stop (those computed hold their memory while
        shown: until this comparison's runs replace them, `_finish`)."""
        self.late.ask(inputs[5])
        self.carry.discard()

    def _compute(self, inputs, run):
        scene, setups, h, T, _, awaits, loops = inputs
        return run_pair(scene, setups, h, T, awaits, loops)

    def _finish(self, inputs, runs):
        self._good = inputs[4]
        if self.late.kept is not None:
            runs = runs.against(self.late.kept)
        self.results = runs
        note_ = failure_note(runs)
        if note_:
            self.say(note_)
        self.carry.ask(runs)

    def quick(self):
        """Whether the last comparison of this scene and pair of methods in this server, with or without
        their carried loops as this one (`_inputs`), scaled to this many steps, took at most QUICK_S (a
        comparison's cost per step depends on little else; kapitza's loops cost 6 times its runs)."""
        key = (self.scene, self.method, self.other, self.view in LOOP_VIEWS)
        return expected_quick(SECONDS_PER_STEP.get(key), self.h, self.T)

    def _done_in(self, inputs, elapsed):
        """A live comparison keeps no status line; its cost per step is noted (`quick`): the time the
        computation itself took, not the time to its results on the loop (`elapsed`), which counts
        the loop's other work meanwhile. With the latter, a comparison computed in its thread once
        was never quick again: modulated's first view (6 ms) noted 35-40 ms a time, above QUICK_S,
        and each scene change to it came in two messages 110 ms apart. A run in its own thread can
        only lower it (`note_rate`)."""
        scene, setups, h, T = inputs[:4]
        note_rate(SECONDS_PER_STEP, (scene, *(s.method.name for s in setups), inputs[6]), self.run, check_step(h, T))


def report_filename(study):
    """The report's file name, also in its 'Reproduce' command: the scene and the method."""
    return f"cosymp-{study.scene}-{study.method}.html"


class ReportInputs(NamedTuple):
    """What a study's report is made of, read at once (on the loop, as the page shows it): the
    setups, h, T, the file name, and the views' own (Comparison, failure) pairs where they match
    these inputs (None: computed afresh)."""

    setups: tuple
    h: float
    T: float
    filename: str
    computed: list

    def bytes(self):
        """Memory the report computes beyond the page's runs: a comparison afresh, and a reference
        where a comparison it takes is not measured (no exact flow; the page's awaits or lost its
        own)."""
        setups, h, T, computed = self.setups, self.h, self.T, self.computed
        fresh = comparison_bytes(setups, h, T) if computed is None else 0
        unmeasured = computed is None or any(c is not None and c.error is None for c, _ in computed)
        return fresh + (reference_bytes(setups[0], h, T) if unmeasured and not setups[0].scene.has_flow else 0)


def report_inputs(study):
    """The study's ReportInputs, or InputError saying what to change."""
    setups = tuple(study.setups())
    study.check_horizon()
    h, T = float(study.h), float(study.T)
    runs = study.results
    computed = None
    if runs is not None and (runs.scene, runs.h, runs.T) == (study.scene, h, T) and all(
            e.comparison is None or e.comparison.setup.values == s.values for e, s in zip(runs.entries, setups)) \
            and [e.method for e in runs.entries] == [s.method.name for s in setups]:
        computed = [(e.comparison, e.failure) for e in runs.entries]
    return ReportInputs(setups, h, T, report_filename(study), computed)


def rendered_report(inputs, lease=None):
    """The HTML report of ReportInputs (in any thread: it reads no study); `lease`, the memory it
    holds meanwhile (`ReportInputs.bytes`), is released when it is done."""
    try:
        setups, h, T = inputs.setups, inputs.h, inputs.T
        report = scene_report(setups, h, T, report_command(setups, h, T, inputs.filename), computed=inputs.computed)
        return render(report)
    finally:
        if lease is not None:
            lease.release()


def study_report(study):
    """The HTML report of the study's comparison (the views' own runs when they match the
    inputs, else computed afresh), or InputError saying what to change."""
    return rendered_report(report_inputs(study))


# ---------------------------------------------------------------- the sidebar and the header


class Controls(pn.viewable.Viewer):
    """Scene, methods, θ, h, T and the scene's own parameters (generated from its metadata)."""

    study = param.ClassSelector(class_=Study)

    def __panel__(self):
        s = self.study
        takes_theta = pn.bind(lambda m, o: METHODS[m].takes_theta or METHODS[o].takes_theta,
                              s.param.method, s.param.other)
        wide = {"sizing_mode": "stretch_width"}
        return pn.Column(
            pn.widgets.Select.from_param(s.param.scene, name="Scene", **wide),
            pn.widgets.Select.from_param(s.param.method, name="Method", **wide),
            pn.widgets.FloatSlider.from_param(s.param.theta, visible=takes_theta, **wide),
            pn.widgets.Select.from_param(s.param.other, **wide),
            pn.Row(bound(pn.widgets.FloatInput, s, "h", label="Step h", description=s.param.h.doc, format="0.[000000]",
                         **wide),
                   bound(pn.widgets.FloatInput, s, "T", label="Horizon T", description=s.param.T.doc, **wide), **wide),
            note("<h4>Scene parameters</h4>", margin=(10, 5, 0, 5)),
            SceneControls(study=s),
            **wide,
        )


def kind(p):
    """The kind of control a scene parameter takes."""
    if isinstance(p, param.Selector):
        return ChoiceControl
    return TextControl if isinstance(p, param.String) else NumberControl


class SceneControls(pn.viewable.Viewer):
    """A control for each of the scene's parameters: a slider with a text box for each number (the
    slider spans a range around the default; any value can be typed), a select for choices, a text
    input (applied on Enter) for beta(t).

    The controls are a fixed pool, rebound in place when the scene changes: at each position, one
    control of each kind some scene has there, so that no scene reorders them. New widgets cost
    the server 0.2 s and the browser a layout of the sidebar (115 kB of models for charged), and a
    reordered column re-renders its children."""

    study = param.ClassSelector(class_=Study)

    def __init__(self, **params):
        super().__init__(**params)
        kinds = collections.defaultdict(list)
        for key, s in SCENES.items():
            for i, p in enumerate(s.params):
                k = kind(inputs_class(key).param[p.name])
                if k not in kinds[i]:
                    kinds[i].append(k)
        self.pool = [{k: k(self.study.say) for k in kinds[i]} for i in range(len(kinds))]
        self._glossary = note("", margin=(0, 5))
        self._column = pn.Column(*[c.layout for at in self.pool for c in at.values()], self._glossary,
                                 sizing_mode="stretch_width", margin=0)
        self._bind(self.study.inputs)
        self.study.param.watch(lambda e: push(lambda: self._bind(e.new)), "inputs")  # one message
        self.study.param.watch(lambda e: self._disable_unused(), "values")

    def __panel__(self):
        return self._column

    def shown(self):
        """The controls bound to the scene's parameters, in the scene's order."""
        return [c for at in self.pool for c in at.values() if c.name is not None]

    def _bind(self, inputs):
        names = [n for n in inputs.param if n != "name"]
        for i, at in enumerate(self.pool):
            chosen = kind(inputs.param[names[i]]) if i < len(names) else None
            for k, control in at.items():
                if k is chosen:
                    control.bind(inputs, names[i])
                else:
                    control.unbind()
        self._glossary.object = glossary(inputs, names)
        self._disable_unused()

    def _disable_unused(self):
        """Disable the controls of parameters the other values leave without effect (eps and w
        with a constant beta(t), say): a slider that moves nothing would teach that it does not matter."""
        vals = self.study.checked_values()
        if vals is not None:
            unused = self.study.scene_obj.unused(vals)
            for control in self.shown():
                control.enable(control.name not in unused)


def glossary(inputs, names):
    """What each of the scene's parameters means, below its controls (as text: a widget's tooltip
    is a new model each time it changes, and new models cost each scene change a walk of the whole
    page's model graph, about 35 ms)."""
    items = "".join(f"<li><b>{html.escape(n)}</b>: {html.escape(inputs.param[n].doc or '')}</li>" for n in names)
    return f"<details class='params'><summary>What the parameters mean</summary><ul>{items}</ul></details>"


class Control:
    """One pooled control: bound to a parameter of a scene's inputs (and shown), or unbound."""

    def __init__(self, layout, labelled, widgets, say):
        self.say = say  # the study's: a message for the page
        self.layout = layout
        self.labelled = labelled  # the widget carrying the label
        self.widgets = widgets
        self.inputs = self.name = None

    def bind(self, inputs, name):
        self.inputs = self.name = None  # no write to the old or new inputs while rebinding
        self.show(inputs, name)
        self.layout.visible = True
        inputs.param.watch(self._follow, name)
        self.inputs, self.name = inputs, name

    def unbind(self):
        """Hidden, and unlabelled (a hidden "q0" beside the shown one would make two)."""
        if self.name is not None:
            self.labelled.label = ""
        self.inputs = self.name = None
        self.layout.visible = False

    def _follow(self, event):
        if event.obj is self.inputs and event.name == self.name:
            self.show(self.inputs, self.name)

    def enable(self, on):
        for widget in self.widgets:
            widget.disabled = not on

    def take(self, value):
        if self.inputs is not None and value != getattr(self.inputs, self.name):
            setattr(self.inputs, self.name, value)

    def show(self, inputs, name):
        raise NotImplementedError


class NumberControl(Control):
    """A slider over the parameter's soft range and a box that takes any value; the slider widens
    to a typed value outside its range.

    Not Panel's EditableFloatSlider: in Panel 1.9 its JavaScript callback sits in a global
    registry whose entry refers back to the widget, so every one stays alive, and with it the
    inputs it shows, the Study watching them and the closed session's results."""

    def __init__(self, say):
        self.slider = pn.widgets.FloatSlider(start=0.0, end=1.0, value=0.0, format="0.[00000]",
                                             sizing_mode="stretch_width")
        # No start or end on the box: a typed value outside the scene's bounds must reach the
        # study, which says what is wrong and puts the last good value back.
        self.box = pn.widgets.FloatInput(label="", format="0.[00000]", width=100, align="end")
        super().__init__(pn.Row(self.slider, self.box, sizing_mode="stretch_width", margin=0), self.slider,
                         (self.slider, self.box), say)
        self.slider.param.watch(lambda e: self.take(e.new), "value")
        self.box.param.watch(self._typed, "value")

    def _typed(self, event):
        if event.new is None and self.name is not None:  # emptied: the value in use back, and why
            self.box.value = getattr(self.inputs, self.name)
            self.say(empty(self.name))
        else:
            self.take(event.new)

    def show(self, inputs, name):
        v = getattr(inputs, name)  # not the event's value: a refused one has been put back meanwhile
        p = inputs.param[name]
        if name != self.name:
            lo, hi = p.softbounds
            self.slider.param.update(label=p.label, start=min(lo, v), end=max(hi, v), step=p.step, value=v)
            self.box.value = v
        elif math.isfinite(v):
            self.slider.param.update(start=min(self.slider.start, v), end=max(self.slider.end, v), value=v)
            self.box.value = v


class TextControl(Control):
    def __init__(self, say):
        self.widget = pn.widgets.TextInput(sizing_mode="stretch_width",
                                           placeholder="e.g. 0.05*(1 + tanh(t)), then Enter")
        super().__init__(self.widget, self.widget, (self.widget,), say)
        self.widget.param.watch(lambda e: self.take(e.new), "value")

    def show(self, inputs, name):
        self.widget.param.update(label=f"{name}(t): 'paper', 'constant' or an expression of t",
                                 value=getattr(inputs, name))


class ChoiceControl(Control):
    def __init__(self, say):
        self.widget = pn.widgets.Select(sizing_mode="stretch_width")
        super().__init__(self.widget, self.widget, (self.widget,), say)
        self.widget.param.watch(lambda e: self.take(e.new), "value")

    def show(self, inputs, name):
        p = inputs.param[name]
        self.widget.param.update(label=p.label, options=list(p.objects), value=getattr(inputs, name))


class SceneInfo(pn.viewable.Viewer):
    """The scene's title, summary, equations, what to look for (in the scene, and in its first view),
    and its notes. A scene change rewrites the panes' text (and shows as many equation panes as the
    scene has), so the page's layout is not rebuilt."""

    study = param.ClassSelector(class_=Study)

    def __panel__(self):
        most = max(len(s.equations) for s in SCENES.values())
        self._head = note("", margin=(0, 10))
        self._equations = [equation("", styles={"font-size": "1.05em"}) for _ in range(most)]
        self._look = note("", margin=(0, 10))
        self._show(self.study.scene)
        self.study.param.watch(lambda e: self._show(e.new), "scene")
        self.study.param.watch(lambda e: self._show_equations(), "values")
        return pn.Column(self._head, pn.FlexBox(*self._equations, gap="1.5em", sizing_mode="stretch_width"),
                         self._look, sizing_mode="stretch_width")

    def _show(self, name):
        s = SCENES[name]
        notes = "".join(f"<li>{html.escape(n)}</li>" for n in s.notes)
        self._head.object = f"<h2>{html.escape(s.title)}</h2><p>{html.escape(s.summary)}</p>"
        self._show_equations()
        self._look.object = (f"<p class='lookfor'><b>Look for:</b> {html.escape(s.look_for)}<br><b>First view</b> "
                             f"({self._first_view_shown(s)}): {html.escape(first(s).doc)}</p>"
                             + (f"<ul class='notes'>{notes}</ul>" if notes else ""))

    def _first_view_shown(self, scene):
        """Whether the page opened on the scene's first view, which the box describes: a link naming
        the scene alone opens the paper's values (Study), and the box read as the page's state."""
        first_view = first_state(scene)
        if all(rounded(getattr(self.study, k)) == rounded(v) for k, v in first_view.items()):
            return "what the Scene menu opens"
        link = "?" + urlencode(query_items({**first_view, "view": self.study.view}, URL_NAMES))
        return (f"what the Scene menu opens; the link opened this page on other values: "
                f"<a href='{html.escape(link)}'>open the first view</a>")

    def _show_equations(self):
        """The scene's equations as its values make them (the beta(t) chosen, say)."""
        vals = self.study.checked_values()
        if vals is None:
            return
        lines = self.study.scene_obj.shown_equations(vals)
        for i, pane_ in enumerate(self._equations):
            shown = i < len(lines)
            pane_.param.update(object=typeset(lines[i]) if shown else "", visible=shown)


class PresetLinks(pn.viewable.Viewer):
    """Links that open the app on each paper figure's parameters, and on the hard cases (each
    with its sentence on what to see)."""

    def __panel__(self):
        groups = []
        for group in (PAPER, HARD):
            items = "".join(f"<li><a href='{html.escape(p.query())}' title='{html.escape(p.doc)}'>"
                            f"{html.escape(p.name)}</a>"
                            + (f"<br><small>{html.escape(p.doc)}</small>" if group == HARD else "") + "</li>"
                            for p in PRESETS if p.group == group)
            body = f"<ul class='presets'>{items}</ul>"
            groups.append(f"<h4>{group}</h4>{body}" if group == PAPER else
                          f"<details class='presets'><summary><b>{group}</b> (what each shows)</summary>{body}</details>")
        return note("".join(groups))

