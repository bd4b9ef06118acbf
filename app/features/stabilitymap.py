"""Stability map: one measure of the sidebar's method over two varied quantities (scene parameters,
h, T or θ), computed by cosymp.sweep in the background with progress and Cancel (on a Dask cluster
when COSYMP_DASK_SCHEDULER names its scheduler), drawn as a heat map (failed runs black); a click
on a cell opens that run in Orbits."""
import html
import os
import shlex

import numpy as np
import panel as pn
import param
from bokeh.events import Tap
from bokeh.models import (
    ColorBar,
    ColumnDataSource,
    CustomJS,
    HoverTool,
    LogColorMapper,
    TapTool,
)
from bokeh.palettes import Viridis256
from bokeh.transform import transform

from cosymp import sweep
from cosymp.errors import InputError
from cosymp.methods import METHODS
from cosymp.scenes import SCENES

from ..jobs import Job
from ..plotting import FLOOR, figure, log_formatter, log_ticker, note, pane
from ..study import soft_range, theta_for
from .base import Feature, FeatureView
from .workprecision import run_controls

MAP_MAX_SIDE = 100
# The address of a running Dask scheduler (tcp://host:8786): maps are computed on that cluster,
# whose workers need cosymp installed; unset, in this process on a thread pool.
SCHEDULER_ENV = "COSYMP_DASK_SCHEDULER"
MAP_MAX_STEPS = 200_000_000
LOG_MEASURES = ("H_ext_max_abs", "det_max_dev", "error_final")
# What the page calls each measure (the command line's names are in the map's text)
MEASURE_TITLES = {"growth": "growth, ln σmax / T", "H_ext_max_abs": "max |H + p_t|",
                  "det_max_dev": "max |det M − 1|", "error_final": "relative error at T"}
HEIGHT = 480
SIGNIFICANT = 4  # a cell opened in Orbits carries its values to this many significant digits
UNIFORM = 2.0  # a map whose values lie within this factor is said to be nearly one colour (uniform_text)


def map_axes(scene, unused=()):
    """The Stability map's first axes for a scene, (name, start, stop, log) for x and y: those it
    declares (Scene.map_axes), else h on a log axis around the scene's step by its first parameter
    that is not an initial condition, over its slider range. Never a parameter the other values
    leave without effect (`unused`: charged's ε and ω with a constant β(t), which mapped to one colour
    over axes the sidebar greys out)."""
    if scene.map_axes is not None and not {axis[0] for axis in scene.map_axes} & set(unused):
        return scene.map_axes
    p = next(p for p in scene.params if not p.initial and not p.choices and not isinstance(p.default, str)
             and p.name not in unused)
    return ("h", scene.h / 4, 8 * scene.h, True), (p.name, *soft_range(p), False)


def first_measure(scene):
    """What a scene's first map shows: the measure it declares (Scene.map_measure), growth unless
    growth says nothing (the damped oscillator grows at γ/2 with every method: max |H + p_t| shows
    the methods apart, its error at T is noise from cell to cell; every structure-preserving
    method's growth on the decaying one is 0 to round-off: their errors show them apart)."""
    return scene.map_measure


def map_bytes(points):
    """What a sweep holds at once: the grid's results (its measures and a status per point) and
    its threads' working arrays (the fused driver keeps nothing per step). Measured with
    tracemalloc: 50 kB for 4 points, 0.18 MB for 400, 0.62 MB for 2,500."""
    return points * 512 + (1 << 20)


def significant(x):
    return float(f"{x:.{SIGNIFICANT}g}")


def run_values(plan):
    """{name: value} of h, T and θ (where the method takes it) as every cell of a plan runs them,
    less the varied ones (a varied name's plan value is the scene's default, which no cell uses)."""
    varied = {a.name for a in plan.axes}
    run = {"h": plan.h, "T": plan.T, "theta": plan.theta}
    return {k: v for k, v in run.items() if v is not None and k not in varied}


def shared_values(plan):
    """{name: value} of everything every cell of a plan runs with but its varied names: h, T, θ
    (`run_values`) and each of the scene's parameters (its default unless the plan sets it)."""
    varied = {a.name for a in plan.axes}
    scene = SCENES[plan.scene].values(dict(plan.values))
    return {**run_values(plan), **{k: v for k, v in scene.items() if k not in varied}}


def value_text(v):
    return f"{v:g}" if isinstance(v, float) else str(v)


class StabilityMap(Job):
    """A measure of the study's method over a grid of two varied names (scene parameters, h, T or θ)
    with the study's other values, computed by cosymp.sweep on this machine's cores in the
    computation's thread. A cell can be opened in the Orbits view (`open_cell`)."""

    study = param.Parameter(doc="The sidebar's study.")
    measure = param.Selector(default="growth", objects={MEASURE_TITLES[k]: k for k in sweep.MEASURES},
                             doc="What each cell shows.")
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
    setting = param.String(default="", doc="What the map was computed on.")

    KIND = "stability map"
    WHAT = "this map"
    PREFIX = "stability map: "
    KEEP = 16  # a map's result: its measure and status per cell (tens of kB)

    def _key(self, plan):
        return plan

    def __init__(self, study, **params):
        super().__init__(study=study, **params)
        self.job = None
        self._on_scene()
        study.param.watch(self._on_scene, ["scene", "method"])
        study.param.watch(self._on_values, ["values"])

    def say(self, note_):
        self.study.say(note_)

    def _on_scene(self, *events):
        """The axes of the study's scene and method; after a change of either, the map under way
        stops and the old map goes (the view computes the new one when its tab is shown: `wanted`)."""
        if events:
            self.discard()
            self.job = None
            self.param.update(result=None, setting="")
        names = self._names()
        if events and all(e.name == "method" for e in events) and {self.x, self.y} <= set(names):
            return
        self._first_axes()
        self.param.update(measure=first_measure(self.study.scene_obj))

    def _unused(self):
        vals = self.study.checked_values()
        return self.study.scene_obj.unused(vals) if vals is not None else ()

    def _names(self):
        """The names an axis may vary: the method's and scene's, less those without effect. Given to the
        axis menus only when they change: each assignment is a message to a page showing the map, and
        this runs on every value change (a slider's drag)."""
        unused = self._unused()
        names = [n for n in sweep.variables(self.study.scene_obj, METHODS[self.study.method]) if n not in unused]
        if names != self.param.x.objects:
            self.param.x.objects = self.param.y.objects = names
        return names

    def _first_axes(self):
        (xn, x0, x1, xl), (yn, y0, y1, yl) = map_axes(self.study.scene_obj, self._unused())
        self.param.update(x=xn, x_start=x0, x_stop=x1, x_log=xl, y=yn, y_start=y0, y_stop=y1, y_log=yl)

    def _on_values(self, event):
        """A value that leaves an axis without effect (β(t) made constant under an ε axis) gives the
        scene's first axes among those that act; the map shown then goes, as after a scene change."""
        if {self.x, self.y} <= set(self._names()):
            return
        self.discard()
        self.job = None
        self.param.update(result=None, setting="")
        self._first_axes()

    def _inputs(self):
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

    def planned(self):
        """The plan of the map the controls ask for, or None if they ask for none."""
        try:
            return self._inputs()
        except InputError:
            return None

    def _bytes(self, plan):
        return map_bytes(plan.size)

    def _describe(self, plan):
        (ax, ay) = plan.axes
        shared = ", ".join(f"{k} = {value_text(v)}" for k, v in shared_values(plan).items())
        return (f"{MEASURE_TITLES[plan.measures[0]]} of {plan.method} on {plan.scene}: {ax.name} {ax.values[0]:g}…{ax.values[-1]:g} "
                f"× {ay.name} {ay.values[0]:g}…{ay.values[-1]:g}, {plan.size} cells, each with {shared}")

    def _started(self, plan):
        self.status = f"running: {self._describe(plan)}"

    def _compute(self, plan, run):
        return sweep.run(plan, scheduler=os.environ.get(SCHEDULER_ENV) or None, progress=run.report)

    def _finish(self, plan, result):
        self.job = plan
        self.param.update(result=result, setting=self._describe(plan))

    def release(self):
        """The page is gone: drop the map without redrawing it."""
        super().release()
        with param.parameterized.discard_events(self):
            self.result = None

    def open_cell(self, i, j):
        """Open cell (i along x, j along y) of the last map in the Orbits view: the map's scene,
        method and values with that cell's varied values (to SIGNIFICANT digits)."""
        plan = self.job
        point = {plan.axes[0].name: significant(plan.axes[0].values[i]),
                 plan.axes[1].name: significant(plan.axes[1].values[j])}
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


def map_command(plan):
    """The `cosymp sweep` command line of a plan, as a POSIX shell reads it (a beta(t) expression is
    quoted)."""
    fixed = "".join(f" --set {shlex.quote(f'{k}={v}')}" for k, v in plan.values)
    vary = "".join(f" --vary {a.name}={a.values[0]:g}:{a.values[-1]:g}:{len(a.values)}" + (":log" if a.log else "")
                   for a in plan.axes)
    run = "".join(f" --{k} {v:g}" for k, v in run_values(plan).items())
    return (f"cosymp sweep {plan.scene} --method {plan.method}{vary} --measure {' '.join(plan.measures)}"
            f"{run}{fixed} -o map.csv")


def edges(values, log):
    """Cell edges around the grid's values (geometric midpoints on a log axis)."""
    v = np.log(values) if log else np.asarray(values, float)
    if len(v) == 1:
        e = v[0] + np.array([-0.5, 0.5]) * (0.2 if log else max(abs(v[0]), 1.0))
    else:
        mid = 0.5 * (v[1:] + v[:-1])
        e = np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])
    return np.exp(e) if log else e


CELL_FIELDS = ("left", "right", "bottom", "top", "z", "i", "j", "x", "y")


def cells(result):
    """The quads of a sweep's single measure (x fastest within each y row is not assumed: C order
    of the grid, x the first axis): their edges, values and grid indices."""
    plan = result.plan
    ax, ay = plan.axes
    key = plan.measures[0]
    Z = result.values[key]
    xe, ye = edges(ax.values, ax.log), edges(ay.values, ay.log)
    i, j = np.meshgrid(np.arange(len(ax.values)), np.arange(len(ay.values)), indexing="ij")
    i, j = i.ravel(), j.ravel()
    z = Z.ravel()
    if key in LOG_MEASURES:
        z = np.where(np.isnan(z), np.nan, np.maximum(z, FLOOR))
    return {"left": xe[i], "right": xe[i + 1], "bottom": ye[j], "top": ye[j + 1], "z": z, "i": i, "j": j,
            "x": np.asarray(ax.values)[i], "y": np.asarray(ay.values)[j]}


def colour_range(plan, z):
    """(low, high) of a map's log colour scale for its finite values z, or None if it has none.

    growth from 1/T (of the grid's longest run): ln σ_max = 1, one e-fold of the product of the
    one-step maps over the run. A bounded map's growth is the logarithm of its oscillation's stretch
    over T (a few e-folds at most; round-off where every map is a rotation), a contraction's is
    negative, an instability's is many e-folds: at or below one, the lowest colour, and the colours
    above count e-folds on a log scale. On a linear scale from the smallest to the largest value,
    Kapitza's map was one colour but for its top rows (the upper instability of the inverted
    position, growth up to 12 against 0.15-0.7 where the pendulum falls and 0.01-0.2 where it stays
    up), and noise of 1e-16 was drawn as structure where every cell was round-off. The other
    measures, deviations over decades: their smallest to largest value."""
    if not len(z):
        return None
    if plan.measures[0] == "growth":
        low = 1.0 / max(next((a.values for a in plan.axes if a.name == "T"), (plan.T,)))
    else:
        low = float(z.min())
    high = float(z.max())
    return low, high if high > low else 10.0 * low


# BokehJS 3's HoverToolView._move_exit, once the tap has been handled: the tooltip hidden and the
# mouse's last position forgotten, as when the mouse leaves the plot (`_clear` alone hides it, but the
# plot's next repaint, its tab shown again, inspects that position anew)
CLEAR_TOOLTIP = """setTimeout(() => {
  const view = Bokeh.index.find_one(hover);
  if (view != null && typeof view._move_exit === "function") view._move_exit();
}, 0);"""


def tooltips(x, y, value):
    """A cell's hover lines, named as the map's axes and measure."""
    return [(x, "@x{0.[0000]}"), (y, "@y{0.[0000]}"), (value, "@z")]


class MapPlot:
    """The heat map for one pair of axis kinds (linear or log): quads coloured by the measure on a
    log scale (`colour_range`), a colour bar, hover, and a click that calls on_tap(i, j)."""

    def __init__(self, logx, logy, on_tap):
        self.fig = figure("", "x", "y", logx=logx, logy=logy, height=HEIGHT)
        # Every column and a colour range from the start: a map built ahead of its data, empty, made
        # BokehJS warn of nonexistent fields and of a colour range of -Infinity.
        self.source = ColumnDataSource({k: np.empty(0) for k in CELL_FIELDS})
        self.mapper = LogColorMapper(palette=Viridis256, nan_color="black", low=1.0, high=10.0)
        quads = self.fig.quad(left="left", right="right", bottom="bottom", top="top", source=self.source,
                              fill_color=transform("z", self.mapper), line_color=transform("z", self.mapper),
                              line_width=0.6, nonselection_fill_alpha=1.0, nonselection_line_alpha=1.0)
        # Edges in the cell's own colour: without them anti-aliasing drew white hairlines between cells.
        self.bar = ColorBar(color_mapper=self.mapper, width=12, title_standoff=6,
                            ticker=log_ticker(), formatter=log_formatter())
        self.fig.add_layout(self.bar, "right")
        self.hover = HoverTool(renderers=[quads], tooltips=tooltips("x", "y", "value"))
        self.fig.add_tools(self.hover, TapTool(renderers=[quads]))
        # A click opens the Orbits tab: the cell's tooltip stayed on the map, and was there on coming back.
        self.fig.js_on_event(Tap, CustomJS(args={"hover": self.hover}, code=CLEAR_TOOLTIP))
        self.source.selected.on_change("indices", lambda attr, old, new: new and on_tap(
            int(self.source.data["i"][new[0]]), int(self.source.data["j"][new[0]])))
        self.pane = pane(self.fig, min_height=HEIGHT + 10)
        # Shown and hidden as a whole (a Bokeh pane's own `visible` follows its figure's)
        self.box = pn.Column(self.pane, visible=False, sizing_mode="stretch_width")

    def set(self, result):
        plan = result.plan
        ax, ay = plan.axes
        key = plan.measures[0]
        data = cells(result)
        z = data["z"][np.isfinite(data["z"])]
        scale = colour_range(plan, z)
        if scale is not None:
            self.mapper.update(low=scale[0], high=scale[1])
        below = key == "growth" and scale is not None and z.max() <= scale[0]
        self.source.selected.indices = []
        self.source.data = data
        self.fig.title.text = f"{MEASURE_TITLES[key]} of {plan.method} on {plan.scene}" + (
            f": at most one e-fold over T in every cell (growth ≤ 1/T = {scale[0]:g})" if below else "")
        self.fig.xaxis.axis_label, self.fig.yaxis.axis_label = ax.name, ay.name
        self.hover.tooltips = tooltips(ax.name, ay.name, MEASURE_TITLES[key])
        self.bar.title = "growth (≤ 1/T: lowest colour)" if key == "growth" else MEASURE_TITLES[key]


MAP_TEXT = ("<p>One measure of the sidebar's method over a grid of two varied quantities (scene parameters, h, T "
            "or θ), every other value taken from the sidebar. Each cell is one run from the scene's initial "
            "state (the command line names the measures growth, H_ext_max_abs, det_max_dev and error_final): "
            "<b>growth</b> is ln σ<sub>max</sub> of the product of the method's one-step maps, over T (a "
            "finite-time Lyapunov exponent of the method: 0 where its map stays bounded, the Floquet exponent "
            "inside a parametric-resonance tongue, ln|R(ih)|/h for RK4 beyond its stability limit); "
            "<b>max |H + p_t|</b> the largest |H~| = |H + p_t| over the run; <b>max |det M − 1|</b> the largest "
            "|det M<sub>k</sub> − 1| of the one-step maps; <b>relative error at T</b> the error at T relative to the "
            "exact flow or a fine RK8 run. Colours are on a log scale: growth's from 1/T, one e-fold of "
            "σ<sub>max</sub> over the run (at or below it, the lowest colour), the others' from their smallest "
            "value. Black cells: the run failed, or its error at T has no reference (the line below the map says why). The same grid runs "
            "from the command line, also on a Dask cluster: <code>{command}</code>. "
            "<b>Click a cell</b> to open that run in the Orbits view.</p>")


def since_text(shown, asked):
    """What the shown map (its plan) was not computed with that the sidebar and the map's controls
    now ask for (`asked`, None if they ask for no map): '' when they ask for the shown map. The map
    is computed on Compute map (or a first visit), not on every change of the sidebar."""
    if shown is None or asked is None:
        return ""
    old, new = shared_values(shown), shared_values(asked)
    if (shown.axes, shown.measures, old) == (asked.axes, asked.measures, new):
        return ""
    changed = ", ".join(f"{k} = {value_text(v)}" for k, v in new.items() if old.get(k) != v)
    return (f"<p class='doc since'><b>Computed before the latest changes</b> "
            f"({'now ' + html.escape(changed) if changed else 'of its axes or measure'}): press Compute map "
            "to compute it with them.</p>")


def uniform_text(result):
    """A sentence where every finite value of the map lies within a factor UNIFORM of the others
    (positive values): one colour, which shows nothing. At the charged scene's paper values (B0 0.05,
    T 20) the w x eps map's growth is 0.15-0.2 in every cell, where its first view (B0 1, T 300)
    shows the tongues."""
    if result is None:
        return ""
    z = result.values[result.plan.measures[0]]
    z = z[np.isfinite(z)]
    if len(z) < 2 or not 0 < z.min() or z.max() > UNIFORM * z.min():
        return ""
    return (f"<p class='doc'><b>Nearly one colour:</b> the measure ({MEASURE_TITLES[result.plan.measures[0]]}) lies "
            f"between {z.min():.3g} and {z.max():.3g} in every cell, so nothing stands out on this grid at these fixed "
            "values and horizon. Slow instabilities show over a longer T, or with other fixed values: the Scene "
            "menu's first view of each scene sets values where its map has structure.</p>")


def map_failures(result):
    if result is None:
        return ""
    (failed, first), (unmeasured, why) = result.failures()
    if not failed and not unmeasured:
        return (f"<p class='doc'>Every one of the {result.plan.size} runs completed ({html.escape(result.where)}, "
                f"{result.wall_s:.1f} s).</p>")
    return ("<p class='doc'>"
            + (f"<b>{failed} of {result.plan.size} runs failed</b> (black cells), e.g.: {html.escape(first)} "
               if failed else "")
            + (f"<b>{unmeasured} of {result.plan.size} runs have no error</b> (black cells; the runs completed): "
               f"their reference failed, e.g.: {html.escape(why)}" if unmeasured else "")
            + "</p>")


class StabilityMapView(FeatureView):
    NAME = "map"

    def layout(self):
        m = self.state
        row, status = run_controls(m, "Compute map")
        # The map's figure is built with the tab, for the axis kinds it opens with, and shown when a map
        # comes: built with the first map, it was sent and laid out at the visit (0.25 s of a recalled
        # map's 0.27 s).
        self.hint = note("<p class='doc'>No map yet: choose the axes and press Compute map.</p>")
        kind = (m.x_log, m.y_log)
        self.plots = {kind: MapPlot(*kind, m.open_cell)}
        self.box = pn.Column(self.hint, self.plots[kind].box, sizing_mode="stretch_width")
        self.text = note("")
        self.failures = note("")
        self.since = note("")
        self._drawn = None
        self.follow(m, "result", "running", "measure", *(f"{a}{k}" for a in "xy" for k in ("", "_start", "_stop", "_log")),
                    "nx", "ny")
        self.follow(self.study, "h", "T", "theta", "values")

        def axis(prefix):
            return pn.Row(self.widget(pn.widgets.Select, m, prefix, width=120),
                          self.widget(pn.widgets.FloatInput, m, f"{prefix}_start", width=110),
                          self.widget(pn.widgets.FloatInput, m, f"{prefix}_stop", width=110),
                          self.widget(pn.widgets.IntInput, m, f"n{prefix}", width=100),
                          self.widget(pn.widgets.Checkbox, m, f"{prefix}_log", margin=(30, 10, 10, 10)))

        return pn.Column(self.text, self.widget(pn.widgets.Select, m, "measure", width=200), axis("x"), axis("y"),
                         row, status, self.since, self.box, self.failures, sizing_mode="stretch_width")

    def wanted(self):
        if self.state.result is None and not self.state.busy:
            self.state.request()

    def ahead(self):
        """Built ahead with this server's map of the same inputs drawn, when it computed one (a class
        opening the tab); a new map waits for the tab (both cores for up to seconds)."""
        m = self.state
        return [lambda: m.result is None and not m.busy and m.quick() and m.request(), self._draw_stale]

    def update(self):
        m = self.state
        result = m.result
        asked = m.planned()
        plan = result.plan if result else asked
        self.text.object = MAP_TEXT.format(command=html.escape(map_command(plan)) if plan else
                                           "cosymp sweep SCENE --vary NAME=START:STOP:NUM ...")
        self.failures.object = map_failures(result) + uniform_text(result)
        self.since.object = "" if m.running else since_text(result.plan if result else None, asked)
        plot = None
        if result is not None:
            ax, ay = result.plan.axes
            kind = (ax.log, ay.log)
            if kind not in self.plots:
                self.plots[kind] = MapPlot(*kind, m.open_cell)
                self.box.append(self.plots[kind].box)
            plot = self.plots[kind]
            if self._drawn is None or self._drawn[0] is not plot or self._drawn[1] is not result:
                plot.set(result)  # not again when only the inputs changed: the text is redrawn, not the cells
                self._drawn = (plot, result)
        self.hint.visible = plot is None
        for other in self.plots.values():
            other.box.visible = other is plot


FEATURE = Feature("map", "Stability map", StabilityMapView, StabilityMap)
