"""Work–precision: error and max |H~| against wall time for the chosen methods over step sizes and
scipy's solve_ivp over tolerances, the time each needs to reach 1e-6 and 1e-9; and below, the
long-horizon growth of the error and of |H~| at one h. Both are measured on demand (Start), in
the background, with progress and Cancel; a click on a cosymp point opens that run in Orbits."""
import dataclasses
import datetime
import html
import math
from functools import partial

import numpy as np
import pandas as pd
import panel as pn
import param
from bokeh.core.properties import value
from bokeh.models import HoverTool, LegendItem, TapTool

from cosymp import workprecision as wp
from cosymp.errors import InputError
from cosymp.integrate import Setup, check_step
from cosymp.methods import METHODS
from cosymp.methods import applicable as applying
from cosymp.report.style import METHOD_COLORS, OTHER, method_color, method_marker
from cosymp.scenes import SCENES

from ..jobs import Job, Note
from ..memory import MB
from ..plotting import FLOOR, figure, legend_outside, note, pane, push, rule, source, table
from ..study import theta_for
from .base import Feature, FeatureView

WP_MAX_STEPS = 1 << 17
WP_BUDGET = 0.05
WP_RTOLS = tuple(10.0 ** -k for k in range(3, 13))
DRIFT_TOPS = (1e3, 1e4, 1e5, 1e6)
DRIFT_DEFAULT_STEPS = 1_000_000
MEASURE_BYTES = 96 * MB  # measured peak: work-precision 43 MB, long horizons 29 MB
HEIGHT = 340
MARKER_SIZE = 8  # points in the solver's family's marker (cosymp.report.style)
KEEP = 16  # measurements this server remembers (MEASURED)
WP_KEYS = {"error": "relative error at T", "H_ext_max_abs": "max |H~| over the run"}
DRIFT_KEYS = {"error": "relative error at T", "H_ext_max_abs": "max |H~| up to T"}
HOVER = [("solver", "@solver"), ("run", "@run"), ("steps", "@steps"), ("error at T", "@error_text"),
         ("wall time", "@wall_text"), ("max |H~|", "@H_text"), ("max |det M − 1|", "@det_text")]


def applicable(scene, names):
    """The names of the methods that apply to the scene (never the exact flow: it is the reference)."""
    return [m for m in applying(names, SCENES[scene]) if m != "exact"]


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


# This server's last work–precision measurements, for every page: {key(measured): (rows, when)}. A page
# opening the tab shows the one of its inputs at once instead of measuring for seconds; pages
# measuring at the same time also share the cores, and so each other's wall times.
MEASURED = {}


def key(measured):
    m = measured
    return (m.scene, tuple(sorted(m.values.items())), m.method_theta, tuple(m.solvers.items()), m.T, m.peers, m.h,
            m.horizons)


def solvers_of(scene, methods, values, theta):
    """{solver name as cosymp.workprecision names it: (method, θ or None)}, or InputError."""
    if not methods:
        raise InputError("no methods chosen: choose at least one method")
    out = {}
    for m in methods:
        s = Setup.make(scene, m, values, theta_for(m, theta))
        out[wp.solver_name(s)] = (m, s.theta)
    return out


class Measurement(Job):
    """A measurement of the study's scene, started by a button (see jobs.Job): its rows, and what
    they were measured on."""

    study = param.Parameter(doc="The sidebar's study.")
    rows = param.List(default=[], doc="The rows of the last completed measurement.")
    setting = param.String(default="", doc="What the rows were measured on.")
    methods = param.ListSelector(default=[], objects=list(METHODS), doc="cosymp's methods to measure.")

    DEFAULTS = ()

    def __init__(self, study, **params):
        super().__init__(study=study, **params)
        self.job = None
        self.param.methods.objects = applicable(study.scene, METHODS)
        if "methods" not in params:
            self.methods = applicable(study.scene, self.DEFAULTS)
        study.param.watch(self._on_scene, ["scene"])

    def _on_scene(self, event):
        self.drop()
        self.param.methods.objects = applicable(self.study.scene, METHODS)
        self.methods = applicable(self.study.scene, self.DEFAULTS)

    def drop(self):
        """Another scene: the measurement under way stops and the old scene's rows go."""
        self.discard()
        self.job = None
        self.param.update(rows=[], setting="")

    @property
    def PREFIX(self):
        return f"{self.KIND}: "

    def say(self, note_):
        self.study.say(note_)

    def _bytes(self, inputs):
        return MEASURE_BYTES

    def _started(self, inputs):
        self.status = f"running: {self._describe(inputs)}"

    def _finish(self, inputs, rows):
        self.job = inputs
        self.param.update(rows=rows, setting=self._describe(inputs))

    def since(self):
        """'' while the sidebar and this measurement's controls ask for the rows shown (or none are
        shown, or are being measured), else what they ask for now, or why a measurement of it is
        refused: a measurement starts on its Start button, not on every change of the sidebar."""
        if not self.rows or self.job is None:
            return ""
        try:
            inputs = self._inputs()
        except InputError as err:
            return f"they now ask for a measurement that is refused: {err}"
        if key(inputs) == key(self.job):
            return ""
        if self.running and (self.run is None or self.run.finished.is_set()):
            return ""  # asked for and not started yet (`running` is set first): the latest inputs run next
        if self.busy and key(inputs) == key(self.run.inputs):  # it is being measured: the status says so
            return ""
        start = f"cancel this one, then press {self.START}" if self.running else f"press {self.START}"
        return f"now {self._describe(inputs)}: {start} to measure it"


class WorkPrecision(Measurement):
    """Error at T against wall time for the chosen methods over step sizes (and scipy's
    solve_ivp over tolerances), on the study's scene, parameters and θ, to this measurement's own
    horizon T (the scene's paper horizon at first). A cosymp point can be opened in the Orbits
    view (`open_row`)."""

    peers = param.Boolean(default=True, label="with scipy's solve_ivp (RK45, DOP853, LSODA)",
                          doc="Also measure scipy's adaptive solvers over tolerances 1e-3 ... 1e-12.")
    T = param.Number(default=50.0, label="Horizon T", doc="The horizon every run is measured at.")
    KIND = "work–precision"
    START = "Start work–precision"
    DEFAULTS = wp.DEFAULT_METHODS

    def __init__(self, study, **params):
        params.setdefault("T", study.scene_obj.T)
        super().__init__(study, **params)

    def _on_scene(self, event):
        super()._on_scene(event)
        self.T = self.study.scene_obj.T

    def _inputs(self):
        s = self.study
        T = wp.check_horizon(self.T)
        first = math.ceil(T / s.scene_obj.time_scale)
        if first > WP_MAX_STEPS:
            raise InputError(f"T = {T:g} takes at least {first} steps per run at the scene's time scale, beyond "
                             f"this view's {WP_MAX_STEPS} steps per run: shorten T (the long horizons below go "
                             "further at one h)")
        return Measured(s.scene, dict(s.values), float(s.theta), solvers_of(s.scene, self.methods, s.values, s.theta),
                        T=T, peers=bool(self.peers))

    def _describe(self, job):
        peers = ", scipy's RK45, DOP853, LSODA" if job.peers else ""
        return f"{job.describe()}; {len(job.solvers)} methods{peers}"

    partial_interval = 0.3  # the rows so far are drawn at most this often while it measures

    def _compute(self, job, run):
        return wp.measure(job.scene, [m for m, _ in job.solvers.values()], job.values, job.T, theta=job.method_theta,
                          peers=job.peers, rtols=WP_RTOLS, max_steps=WP_MAX_STEPS, budget=WP_BUDGET,
                          progress=run.report, partial=run.publish)

    def _partial(self, job, rows):
        self.job = job
        self.param.update(rows=rows, setting=f"{self._describe(job)} (measuring)")

    def _cancelled(self, job, elapsed):
        super()._cancelled(job, elapsed)
        if self.job is job:  # rows of this measurement are shown
            self.setting = f"{self._describe(job)} (cancelled: the runs before it)"

    def _finish(self, job, rows):
        MEASURED.pop(key(job), None)
        MEASURED[key(job)] = (rows, datetime.datetime.now())
        while len(MEASURED) > KEEP:
            MEASURED.pop(next(iter(MEASURED)))
        super()._finish(job, rows)

    def recall(self):
        """Show this server's last measurement of the current inputs (made for any page), if there is
        one; True if shown."""
        try:
            job = self._inputs()
        except InputError:
            return False
        if key(job) not in MEASURED:
            return False
        rows, when = MEASURED[key(job)]
        self.job = job
        self.param.update(rows=rows, setting=self._describe(job),
                          status=f"measured at {when:%H:%M:%S} by this server; Start measures again")
        return True

    def open_row(self, row):
        """Open a cosymp run in the Orbits view: the measured scene and parameters, the run's
        method (and θ), its h and the measured T. A scipy run cannot be opened there: a note says so."""
        if row["kind"] != "cosymp":
            self.say(Note("info", f"{row['solver']} at rtol = {row['rtol']:.0e} is scipy's solve_ivp, which the "
                                  "main view does not run: click a point of a cosymp method to open it"))
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


class LongHorizons(Measurement):
    """Error and max |H~| at growing horizons (DRIFT_HORIZONS up to `T_max`), each chosen method
    at one step h, on the study's scene, parameters and θ. If the reference itself fails beyond
    some horizon (a scene whose state grows past floating point), the horizons below it are shown
    and a note says so."""

    h = param.Number(default=0.1, label="Step h", doc="The step of every method (default: the scene's).")
    capped = param.String(default="", doc="Why the rows shown stop before the largest horizon asked for ('' if "
                                          "they do not), said beside them.")
    T_max = param.Selector(default=1e4, objects={f"{T:.0e}": T for T in DRIFT_TOPS}, label="Largest horizon",
                           doc="The horizons are 1e2, 2e2, 5e2, 1e3, ... up to this one.")
    KIND = "long horizons"
    START = "Start long horizons"
    DEFAULTS = wp.DRIFT_METHODS

    def __init__(self, study, **params):
        super().__init__(study, **params)
        self.param.update({k: v for k, v in self._defaults().items() if k not in params})

    def _defaults(self):
        scene = self.study.scene_obj
        return {"methods": applicable(scene.name, wp.DRIFT_METHODS), "h": scene.h, "T_max": default_top(scene.h)}

    def _on_scene(self, event):
        self.drop()
        self.param.methods.objects = applicable(self.study.scene, METHODS)
        self.param.update(self._defaults())

    def drop(self):
        self.capped = ""
        super().drop()

    def _inputs(self):
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

    def _compute(self, job, run):
        return wp.drift(job.scene, [m for m, _ in job.solvers.values()], job.values, job.h, list(job.horizons),
                        theta=job.method_theta, progress=run.report)

    def _finish(self, job, rows):
        """The rows, and where the reference stopped short of the largest horizon, why and how to
        reach it, on the page beside them (a toast points there)."""
        short = [r for r in rows if r["status"].startswith(wp.REFERENCE_SHORT)]
        capped = ""
        if short:
            top = max((r["T"] for r in rows if not r["status"].startswith(wp.REFERENCE_SHORT)), default=0.0)
            why = short[0]["status"].split(": ", 1)[1]
            capped = (f"Shown up to T = {top:g}, not to the {job.horizons[-1]:g} asked for: {why}; or choose a "
                      "smaller largest horizon.")
            job = dataclasses.replace(job, horizons=tuple(T for T in job.horizons if T <= top * (1 + 1e-9)))
            self.say(Note("warning", f"long horizons shown up to T = {top:g} only: the reason is beside them"))
            rows = [r for r in rows if r not in short]
        self.capped = capped
        super()._finish(job, rows)


# ---------------------------------------------------------------- the view


def finite(x):
    return isinstance(x, (int, float)) and math.isfinite(x)


def _sci(x, unit=""):
    return f"{x:.3g}{unit}" if finite(x) else "–"


def run_text(row):
    """The step or the tolerance of a work-precision row."""
    return f"h = {row['h']:.4g}" if row["kind"] == "cosymp" else f"rtol = {row['rtol']:.0e}"


def wp_points(rows, key):
    """The rows drawn in the work-precision plot of `key` ('error' or 'H_ext_max_abs'): those with
    a finite wall time and a finite value, in row order (point i of the plot's points is row i)."""
    return [r for r in rows if finite(r["wall_s"]) and finite(r[key])]


class Curves:
    """Log-log curves, one per solver, in the solver's colour, scipy's dashed, with a legend beside
    the plot: the rows of one multi-line renderer built with the figure (a renderer added to a figure
    already on the page drew its line as a streak in the left margin; a pool of 24 line renderers per
    plot, used before, made the tab's four plots 0.7 s of the server's time to build), each legend
    item showing its row and its solver's marker: a point per row of a scatter renderer built with
    it, at no position, so that it draws nothing in the plot, and KEYS of them at least (BokehJS
    sets a scatter's new data asynchronously, and a legend that drew a new row before it was set
    read past the end of the old data: "Offset is outside the bounds of the DataView", when the
    long horizons were first shown)."""

    KEYS = len(METHOD_COLORS)  # more than the solvers of any plot

    def __init__(self, fig):
        self.fig = fig
        self.source = source()
        self.source.data = {"xs": [], "ys": [], "color": [], "dash": []}
        self.lines = fig.multi_line("xs", "ys", source=self.source, line_color="color", line_dash="dash",
                                    line_width=1.5)
        self.keys = source()
        self.keys.data = self._keys([])
        self.marks = fig.scatter("x", "y", source=self.keys, color="color", marker="marker", size=MARKER_SIZE)
        self.legend = legend_outside(fig, [])  # built with the figure: one added later has no view
        self.legend.items = self.items = [self._item(k) for k in range(self.KEYS)]

    def _keys(self, solvers):
        n = max(self.KEYS, len(solvers))
        return {"x": np.full(n, np.nan), "y": np.full(n, np.nan),
                "color": [method_color(s) for s in solvers] + [OTHER] * (n - len(solvers)),
                "marker": [method_marker(s) for s in solvers] + ["circle"] * (n - len(solvers))}

    def set(self, curves):
        """curves: {label: (x, y, dashed, solver)} drawn in the solver's colour; the legend lists
        them with the solver's marker."""
        rows = list(curves.values())
        self.source.data = {"xs": [np.asarray(x, float) for x, _, _, _ in rows],
                            "ys": [np.asarray(y, float) for _, y, _, _ in rows],
                            "color": [method_color(solver) for _, _, _, solver in rows],
                            "dash": ["dashed" if dashed else "solid" for _, _, dashed, _ in rows]}
        self.keys.data = self._keys([solver for _, _, _, solver in rows])
        if len(curves) > len(self.items):
            self.items += [self._item(k) for k in range(len(self.items), len(curves))]
            self.legend.items = list(self.items)
        labels = list(curves)
        for k, item in enumerate(self.items):
            item.update(label=value(labels[k] if k < len(labels) else ""), visible=k < len(labels))

    def _item(self, k):
        """The legend's row k, hidden until a curve k is drawn. The rows are kept and changed in
        place: legend items replaced at each update dropped models from the page, and Bokeh then
        walked all of its models (app/graph.py; 12 ms for a page's 2,900) at each row a measurement
        brought, 44 walks in one measurement."""
        return LegendItem(label="", renderers=[self.lines, self.marks], index=k, visible=False)


POINT_COLUMNS = ("x", "y", "solver", "run", "steps", "error_text", "wall_text", "H_text", "det_text", "color",
                 "marker")


class WorkPrecisionPlot:
    """key against wall time: a line per solver (its runs in order of refinement) and every point
    (hover: what the run was; a click on a cosymp point calls on_tap(row))."""

    def __init__(self, key, title, on_tap):
        self.key = key
        self.fig = figure(title, "wall time (s)", WP_KEYS[key], logx=True, logy=True, height=HEIGHT)
        self.curves = Curves(self.fig)
        self.points = source()
        # Every column the glyph and the hover read exists from the start (a missing one logged
        # "nonexistent field" warnings in the console before the first data).
        self.points.data = {k: [] for k in POINT_COLUMNS}
        dots = self.fig.scatter("x", "y", source=self.points, size=MARKER_SIZE, color="color", marker="marker",
                                nonselection_alpha=1.0)
        self.fig.add_tools(HoverTool(renderers=[dots], tooltips=HOVER), TapTool(renderers=[dots]))
        self.rows = []
        self.points.selected.on_change("indices", lambda attr, old, new: new and on_tap(self.rows[new[0]]))

    def set(self, rows):
        pts = wp_points(rows, self.key)
        self.rows = pts
        curves = {}
        for solver in dict.fromkeys(r["solver"] for r in pts):
            mine = [r for r in pts if r["solver"] == solver]
            curves[solver] = ([r["wall_s"] for r in mine], [max(r[self.key], FLOOR) for r in mine],
                              mine[0]["kind"] == "scipy", solver)
        self.curves.set(curves)
        self.points.selected.indices = []
        self.points.data = {
            "x": np.array([r["wall_s"] for r in pts]), "y": np.array([max(r[self.key], FLOOR) for r in pts]),
            "solver": [r["solver"] for r in pts], "run": [run_text(r) for r in pts],
            "steps": [str(r["steps"]) for r in pts], "error_text": [_sci(r["error"]) for r in pts],
            "wall_text": [_sci(r["wall_s"], " s") for r in pts], "H_text": [_sci(r["H_ext_max_abs"]) for r in pts],
            "det_text": [_sci(r["det_max_dev"]) for r in pts], "color": [method_color(r["solver"]) for r in pts],
            "marker": [method_marker(r["solver"]) for r in pts]}


class DriftPlot:
    """key against the horizon T, one line with markers per method (its fitted growth exponent in
    the legend), and the slopes T¹ and T² through the first horizon's geometric mean, up to ten
    times the largest value."""

    def __init__(self, key, title):
        self.key = key
        self.fig = figure(title, "horizon T", DRIFT_KEYS[key], logx=True, logy=True, height=HEIGHT)
        self.curves = Curves(self.fig)
        self.dots = source()
        self.dots.data = {"x": [], "y": [], "color": [], "marker": []}
        self.fig.scatter("x", "y", source=self.dots, size=MARKER_SIZE, color="color", marker="marker")
        self.guides = {p: source() for p in (1, 2)}
        for p, src in self.guides.items():
            self.fig.line("x", "y", source=src, line_color="#868e96", line_width=2,
                          line_dash="dotted" if p == 1 else "dotdash")

    def set(self, rows):
        key = self.key
        pts = [r for r in rows if finite(r[key]) and r[key] > 0]
        curves = {}
        for solver in dict.fromkeys(r["solver"] for r in rows):
            mine = [r for r in pts if r["solver"] == solver]
            text = wp.growth_text(rows, solver, key)
            curves[f"{solver}: " + ("at round-off" if text == "round-off" else f"slope {text}")] = (
                [r["T"] for r in mine], [r[key] for r in mine], False, solver)
        self.curves.set(curves)
        self.dots.data = {"x": np.array([r["T"] for r in pts]), "y": np.array([r[key] for r in pts]),
                          "color": [method_color(r["solver"]) for r in pts],
                          "marker": [method_marker(r["solver"]) for r in pts]}
        guides = {1: ([], []), 2: ([], [])}
        if pts:
            T0 = min(r["T"] for r in pts)
            T1 = max(r["T"] for r in pts)
            y0 = math.exp(np.mean([math.log(r[key]) for r in pts if r["T"] == T0]))
            top = 10 * max(r[key] for r in pts)
            for power in (1, 2):
                end = min(T1, T0 * (top / y0) ** (1 / power))
                guides[power] = ([T0, end], [y0, y0 * (end / T0) ** power])
        for p, (x, y) in guides.items():
            self.guides[p].data = {"x": np.asarray(x, float), "y": np.asarray(y, float)}


def failed_html(rows, setting=run_text):
    """The runs that failed (not plotted), with their messages (a message repeated by a solver's
    later rows, as a drift's after its run stopped, once at its first row)."""
    bad = list({(r["solver"], r["status"]): r for r in reversed(rows) if r["status"] != "ok"}.values())[::-1]
    if not bad:
        return ""
    items = "".join(f"<li><b>{html.escape(r['solver'])}</b> {html.escape(setting(r))}: {html.escape(r['status'])}"
                    "</li>" for r in bad[:8])
    more = f"<li>… and {len(bad) - 8} more</li>" if len(bad) > 8 else ""
    return (f"<p class='caveat'>{len(bad)} run{'s' if len(bad) > 1 else ''} failed (not plotted):</p>"
            f"<ul class='notes'>{items}{more}</ul>")


TARGETS_TEXT = ("<p class='doc'>Time to reach an error: the wall time at which a solver's curve crosses it "
                "(interpolated log–log between its cheapest run below the error and the run before it); – where "
                "it does not get there in this measurement, or not yet while its runs come: cosymp's methods refine "
                f"h up to {WP_MAX_STEPS:,} steps, scipy's solvers down to rtol {min(WP_RTOLS):.0e} (a second-order "
                "method can stop just short of 1e-6 there). The ratios compare the costs at the same error: "
                "scipy's DOP853 over cosymp's fastest method (above 1: cosymp is faster), and cosymp's fastest "
                "symplectic method over its RK4 (below 1: structure preservation costs nothing here).</p>")
GROWTH_TEXT = ("<p class='doc'>Growth exponent: the slope of log(error) against log(T), fitted over the horizons "
               "before the error first reaches 0.1 (where it saturates at the orbit's size) and where it is above "
               "ten times the reference's uncertainty, and the slope of log(max |H~|); 1 is linear growth, 2 "
               "quadratic, 0 bounded; – with fewer than three usable horizons; <b>round-off</b> where every value "
               f"fitted is at round-off level: max |H~| within {wp.ROUNDOFF:g} ε |H| √N after N steps (the rounding of "
               f"N steps adds up to about ε |H| √N; ε = 2.2e-16), the relative error within {wp.ROUNDOFF:g} ε √N. "
               "The slope of such values measures the rounding, not the method. Grey: the slopes T and T² for "
               "comparison.</p>")
WP_TEXT = ("<p>What each method costs for the accuracy it delivers, on the sidebar's scene, parameters and θ, to "
           "the horizon T set here (the scene's paper horizon at first): "
           "each of cosymp's methods over step sizes (refined by √2 until the error stops improving or a run "
           "reaches {steps} steps), and scipy's adaptive <code>solve_ivp</code> over tolerances 1e-3 … 1e-12 on "
           "the same extended ODE. Wall time: the best of repeated runs after an untimed warm-up (so no "
           "compilation), timed in this server beside its other work (other pages, a long run): a busy server "
           "can bend a curve back (scipy's loosest tolerances, 1.5 ms alone, read 50 ms beside a long run); "
           "<code>cosymp workprecision</code> times in a process of its own. Top, the relative error at T against the exact flow, or else a DOP853 run tighter than "
           "any peer's; below, the largest |H~| = |H + p_t| over the run. <b>Click a point</b> of one of cosymp's "
           "methods to open that method and step in the Orbits view.</p>")
LONG_TEXT = ("<h4>Long horizons</h4><p>Each method at one step h, carried from T = 100 to the largest horizon: the "
             "error at each horizon and the largest |H~| so far. Where the error grows linearly (slope 1) the "
             "method errs mostly in phase; quadratic growth (slope 2) is the drift that structure preservation "
             "is meant to prevent.</p>")


def reference_html(rows):
    """The reference the errors are measured against, and its largest uncertainty."""
    if not rows:
        return ""
    unc = max((r["reference_uncertainty"] for r in rows if finite(r["reference_uncertainty"])), default=0.0)
    return (f"<p class='doc'>Reference: {html.escape(str(rows[0]['reference']))}"
            + (f" (relative uncertainty up to {unc:.1e}: errors at most as large are not resolved)" if unc > 0 else "")
            + ".</p>")


def targets_table(rows):
    """Time to reach 1e-6 and 1e-9 per solver, and the two ratios (cosymp.workprecision.targets)."""
    if not rows:
        return {"time to reach": []}
    t = wp.targets(rows)
    errors = list(t["cost"])
    cols = {"time to reach": list(t["cost"][errors[0]])}
    for e in errors:
        cols[f"error {e:.0e}"] = [f"{c:.2e} s" if finite(c) else "–" for c in t["cost"][e].values()]
    ratios = t["ratios"]
    for label, ratio, who in (("scipy DOP853 / fastest cosymp", "dop853_over_fastest", "fastest"),
                              ("best symplectic / rk4", "symplectic_over_rk4", "best_symplectic")):
        cols["time to reach"].append(label)
        for e in errors:
            r, name = ratios[e][ratio], ratios[e][who]
            cols[f"error {e:.0e}"].append((f"{r:.3g}×" if finite(r) else "–") + (f" ({name})" if name else ""))
    return cols


def growth_table(rows):
    """The fitted growth exponents of the error and of max |H~| per method."""
    cols = {"method": [], "order": [], "preserves": [], "error ∝ T^": [], "max |H~| ∝ T^": []}
    for s in dict.fromkeys(r["solver"] for r in rows):
        first = next(r for r in rows if r["solver"] == s)
        for k, v in zip(cols, (s, str(first["order"]), str(first["preserves"]),
                               *[wp.growth_text(rows, s, key) for key in DRIFT_KEYS])):
            cols[k].append(v)
    return cols


def run_controls(job, start_label, before_start=None):
    """Start and Cancel buttons, a progress bar, the current run's label and the status line;
    before_start() is called in the Start button's handler, before the job starts."""
    start = pn.widgets.Button(name=start_label, button_type="primary", disabled=job.param.running)

    def started(event):
        if before_start is not None:
            before_start()
        job.start()

    start.on_click(started)
    cancel = pn.widgets.Button(name="Cancel", button_type="danger", disabled=pn.bind(lambda r: not r, job.param.running))
    cancel.on_click(lambda event: job.cancel())
    progress = pn.indicators.Progress(value=pn.bind(lambda p: round(100 * p), job.param.progress), max=100, width=220,
                                      bar_color="primary", margin=(22, 10, 10, 10))
    label = pn.bind(lambda running, text: f"<p class='doc wplabel'>{html.escape(text)}</p>" if running else "",
                    job.param.running, job.param.label)
    status = pn.bind(lambda st, setting: (f"<p class='doc'><b class='wpstatus'>{html.escape(st)}</b>"
                                          + (f"<br>Shown: {html.escape(setting)}" if setting else "") + "</p>"),
                     job.param.status, job.param.setting)
    return (pn.Row(start, cancel, progress, note(label, width=320, sizing_mode=None, margin=(18, 5)),
                   sizing_mode="stretch_width"),
            note(status))


class WorkPrecisionView(FeatureView):
    NAME = "workprecision"

    def layout(self):
        m, lh = self.state.measure, self.state.long
        wide = {"sizing_mode": "stretch_width"}
        choices = [self.widget(pn.widgets.MultiChoice, job, "methods", sizing_mode="stretch_width") for job in (m, lh)]
        wp_row, wp_status = run_controls(m, m.START)
        long_row, long_status = run_controls(lh, lh.START, self._long_figures)
        self.since = {job: note("") for job in (m, lh)}
        for job, names in ((m, ["rows", "running", "methods", "T", "peers"]),
                           (lh, ["rows", "running", "methods", "h", "T_max"])):
            job.param.watch(self._say_since, names)
        self.study.param.watch(self._say_since, ["theta", "values"])
        self.wp_plots = [WorkPrecisionPlot(key, title, m.open_row) for key, title in
                         (("error", "relative error at T against wall time"),
                          ("H_ext_max_abs", "max |H~| = max |H + p_t| against wall time"))]
        self.drift_plots = None  # built with the first long horizons (`_long_figures`): most visits run none
        self.wp_hint = note("<p class='doc'>Nothing measured yet: press Start.</p>")
        self.wp_failed, self.long_failed, self.long_capped = note(""), note(""), note("")
        self.wp_reference, self.long_reference = note(""), note("")
        self.targets = table(["time to reach"])
        self.wp_box = pn.Column(*[pane(p.fig) for p in self.wp_plots], self.wp_reference, note(TARGETS_TEXT),
                                self.targets, visible=False, **wide)
        self.long_box = pn.Column(visible=False, **wide)
        self.follow(m, "rows", "running")
        self.follow(lh, "rows", "capped")
        return pn.Column(
            note(WP_TEXT.format(steps=f"{WP_MAX_STEPS:,}")),
            pn.Row(choices[0], self.widget(pn.widgets.FloatInput, m, "T", description=m.param.T.doc, width=140),
                   **wide),
            pn.widgets.Checkbox.from_param(m.param.peers),
            wp_row, wp_status, self.since[m], self.wp_failed, self.wp_hint, self.wp_box,
            rule(),
            note(LONG_TEXT),
            pn.Row(choices[1],
                   self.widget(pn.widgets.FloatInput, lh, "h", description=lh.param.h.doc, format="0.[000000]",
                               width=140),
                   pn.widgets.Select.from_param(lh.param.T_max, width=140), **wide),
            long_row, long_status, self.since[lh], self.long_capped, self.long_failed, self.long_box,
            **wide)

    def wanted(self):
        m = self.state.measure
        if not m.rows and not m.busy and not m.recall():
            m.request()

    def ahead(self):
        """Built ahead with this server's measurement of the same inputs drawn, when it made one (a
        class opening the tab); a new measurement waits for the tab (seconds of both cores)."""
        m = self.state.measure
        return [lambda: m.rows or m.busy or m.recall(), self._draw_stale]

    def shown(self):
        super().shown()
        self._say_since()

    def _say_since(self, *events):
        """Say, while the tab is shown, when the rows shown are not what the sidebar and the
        measurement's controls now ask for (as the Long run and the Stability map do); a hidden
        tab's text follows when it is shown."""
        if not (self.built and self.visible):
            return
        for job, pane_ in self.since.items():
            ask = job.since()
            text = "" if not ask else (f"<p class='doc since'><b>Computed before the latest changes</b>: "
                                       f"{html.escape(ask)}.</p>")
            if text != pane_.object:
                push(partial(setattr, pane_, "object", text))

    def update(self):
        m, lh = self.state.measure, self.state.long
        self.wp_hint.visible = not m.rows and not m.running
        self.wp_box.visible = bool(m.rows)
        self.long_box.visible = bool(lh.rows)
        self.wp_failed.object = failed_html(m.rows)
        self.long_failed.object = failed_html(lh.rows, lambda r: f"T = {r['T']:g}")
        self.long_capped.object = f"<p class='caveat'>{html.escape(lh.capped)}</p>" if lh.capped else ""
        if m.rows:
            for p in self.wp_plots:
                p.set(m.rows)
            self.wp_reference.object = reference_html(m.rows)
            self.targets.object = pd.DataFrame(targets_table(m.rows))
        if lh.rows:
            self._long_figures()
            for p in self.drift_plots:
                p.set(lh.rows)
            self.long_reference.object = reference_html(lh.rows)
            self.growth.object = pd.DataFrame(growth_table(lh.rows))

    def _long_figures(self):
        """The long horizons' figures and table, built once, when long horizons are first started: a
        tab built with them held 2 more figures and a table (of its 4 and 2) that a first visit sent
        and laid out. Built in the Start button's handler, not when the rows come: built from the
        measurement's end on the loop, their stylesheets were linked from Panel's CDN."""
        if self.drift_plots is not None:
            return
        self.drift_plots = [DriftPlot(key, title) for key, title in
                            (("error", "relative error at T, at fixed h"), ("H_ext_max_abs", "max |H~| up to T, at fixed h"))]
        self.growth = table(["method"])
        self.long_box.objects = [*[pane(p.fig) for p in self.drift_plots], self.long_reference, note(GROWTH_TEXT),
                                 self.growth]


class Measurements:
    """The tab's two measurements: work against precision, and long horizons."""

    def __init__(self, study):
        self.measure = WorkPrecision(study)
        self.long = LongHorizons(study)
        self.jobs = (self.measure, self.long)

    def release(self):
        for job in self.jobs:
            job.release()


FEATURE = Feature("workprecision", "Work–precision", WorkPrecisionView, Measurements)
