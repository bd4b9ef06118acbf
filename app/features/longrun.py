"""Long run: the sidebar's scene, methods, parameters and h run to a long horizon in chunks off the
event loop, with progress and Cancel, drawn as per-bin envelopes as they arrive."""
import dataclasses
import html
import math
import time
from concurrent.futures import ThreadPoolExecutor
from functools import partial

import numpy as np
import panel as pn
import param

from cosymp.drive import CHUNK
from cosymp.errors import InputError
from cosymp.integrate import check_step
from cosymp.report.style import pair_colors
from cosymp.summary import long_drive

from ..jobs import Job, Note
from ..plotting import SLOTS, Curves, grid, note, push, swatch
from ..study import DELTA
from .base import Feature, FeatureView

LONG_BINS = 20_000
LONG_CHUNK_SECONDS = 0.3
LONG_DRAW_SECONDS = 1.0  # the envelopes are published at most this often (each redraw costs the event loop)
LONG_RUN_BYTES = 32 << 20  # measured peak 3.1 MB at any horizon, 2.2 MB of it the envelopes (tests/test_app_state.py)
KEYS = ("t", "H_min", "H_max", "vol_min", "vol_max", "det", "symp")


@dataclasses.dataclass
class LongSeries:
    """Per-bin envelopes of one method's long run: t (bin starts), H~ min/max, the paper's volume
    estimator min/max, and the max per bin of |det M - 1| and ||M^T J M - J||."""

    label: str
    method: str
    parts: dict = dataclasses.field(default_factory=lambda: {k: [] for k in KEYS})
    failure: str = ""

    def arrays(self):
        return {k: np.concatenate(v) if v else np.empty(0) for k, v in self.parts.items()}


def envelopes(series_):
    return {x.label: {**x.arrays(), "failure": x.failure, "method": x.method} for x in series_}


def default_horizon(study):
    """The scene's long horizon for the study (Scene.long_horizon), rounded up to two significant
    digits: a number to read in its box."""
    T = study.scene_obj.long_horizon(study.T, study.values)
    step = 10.0 ** (math.floor(math.log10(T)) - 1)
    return float(f"{math.ceil(T / step - 1e-9) * step:.2g}")


def _chunk(drives, n, i):
    return drives[i].advance(n)


class LongRun(Job):
    """A long run of the study's two methods (see the module's doc); `data` holds the envelopes so
    far, {label: arrays, failure, method}."""

    study = param.Parameter(doc="The sidebar's study.")
    T_long = param.Number(default=5e5, label="Long horizon T", doc="Horizon of the long run (chunked; capped at 1e8 steps).")
    data = param.Dict(default={}, doc="{label: envelope arrays and failure} of the run so far.")
    setting = param.String(default="", doc="What is (or was last) run.")

    KIND = "long run"
    WHAT = "a long run"
    KEEP = 4  # the envelopes are up to 2.2 MB a run

    def __init__(self, study, **params):
        params.setdefault("T_long", default_horizon(study))
        super().__init__(study=study, **params)
        self._said = set()
        self._steps_done = 0
        self._ran = None  # the key (`_key`) of the run shown
        self._asked = False  # a run was asked for and has not started: it replaces what is shown
        study.param.watch(self._on_scene, ["scene"])
        self.param.watch(self._check_horizon, ["T_long"])

    def _check_horizon(self, event):
        """A horizon typed or linked is checked at once, not on Start: one that is not a positive
        number within the step cap at the sidebar's h is refused with what to change, and the box and
        the link keep the value in use (0, -5 and 1e15 were kept, written into the link, and refused
        only on Start, as if the sidebar's T were wrong)."""
        try:
            check_step(self.study.h, event.new)
        except InputError as err:
            self.say(Note("error", f"Long horizon T = {event.new:g} refused: {err} (the box shows the value in use "
                                   "again)"))
            self.T_long = event.old

    def _on_scene(self, event):
        """Another scene: the run under way stops and the old scene's data goes (the view starts a
        run of the new one when its tab is shown: `wanted`)."""
        self.discard()
        self.param.update(data={}, setting="", T_long=default_horizon(self.study))

    def say(self, note_):
        self.study.say(note_)

    @property
    def partial_interval(self):
        return LONG_DRAW_SECONDS

    def _inputs(self):
        s = self.study
        setups = s.setups()
        steps = check_step(s.h, self.T_long)
        s.scene_obj.check_horizon(setups[0].values, steps * s.h)
        return setups, float(s.h), steps, dict(s.values), s.scene

    def _bytes(self, inputs):
        return LONG_RUN_BYTES

    @staticmethod
    def describe(inputs):
        setups, h, steps, values, scene = inputs
        labels = " vs ".join(x.method.label(x.theta) for x in setups)
        shown = ", ".join(f"{k} = {v}" for k, v in values.items())
        return f"{scene}: {labels}, h = {h:g}, T = {steps * h:g}" + (f", {shown}" if shown else "")

    def since(self):
        """'' while the sidebar and the horizon ask for the run shown (or none is shown), else a
        sentence saying what they ask for now (`describe`), or why a long run of it is refused: a long
        run starts on Start long run, a first visit or another scene, not on every change of the
        sidebar. A run under way says so too (a horizon typed during it is not what it runs); from a
        request to the run's start there is nothing to say: what is asked for runs next."""
        if not self.data or self._ran is None or self._asked:
            return ""
        try:
            inputs = self._inputs()
        except InputError as err:
            return f"the sidebar now asks for a long run that is refused: {err}"
        if self._key(inputs) == self._ran:
            return ""
        return f"now {self.describe(inputs)}: " + ("cancel this run, then press Start long run to run it"
                                                    if self.running else "press Start long run to run it")

    def request(self):
        self._asked = True
        super().request()

    def _refused(self):
        self._asked = False

    def cancel(self):
        self._asked = False
        super().cancel()

    def _started(self, inputs):
        self._asked = False
        self._said = set()
        self._steps_done = 0
        self._ran = self._key(inputs)
        self.param.update(data={}, status="running", setting=self.describe(inputs))

    def _compute(self, inputs, run):
        setups, h, steps, _, _ = inputs
        width = max(1, math.ceil(steps / LONG_BINS))
        cap = width * max(1, CHUNK // width)
        found = [LongSeries(x.method.label(x.theta), x.method.name) for x in setups]
        # one run per method, advanced chunk by chunk: it takes exactly the steps of one call
        drives = [long_drive(x, h, width, DELTA) for x in setups]
        active = [True] * len(setups)
        done = 0
        chunk = min(cap, width * max(1, 4096 // width))
        shown = -math.inf  # the first chunk is drawn at once
        with ThreadPoolExecutor(len(setups)) as pool:
            try:
                while done < steps and any(active):
                    n = min(chunk, steps - done)
                    tick = time.perf_counter()
                    running = [i for i, a in enumerate(active) if a]
                    outs = list(pool.map(partial(_chunk, drives, n), running))
                    for i, red in zip(running, outs):
                        if len(red["t"]):
                            for k, v in red.items():
                                found[i].parts[k].append(v)
                        if drives[i].failure:
                            active[i] = False
                            found[i].failure = drives[i].failure
                    done += n
                    now = time.perf_counter()
                    chunk = min(cap, width * max(1, round(n * LONG_CHUNK_SECONDS / max(now - tick, 1e-3) / width)))
                    if now - shown >= 0.5 * LONG_DRAW_SECONDS or any(x.failure for x in found):
                        run.publish(envelopes(found))
                        shown = now
                    run.report(done, steps, f"t = {done * h:.6g}")
            finally:
                run.publish(envelopes(found))
        return done, all(active)

    def _partial(self, inputs, data):
        self.data = data
        for label, d in data.items():
            if d["failure"] and label not in self._said:
                self._said.add(label)
                self.say(Note("warning", f"long run, {label}: {d['failure']}; showing data up to there"))

    def _on_progress(self, done, total, label):
        self._steps_done = done
        super()._on_progress(done, total, label)

    def _cancelled(self, inputs, elapsed):
        self.status = f"cancelled at t = {self._steps_done * inputs[1]:.6g} after {elapsed:.1f} s"

    def _finish(self, inputs, result):
        self._steps_done = result[0]

    def _done_in(self, inputs, elapsed):
        self._ended(inputs, self.run.result, f"in {elapsed:.1f} s", f"after {elapsed:.1f} s")

    def _ended(self, inputs, result, took, stopped):
        done, reached = result
        self.progress = done / max(inputs[2], 1)
        self.status = (f"done: {done} steps per method {took}" if reached else
                       f"stopped early (see the message) {stopped}")

    def _key(self, inputs):
        setups, h, steps, values, scene = inputs
        return scene, tuple((x.method.name, x.theta) for x in setups), tuple(sorted(values.items())), h, steps

    def _kept(self, run):
        return self.data, run.result

    def _recalled(self, inputs, kept, when):
        data, result = kept
        with param.parameterized.batch_call_watchers(self):  # drawn once
            self._started(inputs)
            self._partial(inputs, data)
            self._finish(inputs, result)
            by = f"computed at {when:%H:%M:%S} by this server"
            self._ended(inputs, result, f"({by})", f"({by})")


# (title, value label, log axis, the envelope: (t, y) of a method's arrays)
PLOTS = {
    "H": ("H~ = H + p_t, per-bin min and max", "H + p_t", False, "H"),
    "vol": ("paper's estimator: det[X¹ … X²ⁿ⁺¹], per bin", "det[X¹ … X²ⁿ⁺¹]", False, "vol"),
    "det": ("rigorous: max |det M_k − 1| per bin", "|det M_k − 1|", True, "det"),
    "symp": ("rigorous: max |M_kᵀ J M_k − J| per bin", "|M_kᵀ J M_k − J|", True, "symp"),
}


def band(d, key):
    """A method's per-bin min and max of H~ or of the volume estimator interleaved (so the curve
    spans each bin's range), or its per-bin max of a deviation."""
    t = d["t"]
    if key in ("H", "vol"):
        width = t[1] - t[0] if len(t) > 1 else 1.0
        return np.column_stack([t, t + 0.5 * width]).ravel(), np.column_stack([d[f"{key}_min"], d[f"{key}_max"]]).ravel()
    return t, d[key]


def long_key(data):
    if not data:
        return ""
    methods = [d["method"] for d in data.values()] + [""]
    colors = pair_colors(methods[0], methods[1])
    parts = [swatch(color, label, dashed=i == 1)
             + (f" <span class='caveat' title='{html.escape(d['failure'])}'>stopped at t = {d['t'][-1]:.6g}</span>"
                if d["failure"] and len(d["t"]) else "")
             for i, ((label, d), color) in enumerate(zip(data.items(), colors))]
    return "<div class='colorkey'>" + "&emsp;&emsp;".join(parts) + "</div>"


class LongRunView(FeatureView):
    NAME = "long"

    def layout(self):
        lr = self.state
        start = pn.widgets.Button(name="Start long run", button_type="primary", disabled=lr.param.running)
        start.on_click(lambda event: lr.start())
        cancel = pn.widgets.Button(name="Cancel", button_type="danger", disabled=pn.bind(lambda r: not r, lr.param.running))
        cancel.on_click(lambda event: lr.cancel())
        progress = pn.indicators.Progress(value=pn.bind(lambda p: round(100 * p), lr.param.progress), max=100,
                                          width=260, bar_color="primary", margin=(22, 10))
        status = pn.bind(lambda s, st: f"<p class='doc'>{html.escape(s)}<br><b>{html.escape(st)}</b></p>",
                         lr.param.setting, lr.param.status)
        self.plots = {k: Curves(title, "t", label, log=log) for k, (title, label, log, _) in PLOTS.items()}
        self.key = note("")
        self.since = note("")
        self.follow(lr, "data")
        lr.param.watch(self._say_since, ["data", "running", "T_long"])
        self.study.param.watch(self._say_since, ["method", "other", "h", "theta", "values"])
        return pn.Column(
            note("<p>The study's scene, methods, parameters and h, run to the long horizon in chunks off the "
                 "event loop. The plots show per-bin envelopes (each bin's min and max, or max) as they "
                 "arrive; the page stays usable meanwhile.</p>"),
            pn.Row(self.widget(pn.widgets.FloatInput, lr, "T_long", description=lr.param.T_long.doc, width=180),
                   start, cancel, progress),
            note(status), self.since, self.key,
            grid(*[c.panel for c in self.plots.values()]),
            sizing_mode="stretch_width")

    def wanted(self):
        if not self.state.data and not self.state.busy:
            self.state.request()

    def shown(self):
        super().shown()
        self._say_since()

    def _say_since(self, *events):
        """Say, while the tab is shown, when the run shown is not what the sidebar now asks for (the
        Stability map says so too); a hidden tab's text follows when it is shown."""
        if self.built and self.visible:
            ask = self.state.since()
            text = ("" if not ask else f"<p class='doc since'><b>Computed before the latest changes</b>: "
                    f"{html.escape(ask)}.</p>")
            if text != self.since.object:
                push(lambda: setattr(self.since, "object", text))

    def update(self):
        data = self.state.data
        methods = [d["method"] for d in data.values()] + ["", ""]
        for key, curves in self.plots.items():
            curves.show({slot: band(d, PLOTS[key][3]) for slot, d in zip(SLOTS, data.values()) if len(d["t"])},
                        methods[:2])
        self.key.object = long_key(data)


FEATURE = Feature("long", "Long run", LongRunView, LongRun, url={"T_long": "T_long"})
