"""The app's views: each a `pn.viewable.Viewer` over a state object, implementing `__panel__` only.

Plots are HoloViews DynamicMaps bound to a state parameter (`results`, `data`, `frame`...), so
new data updates the plots' data sources in place. A figure is a builder, a plain function of
the state's data returning bare elements (cheap: no per-update options; testable and timed
without a server), and its options, set once on the DynamicMap (`figures()`). The two methods of
a comparison are drawn in fixed slots (A, B) with fixed colours, named in a colour key above the
plots, so switching methods never changes a plot's structure. Long series go through
`downsample1d` (minmax-lttb, tsdownsample); phase portraits of runs with more than
state.DENSE_RECORDS records are rasterized (datashader).
"""
import html
import math
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import holoviews as hv
import numpy as np
import panel as pn
import param
from holoviews.operation.downsample import downsample1d

from cosymp import workprecision as wp
from cosymp.methods import METHODS
from cosymp.scenes import SCENES
from cosymp.scenes.charged import GAUGES

from .presets import HARD, PAPER, PRESETS
from .state import (
    LONG_URL_NAMES,
    URL_NAMES,
    WP_MAX_STEPS,
    GaugeStudy,
    LongHorizons,
    LongRun,
    Playback,
    StabilityMap,
    Study,
    ThetaLesson,
    WorkPrecision,
)
from .warmup import RASTER_COLUMNS

SLOTS = ("A", "B")
COLORS = ("#1864ab", "#e8590c")
GAUGE_COLORS = ("#212529", "#1864ab", "#2b8a3e", "#e8590c", "#9c36b5")
CLOUD_COLORS = {"A": ("#ced4da", "#74c0fc", "#0b3d91"), "B": ("#ced4da", "#ffc078", "#a63e00")}
FLOOR = 1e-17
DOWNSAMPLE_WIDTH = 1200
TRACE_POINTS = 2000
HEIGHT = 250
ASSETS = Path(__file__).resolve().parent.parent / "assets"


# ---------------------------------------------------------------- element builders

@cache
def dim(name):
    return hv.Dimension(name)


def curve(x, y, kdim, vdim, label=""):
    return hv.Curve({kdim: x, vdim: y}, [dim(kdim)], [dim(vdim)], label=label, datatype=["dictionary"])


def points(xs, ys, kdim, vdim):
    """The first point of each slot's (x, y); kdim and vdim are names or Dimensions."""
    kd, vd = (d if isinstance(d, hv.Dimension) else dim(d) for d in (kdim, vdim))
    return [hv.Scatter({kd.name: x[:1], vd.name: y[:1]}, [kd], [vd], label=slot,
                       datatype=["dictionary"]) for slot, x, y in zip(SLOTS, xs, ys)]


def comparisons(runs):
    """The Comparison (or None) in each slot."""
    entries = runs.entries if runs is not None else ()
    return [entries[i].comparison if i < len(entries) else None for i in range(len(SLOTS))]


EMPTY = np.empty(0)


def time_series(runs, get, vdim, logy=False):
    """One curve per slot of get(comparison) -> (t, y); zeros of log plots drawn at FLOOR."""
    curves = []
    for slot, c in zip(SLOTS, comparisons(runs)):
        t, y = get(c) if c is not None else (EMPTY, EMPTY)
        if y is None:
            t, y = EMPTY, EMPTY
        curves.append(curve(t, np.maximum(np.abs(y), FLOOR) if logy else y, "t", vdim, slot))
    return hv.Overlay(curves)


def energy(runs):
    return time_series(runs, lambda c: (c.run.t, c.run.H_ext[:, 0]), "H + p_t")


def error(runs):
    return time_series(runs, lambda c: (c.run.t, c.error), "|z - z_exact|", logy=True)


def paper_volume(runs):
    return time_series(runs, lambda c: (c.run.t[1:], c.paper_volume), "det[X1 ... X(2n+1)]")


def det_deviation(runs):
    return time_series(runs, lambda c: (c.run.t[:-1], c.det_dev), "|det M - 1|", logy=True)


def paper_omega(runs):
    return time_series(runs, lambda c: (c.run.t[1:], c.paper_omega), "omega(X1, X2)")


def symp_defect(runs):
    return time_series(runs, lambda c: (c.run.t[:-1], c.symp_dev), "|M^T J M - J|", logy=True)


def separation(runs):
    return time_series(runs, lambda c: (c.run.t, c.separation_omega), "omega(d1, d2) / delta^2")


def cloud_area(runs):
    return time_series(runs, lambda c: (c.cloud.t, c.cloud_area), "area / initial area")


def phase_axes(scene):
    """(x index, y index, x label, y label, title) of the scene's phase portraits in z = (q, p)."""
    s = SCENES[scene]
    n = s.ndof
    names = list(s.coordinates)
    if n == 1:
        return [(0, 1, "q", "p", "phase portrait (q, p)")]
    return [(0, 1, names[0], names[1], f"orbit ({names[0]}, {names[1]})")] + [
        (i, n + i, names[i], f"p_{names[i]}", f"({names[i]}, p_{names[i]})") for i in range(n)]


def zcols(run, i, j):
    """Columns i and j of z = (q, p) of the trajectory (empty if the run has fewer coordinates, as
    while a view laid out for another scene receives new results)."""
    n = run.q.shape[-1]
    if max(i, j) >= 2 * n:
        return EMPTY, EMPTY

    def col(k):
        return run.q[:, 0, k] if k < n else run.p[:, 0, k - n]

    return col(i), col(j)


def phase(runs, axis, dense=False):
    """Phase portrait `axis` (an entry of phase_axes) of both slots, with the start points. In a
    dense layout the orbits are rasterized (datashader) instead."""
    i, j, xl, yl, _ = axis
    xs, ys = zip(*[zcols(c.run, i, j) if c is not None else (EMPTY, EMPTY) for c in comparisons(runs)])
    if not dense:
        return hv.Overlay([curve(x, y, xl, yl, slot) for slot, x, y in zip(SLOTS, xs, ys)]
                          + points(xs, ys, xl, yl))
    xd, yd = raster_dims(xl, yl)
    return hv.Overlay([rasterized(x, y, xd, yd, color) for x, y, color in zip(xs, ys, COLORS)]
                      + points(xs, ys, xd, yd))


def raster_dims(xl, yl):
    """The dimensions of a rasterized portrait: always named RASTER_COLUMNS (labelled xl and yl),
    since datashader compiles its aggregation anew for each pair of column names (about 1.2 s
    each on the event loop; the warm-up compiles this pair)."""
    return hv.Dimension(RASTER_COLUMNS[0], label=xl), hv.Dimension(RASTER_COLUMNS[1], label=yl)


def rasterized(x, y, xd, yd, color):
    from holoviews.operation.datashader import datashade

    return datashade(hv.Path({xd.name: x, yd.name: y}, [xd, yd]), cmap=[color], dynamic=False,
                     width=500, height=400)


def closed(q, p):
    return np.append(q, q[0]), np.append(p, p[0])


def cloud_snapshots(runs, slot):
    """The trajectory (first coordinate pair, grey), the initial loop of states (light) and the
    carried loop at T/4, T/2, 3T/4 and T (dark; one curve, broken between loops)."""
    c = comparisons(runs)[SLOTS.index(slot)]
    if c is None or c.cloud is None:
        return hv.Overlay([curve(EMPTY, EMPTY, "q1", "p1") for _ in range(3)])
    q, p = c.run.q[:, 0, 0], c.run.p[:, 0, 0]
    step = max(1, len(q) // TRACE_POINTS)
    K = len(c.cloud.t)
    first = closed(c.cloud.q[0, :, 0], c.cloud.p[0, :, 0])
    later = [closed(c.cloud.q[k, :, 0], c.cloud.p[k, :, 0]) for k in np.linspace(0, K - 1, 5).astype(int)[1:]]
    gap = np.array([np.nan])
    lq = np.concatenate([np.concatenate([x, gap]) for x, _ in later])
    lp = np.concatenate([np.concatenate([y, gap]) for _, y in later])
    return hv.Overlay([curve(q[::step], p[::step], "q1", "p1"), curve(*first, "q1", "p1"),
                       curve(lq, lp, "q1", "p1")])


def sweep(data, which, theta):
    """max over the first steps of |det M - 1| (which='det') or |M^T J M - J| ('symp') against
    θ, for the lifted and the naive θ-method, and the current θ."""
    vdim = "max |det M - 1|" if which == "det" else "max |M^T J M - J|"
    lines = []
    for slot, name in zip(SLOTS, ("theta", "theta-naive")):
        x = data["thetas"] if data else EMPTY
        y = np.maximum(data[name][which], FLOOR) if data else EMPTY
        lines.append(curve(x, y, "θ", vdim, slot))
    return hv.Overlay(lines + [hv.VLine(theta)])


GAUGE_QUANTITIES = {"orbit": ("x", "y"), "p": ("t", "p_x"), "Pi": ("t", "Pi_x"), "diff": ("t", "difference")}


def gauge_plot(data, kind, quantity):
    """One quantity of every gauge's run ('per-gauge' or 'transported'): 'orbit' (x, y), 'p'
    (canonical p_x), 'Pi' (mechanical Pi_x), 'diff' (|q - q_orig| + |Pi - Pi_orig|)."""
    kdim, vdim = GAUGE_QUANTITIES[quantity]
    items = []
    for g in GAUGES:
        if quantity == "diff" and g == "original":
            continue
        if data:
            t, q, p, Pi = data[g][kind]
        else:
            t, q, p, Pi = EMPTY, np.empty((0, 2)), np.empty((0, 2)), np.empty((0, 2))
        if quantity == "orbit":
            x, y = q[:, 0], q[:, 1]
        elif quantity == "p":
            x, y = t, p[:, 0]
        elif quantity == "Pi":
            x, y = t, Pi[:, 0]
        else:
            _, q0, _, Pi0 = data["original"][kind] if data else (t, q, p, Pi)
            x, y = t, np.maximum(np.linalg.norm(q - q0, axis=-1) + np.linalg.norm(Pi - Pi0, axis=-1), FLOOR)
        items.append(curve(x, y, kdim, vdim, g))
    return hv.Overlay(items)


def faint_orbit(runs, scene):
    """The whole orbit of each slot (at most TRACE_POINTS points), drawn faintly under `trace`."""
    i, j, xl, yl, _ = phase_axes(scene)[0]
    lines = []
    for slot, c in zip(SLOTS, comparisons(runs)):
        x, y = zcols(c.run, i, j) if c is not None else (EMPTY, EMPTY)
        step = max(1, len(x) // TRACE_POINTS)
        lines.append(curve(x[::step], y[::step], xl, yl, slot))
    return hv.Overlay(lines)


def trace(runs, scene, fraction):
    """The orbit of each slot traced up to `fraction` of the run (at most TRACE_POINTS points),
    and the current point."""
    i, j, xl, yl, _ = phase_axes(scene)[0]
    lines, now_x, now_y = [], [], []
    for slot, c in zip(SLOTS, comparisons(runs)):
        x, y = zcols(c.run, i, j) if c is not None else (EMPTY, EMPTY)
        k = int(fraction * (len(x) - 1)) if len(x) else 0
        step = max(1, len(x) // TRACE_POINTS)
        upto_x, upto_y = np.append(x[:k:step], x[k:k + 1]), np.append(y[:k:step], y[k:k + 1])
        lines.append(curve(upto_x, upto_y, xl, yl, slot))
        now_x.append(x[k:k + 1])
        now_y.append(y[k:k + 1])
    return hv.Overlay(lines + points(now_x, now_y, xl, yl))


def moving_loop(runs, fraction):
    """The carried loop of both slots at `fraction` of the run."""
    items = []
    for slot, c in zip(SLOTS, comparisons(runs)):
        if c is None or c.cloud is None:
            items.append(curve(EMPTY, EMPTY, "q1", "p1", slot))
            continue
        k = round(fraction * (len(c.cloud.t) - 1))
        items.append(curve(*closed(c.cloud.q[k, :, 0], c.cloud.p[k, :, 0]), "q1", "p1", slot))
    return hv.Overlay(items)


def cursor(runs, fraction):
    """A vertical line at `fraction` of the run's time span."""
    ends = [c.run.t[-1] for c in comparisons(runs) if c is not None]
    return hv.VLine(max(ends, default=0.0) * fraction)


def long_series(data, key, vdim):
    """Long-run envelopes per slot: for 'H' and 'vol' the per-bin min and max interleaved (so
    the curve spans each bin's range), for 'det' and 'symp' the per-bin max (log scale)."""
    curves = []
    values = list(data.values())
    for n, slot in enumerate(SLOTS):
        d = values[n] if n < len(values) else None
        if d is None or not len(d["t"]):
            t, y = EMPTY, EMPTY
        elif key in ("H", "vol"):
            width = d["t"][1] - d["t"][0] if len(d["t"]) > 1 else 1.0
            t = np.column_stack([d["t"], d["t"] + 0.5 * width]).ravel()
            y = np.column_stack([d[f"{key}_min"], d[f"{key}_max"]]).ravel()
        else:
            t, y = d["t"], np.maximum(d[key], FLOOR)
        curves.append(curve(t, y, "t", vdim, slot))
    return hv.Overlay(curves)


# ---------------------------------------------------------------- figure options

PLOT = {"responsive": True, "height": HEIGHT, "show_grid": True, "framewise": True,
        "toolbar": "right", "default_tools": ["pan", "wheel_zoom", "box_zoom", "reset", "save"]}


def figure_opts(title, xlabel="t", ylabel=None, logy=False, colors=COLORS, legend=False, **curve):
    """Options of a plot: the overlay's, and its elements' (ranges follow each new frame)."""
    norm = {"framewise": True}
    extra = {"ylim": (FLOOR / 3, None)} if logy else {}
    if ylabel:
        extra["ylabel"] = ylabel
    return (hv.opts.Overlay(**{**PLOT, "title": title, "xlabel": xlabel, "logy": logy, "show_legend": legend,
                               "legend_position": "top_left", "legend_opts": {"background_fill_alpha": 0.6}},
                            **extra),
            hv.opts.Curve(**{"color": hv.Cycle(list(colors)), "line_width": 1.5, **norm, **curve}),
            hv.opts.Scatter(color=hv.Cycle(list(colors)), size=8, **norm),
            hv.opts.VLine(color="#868e96", line_dash="dashed", line_width=1.5, **norm),
            hv.opts.RGB(alpha=0.9, **norm))


@dataclass(frozen=True)
class Figure:
    """A builder and the options of its plot."""

    build: object
    opts: tuple
    downsample: bool = True


@cache
def figures():
    """The figures shared by several views (built on first use, after the plotting extension)."""
    return {
        "energy": Figure(energy, figure_opts("H~ = H + p_t")),
        "error": Figure(error, figure_opts("error |z − z_exact|", logy=True)),
        "paper_volume": Figure(paper_volume, figure_opts("paper's estimator: det[X¹ … X²ⁿ⁺¹]")),
        "det": Figure(det_deviation, figure_opts("rigorous: |det M_k − 1|", logy=True)),
        "paper_omega": Figure(paper_omega, figure_opts("paper's estimator: ω(X¹, X²)")),
        "symp": Figure(symp_defect, figure_opts("rigorous: max |M_kᵀ J M_k − J|", logy=True)),
        "separation": Figure(separation, figure_opts("rigorous: ω(δ¹, δ²)/δ² of nearby runs")),
        "area": Figure(cloud_area, figure_opts("carried loop: area / initial area")),
        **{f"cloud {slot}": Figure(cloud_snapshots, figure_opts(
            f"{slot}: loop at t = 0 (light), T/4, T/2, 3T/4, T (dark)", xlabel="q1",
            colors=CLOUD_COLORS[slot]), downsample=False) for slot in SLOTS},
        "sweep det": Figure(sweep, figure_opts("max |det M_k − 1| over the first steps, against θ",
                                               xlabel="θ", logy=True), downsample=False),
        "sweep symp": Figure(sweep, figure_opts("max |M_kᵀ J M_k − J| over the first steps, against θ",
                                                xlabel="θ", logy=True), downsample=False),
        "loop": Figure(moving_loop, figure_opts("loop of initial states, now", xlabel="q1", line_width=2),
                       downsample=False),
        "cursor": Figure(cursor, figure_opts(""), downsample=False),
    }


def phase_figure(axis):
    return Figure(phase, figure_opts(axis[4] + ", dot: start", xlabel=axis[2]), downsample=False)


def trace_figures(axis):
    """The faint whole orbit and the traced part, overlaid in the Play view."""
    title = axis[4] + ", traced (dot: now)"
    faint = figure_opts(title, xlabel=axis[2], alpha=0.15, line_width=1)
    return (Figure(faint_orbit, faint, downsample=False),
            Figure(trace, figure_opts(title, xlabel=axis[2], line_width=2), downsample=False))


def layout_key(shown):
    """(scene, dense) from Study.shown."""
    scene, _, density = shown.partition("/")
    return scene, density == "dense"


def gauge_figure(quantity):
    titles = {"orbit": "orbit (x, y)", "p": "canonical p_x (gauge-dependent)",
              "Pi": "mechanical Π_x = p_x − e A_x (gauge-invariant)", "diff": "|q − q_orig| + |Π − Π_orig|"}
    colors = GAUGE_COLORS[1:] if quantity == "diff" else GAUGE_COLORS
    return Figure(gauge_plot, figure_opts(titles[quantity], xlabel=GAUGE_QUANTITIES[quantity][0],
                                          logy=quantity == "diff", colors=colors, legend=True,
                                          line_dash=hv.Cycle(["dashed"] * 4 if quantity == "diff"
                                                             else ["solid"] + ["dashed"] * 4)),
                  downsample=quantity != "orbit")


@cache
def long_figures():
    """key -> (value dimension, options) of the long-run plots."""
    return {
        "H": ("H + p_t", figure_opts("H~ = H + p_t, per-bin min and max")),
        "vol": ("det[X1 ... X(2n+1)]", figure_opts("paper's estimator: det[X¹ … X²ⁿ⁺¹], per bin")),
        "det": ("|det M - 1|", figure_opts("rigorous: max |det M_k − 1| per bin", logy=True)),
        "symp": ("|M^T J M - J|", figure_opts("rigorous: max |M_kᵀ J M_k − J| per bin", logy=True)),
    }


# ---------------------------------------------------------------- helpers for viewers

@cache
def stylesheet():
    """The app's CSS, given to each HTML pane (Panel renders components in shadow roots)."""
    return (ASSETS / "app.css").read_text()


def note(obj, **kw):
    """An HTML pane with the app's stylesheet."""
    return pn.pane.HTML(obj, stylesheets=[stylesheet()], **{"sizing_mode": "stretch_width", **kw})


def live(figure, *refs):
    """A DynamicMap of figure.build(*refs), updated in place when a referenced parameter changes.

    Long series are reduced with `downsample1d` (minmax-lttb) on every update, to at most
    DOWNSAMPLE_WIDTH points over the whole run: the operation is applied statically because its
    dynamic form keeps slicing to the previous viewport when new data spans a new range."""
    build = figure.build
    if figure.downsample:
        reduce = downsample1d.instance(algorithm="minmax-lttb", width=DOWNSAMPLE_WIDTH, dynamic=False)

        def build(*args):
            return reduce(figure.build(*args))

    return hv.DynamicMap(pn.bind(build, *refs)).opts(*figure.opts)


def plot(obj):
    return pn.pane.HoloViews(obj, sizing_mode="stretch_width", min_height=HEIGHT + 10, linked_axes=False)


def grid(*items, ncols=2):
    return pn.GridBox(*items, ncols=ncols, sizing_mode="stretch_width")


def swatch(slot_index, label):
    return (f"<b>{SLOTS[slot_index]}</b> <span class='swatch' style='background:{COLORS[slot_index]}'></span>"
            f"{html.escape(label)}")


def color_key(runs):
    """Which method each colour is, with what it preserves and its order."""
    if runs is None:
        return ""
    parts = []
    for i, e in enumerate(runs.entries):
        m = METHODS[e.method]
        theta = e.comparison.setup.theta if e.comparison is not None else None
        theta = 0.5 if theta is None else theta
        parts.append(f"{swatch(i, e.label)} <span class='doc'>{html.escape(m.title)}; preserves: "
                     f"{html.escape(m.preserves_at(theta))}; order {m.order_at(theta)}</span>")
    return "<div class='colorkey'>" + "&emsp;&emsp;".join(parts) + "</div>"


def numbers_html(runs):
    """The numbers panel: Comparison.summary of both methods (maxima over every step)."""
    if runs is None:
        return ""
    rows = {}
    for e in runs.entries:
        for k, v in (e.comparison.summary if e.comparison is not None else {}).items():
            rows.setdefault(k, {})[e.label] = v
    head = "".join(f"<th>{swatch(i, e.label)}</th>" for i, e in enumerate(runs.entries))
    body = [f"<tr><th>{html.escape(k)}</th>" + "".join(f"<td>{_fmt(cells.get(e.label))}</td>"
                                                     for e in runs.entries) + "</tr>"
            for k, cells in rows.items()]
    body.append("<tr><th>run</th>" + "".join(f"<td class='wrap'>{html.escape(e.failure) or 'reached T'}</td>"
                                             for e in runs.entries) + "</tr>")
    return (f"<table class='numbers'><tr><th>h = {runs.h:g}, T = {runs.T:g}</th>{head}</tr>"
            + "".join(body) + "</table>")


def _fmt(v):
    if v is None:
        return "–"
    if isinstance(v, int):
        return str(v)
    return f"{v:.3e}"


def long_key(data):
    parts = [swatch(i, label) + (f" <span class='caveat'>stopped: {html.escape(d['failure'])}</span>"
                                 if d["failure"] else "")
             for i, (label, d) in enumerate(data.items())]
    return "<div class='colorkey'>" + "&emsp;&emsp;".join(parts) + "</div>"


def loading():
    return pn.indicators.LoadingSpinner(value=True, size=40, name="computing…")


# ---------------------------------------------------------------- viewers

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
            pn.Row(pn.widgets.FloatInput.from_param(s.param.h, name="Step h", format="0.[000000]", **wide),
                   pn.widgets.FloatInput.from_param(s.param.T, name="Horizon T", **wide), **wide),
            note("<h4>Scene parameters</h4>", margin=(10, 5, 0, 5)),
            pn.panel(pn.bind(scene_widgets, s.param.inputs), **wide),
            **wide,
        )


def scene_widgets(inputs):
    """Widgets for a scene-inputs object: a slider with a text box for each number (the slider
    spans a range around the default; any value within the bounds can be typed), a select for
    choices, a text input (applied on Enter) for beta(t)."""
    widgets = []
    for name in (n for n in inputs.param if n != "name"):
        p = inputs.param[name]
        if isinstance(p, param.Selector):
            w = pn.widgets.Select.from_param(p, description=p.doc, sizing_mode="stretch_width")
        elif isinstance(p, param.String):
            label = f"{name}(t): 'paper', 'constant' or an expression of t"
            w = pn.widgets.TextInput.from_param(p, name=label, description=p.doc, sizing_mode="stretch_width",
                                                placeholder="e.g. 0.05*(1 + tanh(t)), then Enter")
        else:
            w = number_control(inputs, name)
        widgets.append(w)
    return pn.Column(*widgets, sizing_mode="stretch_width", margin=0)


def number_control(inputs, name):
    """A slider over the parameter's soft range and a box that takes any value within its bounds;
    the slider widens to a typed value outside its range.

    Not Panel's EditableFloatSlider: in Panel 1.9 its JavaScript callback sits in a global
    registry whose entry refers back to the widget, so every one stays alive, and with it the
    inputs it shows, the Study watching them and the closed session's results."""
    p = inputs.param[name]
    lo, hi = p.softbounds
    value = getattr(inputs, name)
    slider = pn.widgets.FloatSlider(label=p.label, start=min(lo, value), end=max(hi, value), step=p.step,
                                    value=value, format="0.[00000]", sizing_mode="stretch_width")
    box = pn.widgets.FloatInput.from_param(p, name="", format="0.[00000]", width=100, align="end",
                                           description=p.doc)

    def show(event):
        slider.param.update(start=min(slider.start, event.new), end=max(slider.end, event.new),
                            value=event.new)

    inputs.param.watch(show, name)
    slider.param.watch(lambda e: setattr(inputs, name, e.new), "value")
    return pn.Row(slider, box, name=name, sizing_mode="stretch_width", margin=0)


class SceneInfo(pn.viewable.Viewer):
    """The scene's title, summary, equations, what to look for, and its notes."""

    study = param.ClassSelector(class_=Study)

    def __panel__(self):
        return pn.panel(pn.bind(scene_info, self.study.param.scene), sizing_mode="stretch_width")


def scene_info(name):
    s = SCENES[name]
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in s.notes)
    return pn.Column(
        note(f"<h2>{html.escape(s.title)}</h2><p>{html.escape(s.summary)}</p>", margin=(0, 10)),
        pn.FlexBox(*[pn.pane.LaTeX(f"${e}$", renderer="katex", styles={"font-size": "1.05em"})
                     for e in s.equations], gap="1.5em", sizing_mode="stretch_width"),
        note(f"<p class='lookfor'><b>Look for:</b> {html.escape(s.look_for)}</p>"
             + (f"<ul class='notes'>{notes}</ul>" if notes else ""), margin=(0, 10)),
        sizing_mode="stretch_width",
    )


VOLUME_TEXT = ("<h4>Volume form</h4><p class='doc'>Left, the paper's estimator as printed: the determinant "
               "of the one-step increments X<sup>i</sup> = z<sup>i</sup><sub>k+1</sub> − "
               "z<sup>i</sup><sub>k</sub> "
               "of 2n+1 nearby runs in (q, t, p) (three for one degree of freedom). Right, the rigorous "
               "check: |det M<sub>k</sub> − 1| of the one-step tangent map on the time slice, 0 to round-off "
               "for a volume-preserving method (exact zeros are drawn at 1e-17).</p>")
SYMPLECTIC_TEXT = ("<h4>Symplectic form</h4><p class='doc'>The paper's estimator as printed: ω(X¹, X²) of "
                   "the one-step increments of two nearby runs. Rigorous checks: max |M<sub>k</sub>ᵀ J "
                   "M<sub>k</sub> − J| of the one-step tangent map (0 to round-off when symplectic), "
                   "ω(δ¹, δ²)/δ² of the separations δ<sup>i</sup> = z<sup>i</sup> − z<sup>0</sup> of "
                   "nearby runs, and the area enclosed by a carried loop of initial states (both stay 1 "
                   "when symplectic).</p>")
CLOUD_TEXT = ("<h4>Phase-space cloud</h4><p class='doc'>A loop of initial states (radius 0.05 around the "
              "initial condition, first coordinate pair) carried by each method (A left, B right), drawn at "
              "t = 0 (light) and at T/4, T/2, 3T/4 and T (dark) over the trajectory (grey).</p>")


NUMBERS_TEXT = "<h4>Numbers</h4><p class='doc'>From the full-resolution runs: maxima over every step.</p>"


class OrbitsView(pn.viewable.Viewer):
    """Phase portraits, H~ and the error against the exact flow of both methods, and the numbers."""

    study = param.ClassSelector(class_=Study)

    def __panel__(self):
        return pn.panel(pn.bind(orbits_layout, self.study, self.study.param.shown),
                        sizing_mode="stretch_width")


def orbits_layout(study, shown):
    if not shown:
        return loading()
    scene, dense = layout_key(shown)
    res = study.param.results
    first = [plot(live(phase_figure(axis), res, axis, dense)) for axis in phase_axes(scene)]
    first.append(plot(live(figures()["energy"], res)))
    remark = ""
    if SCENES[scene].has_flow:
        first.append(plot(live(figures()["error"], res)))
    else:
        remark = (f"<p class='doc'>No closed-form flow for '{scene}', so no error plot (the command line's "
                  "<code>cosymp run</code> measures the error at T against a fine RK8 reference).</p>")
    return pn.Column(
        note(pn.bind(color_key, res)),
        grid(*first, ncols=3 if len(first) == 3 else 2),
        note(remark),
        note(NUMBERS_TEXT),
        note(pn.bind(numbers_html, res)),
        sizing_mode="stretch_width",
    )


class StructureView(pn.viewable.Viewer):
    """Volume and symplectic form of both methods: the paper's estimators beside the rigorous checks."""

    study = param.ClassSelector(class_=Study)

    def __panel__(self):
        res = self.study.param.results
        return pn.Column(
            note(pn.bind(color_key, res)),
            note(VOLUME_TEXT),
            grid(plot(live(figures()["paper_volume"], res)), plot(live(figures()["det"], res))),
            note(SYMPLECTIC_TEXT),
            grid(*[plot(live(figures()[k], res)) for k in ("paper_omega", "symp", "separation", "area")]),
            note(NUMBERS_TEXT),
            note(pn.bind(numbers_html, res)),
            sizing_mode="stretch_width",
        )


class CloudView(pn.viewable.Viewer):
    """The carried loop of initial states of both methods, and its area over time."""

    study = param.ClassSelector(class_=Study)

    def __panel__(self):
        res = self.study.param.results
        return pn.Column(
            note(pn.bind(color_key, res)),
            note(CLOUD_TEXT),
            grid(*[plot(live(figures()[f"cloud {slot}"], res, slot)) for slot in SLOTS]),
            grid(plot(live(figures()["area"], res))),
            sizing_mode="stretch_width",
        )


class GaugeView(pn.viewable.Viewer):
    """The charged particle in five gauges: q, p and Pi per gauge, per-gauge runs beside the
    transported maps, differences from the original gauge, and where the paper's gauges fall short."""

    gauges = param.ClassSelector(class_=GaugeStudy)

    def __panel__(self):
        g = self.gauges
        return pn.panel(pn.bind(gauge_layout, g, g.study.param.scene), sizing_mode="stretch_width")


def gauge_layout(g, scene):
    if scene != "charged":
        button = pn.widgets.Button(name="Open the charged particle", button_type="primary")
        button.on_click(lambda event: g.study.param.update(scene="charged"))
        return pn.Column(note("<p>The gauge study is about the charged particle in a time-dependent "
                              "field.</p>"), button)
    res = g.param.results
    rows = [pn.Row(note(f"<b>{name}</b>", width=90, sizing_mode=None),
                   pn.pane.LaTeX(f"$\\chi = {x.chi}$", renderer="katex", width=230),
                   note(f"<span class='doc'>condition: {html.escape(x.condition)}</span>"
                        + (f"<br><span class='caveat'>{html.escape(x.caveat)}</span>" if x.caveat else "")),
                   sizing_mode="stretch_width")
            for name, x in GAUGES.items()]
    columns = [pn.Column(note(f"<h4>{text}</h4>"),
                         *[plot(live(gauge_figure(quantity), res, kind, quantity))
                           for quantity in ("orbit", "p", "Pi", "diff")], sizing_mode="stretch_width")
               for kind, text in (("per-gauge", "Per-gauge runs: the method applied in each gauge"),
                                  ("transported", "Transported: the original-gauge run mapped by G_χ"))]
    return pn.Column(
        note(pn.bind(lambda m: f"<p>Method: <b>{html.escape(m)}</b>. q and the mechanical momentum Π agree "
                     "across gauges (to the method's order for per-gauge runs, to round-off when "
                     "transported); the canonical momentum p does not.</p>" if m else "", g.param.method)),
        *rows, pn.Row(*columns, sizing_mode="stretch_width"), sizing_mode="stretch_width")


class ThetaView(pn.viewable.Viewer):
    """Lifted against naive θ-method at the same θ: one-step defects, carried area, θ sweep."""

    lesson = param.ClassSelector(class_=ThetaLesson)

    def __panel__(self):
        le = self.lesson
        res = le.param.results
        theta = le.study.param.theta
        return pn.Column(
            note("<p>Both methods evaluate H at an intermediate point of each step. The <b>lifted</b> "
                 "θ-method (the paper's cotangent lift) puts q at θ and p at 1 − θ: it is symplectic on "
                 "every time slice <b>for every θ</b>. The <b>naive</b> θ-method puts q and p both at θ: "
                 "symplectic <b>only at θ = 1/2</b>. Move θ and watch |det M − 1| and the carried area.</p>"),
            note(pn.bind(color_key, res)),
            pn.widgets.FloatSlider.from_param(theta, sizing_mode="stretch_width"),
            note("<p class='doc'>Top: the largest one-step defect over the first steps of the run, for 21 "
                 "values of θ (dashed line: the θ of the slider). Below: the two methods at that θ.</p>"),
            grid(*[plot(live(figures()[f"sweep {k}"], le.param.sweep, k, theta)) for k in ("det", "symp")]),
            grid(*[plot(live(figures()[k], res)) for k in ("det", "symp", "area", "energy")]),
            grid(*[plot(live(figures()[f"cloud {slot}"], res, slot)) for slot in SLOTS]),
            sizing_mode="stretch_width",
        )


class PlayView(pn.viewable.Viewer):
    """Animates the comparison: the orbit traced progressively, the carried loop moving, a time
    cursor on H~ and on the loop's area; speed control."""

    study = param.ClassSelector(class_=Study)
    playback = param.ClassSelector(class_=Playback)

    def __panel__(self):
        return pn.panel(pn.bind(play_layout, self.study, self.playback, self.study.param.shown),
                        sizing_mode="stretch_width")


def play_layout(study, pb, shown):
    if not shown:
        return loading()
    scene, _ = layout_key(shown)
    res = study.param.results
    frac = pn.bind(lambda f: f / Playback.FRAMES, pb.param.frame)
    faint, traced = trace_figures(phase_axes(scene)[0])
    player = pn.widgets.Player.from_param(pb.param.frame, start=0, end=Playback.FRAMES, loop_policy="once",
                                          interval=pn.bind(lambda fps: int(1000 / fps), pb.param.fps),
                                          show_value=False, show_loop_controls=False, width=420)
    clock = pn.bind(lambda r, f: "" if r is None else f"<p class='clock'>t = {r.T * f:.4g} of {r.T:g}</p>",
                    res, frac)
    return pn.Column(
        pn.Row(player, pn.widgets.Select.from_param(pb.param.fps, name="Speed", width=140),
               note(clock, width=220, sizing_mode=None)),
        note(pn.bind(color_key, res)),
        grid(plot((live(faint, res, scene) * live(traced, res, scene, frac)).opts(*traced.opts)),
             plot(live(figures()["loop"], res, frac))),
        grid(*[plot((live(figures()[k], res) * live(figures()["cursor"], res, frac)).opts(*figures()[k].opts))
               for k in ("energy", "area")]),
        sizing_mode="stretch_width",
    )


class LongRunView(pn.viewable.Viewer):
    """Start/cancel a chunked long run, its progress, and its envelopes as they arrive."""

    long = param.ClassSelector(class_=LongRun)

    def __panel__(self):
        lr = self.long
        start = pn.widgets.Button(name="Start long run", button_type="primary", disabled=lr.param.running)
        start.on_click(lambda event: lr.start())
        cancel = pn.widgets.Button(name="Cancel", button_type="danger",
                                   disabled=pn.bind(lambda r: not r, lr.param.running))
        cancel.on_click(lambda event: lr.cancel())
        progress = pn.indicators.Progress(value=pn.bind(lambda p: round(100 * p), lr.param.progress), max=100,
                                          width=260, bar_color="primary", margin=(22, 10))
        status = pn.bind(lambda s, st: f"<p class='doc'>{html.escape(s)}<br><b>{html.escape(st)}</b></p>",
                         lr.param.setting, lr.param.status)
        data = lr.param.data
        return pn.Column(
            note("<p>The study's scene, methods, parameters and h, run to the long horizon in chunks off the "
                 "event loop. The plots show per-bin envelopes (each bin's min and max, or max) as they "
                 "arrive, downsampled for display; the page stays usable meanwhile.</p>"),
            pn.Row(pn.widgets.FloatInput.from_param(lr.param.T_long, width=180), start, cancel, progress),
            note(status),
            note(pn.bind(long_key, data)),
            grid(*[plot(live(Figure(long_series, opts), data, key, vdim))
                   for key, (vdim, opts) in long_figures().items()]),
            sizing_mode="stretch_width",
        )


class PresetLinks(pn.viewable.Viewer):
    """Links that open the app on each paper figure's parameters, and on the hard cases (each
    with its sentence on what to see)."""

    def __panel__(self):
        groups = []
        for group in (PAPER, HARD):
            items = "".join(f"<li><a href='{html.escape(p.query(URL_NAMES, LONG_URL_NAMES))}' "
                            f"title='{html.escape(p.doc)}'>{html.escape(p.name)}</a>"
                            + (f"<br><small>{html.escape(p.doc)}</small>" if group == HARD else "") + "</li>"
                            for p in PRESETS if p.group == group)
            body = f"<ul class='presets'>{items}</ul>"
            groups.append(f"<h4>{group}</h4>{body}" if group == PAPER else
                          f"<details class='presets'><summary><b>{group}</b> (what each shows)</summary>{body}</details>")
        return note("".join(groups))


# ---------------------------------------------------------------- work against precision

SOLVER_COLORS = {  # non-preserving methods warm, structure-preserving cool, scipy's grey to black
    "euler": "#8c564b", "rk4": "#d62728", "rk8": "#ff7f0e", "theta-naive": "#e377c2", "exact": "#7f7f7f",
    "theta": "#bcbd22", "midpoint": "#1f77b4", "symplectic-euler": "#17becf", "gauss4": "#2ca02c",
    "gauss6": "#00441b", "composition4": "#9467bd", "composition6": "#3f007d", "boris": "#0b7285",
    "scipy-RK45": "#868e96", "scipy-DOP853": "#212529", "scipy-LSODA": "#495057",
}
WP_HEIGHT = 340
WP_KEYS = {"error": "relative error at T", "H_ext_max_abs": "max |H~| over the run"}
DRIFT_KEYS = {"error": "relative error at T", "H_ext_max_abs": "max |H~| up to T"}
HOVER = [("solver", "@solver"), ("run", "@run"), ("steps", "@steps"), ("error at T", "@error_text"),
         ("wall time", "@wall_text"), ("max |H~|", "@H_text"), ("max |det M − 1|", "@det_text")]
WALL = hv.Dimension("wall_s", label="wall time (s)")
HORIZON = hv.Dimension("T", label="horizon T")


def solver_color(solver):
    return SOLVER_COLORS.get(solver, SOLVER_COLORS.get(solver.split("(")[0], "#343a40"))


def finite(x):
    return isinstance(x, (int, float)) and math.isfinite(x)


def _sci(x, unit=""):
    return f"{x:.3e}{unit}" if finite(x) else "–"


def run_text(row):
    """The step or the tolerance of a work-precision row."""
    return f"h = {row['h']:.4g}" if row["kind"] == "cosymp" else f"rtol = {row['rtol']:.0e}"


def wp_points(rows, key):
    """The rows drawn in the work-precision plot of `key` ('error' or 'H_ext_max_abs'): those with
    a finite wall time and a finite value, in row order (point i of the plot's Scatter is row i)."""
    return [r for r in rows if finite(r["wall_s"]) and finite(r[key])]


def wp_plot(rows, key):
    """key against wall time: one line per solver (its runs in order of refinement; cosymp's
    methods solid, scipy's dashed) and one Scatter of every point, with what the hover shows.
    Zeros are drawn at FLOOR."""
    pts = wp_points(rows, key)
    vdim = hv.Dimension(key, label=WP_KEYS[key])
    lines = []
    for solver in dict.fromkeys(r["solver"] for r in pts):
        mine = [r for r in pts if r["solver"] == solver]
        lines.append(hv.Curve(([r["wall_s"] for r in mine], [max(r[key], FLOOR) for r in mine]), WALL, vdim,
                              label=solver).opts(color=solver_color(solver),
                                                 line_dash="dashed" if mine[0]["kind"] == "scipy" else "solid"))
    table = {
        "wall_s": [r["wall_s"] for r in pts], key: [max(r[key], FLOOR) for r in pts],
        "solver": [r["solver"] for r in pts], "run": [run_text(r) for r in pts],
        "steps": [str(r["steps"]) for r in pts], "error_text": [_sci(r["error"]) for r in pts],
        "wall_text": [_sci(r["wall_s"], " s") for r in pts], "H_text": [_sci(r["H_ext_max_abs"]) for r in pts],
        "det_text": [_sci(r["det_max_dev"]) for r in pts], "color": [solver_color(r["solver"]) for r in pts],
        "marker": ["square" if r["kind"] == "scipy" else "circle" for r in pts],
    }
    scatter = hv.Scatter(table, WALL, [vdim, *[k for k in table if k not in ("wall_s", key)]])
    return hv.Overlay([*lines, scatter])


def drift_plot(rows, key):
    """key against the horizon T, one line with markers per method (its fitted growth exponent in
    the legend), and the slopes T¹ and T² (dotted) through the first horizon's geometric mean, up
    to ten times the largest value."""
    vdim = hv.Dimension(key, label=DRIFT_KEYS[key])
    items = []
    pts = [r for r in rows if finite(r[key]) and r[key] > 0]
    for solver in dict.fromkeys(r["solver"] for r in rows):
        mine = [r for r in pts if r["solver"] == solver]
        g = wp.growth_exponent(rows, solver, key)
        label = f"{solver}: slope {g:.2f}" if finite(g) else f"{solver}: slope –"
        data = ([r["T"] for r in mine], [r[key] for r in mine])
        color = solver_color(solver)
        items += [hv.Curve(data, HORIZON, vdim, label=label).opts(color=color),
                  hv.Scatter(data, HORIZON, vdim, label=label).opts(color=color)]
    if pts:
        T0 = min(r["T"] for r in pts)
        T1 = max(r["T"] for r in pts)
        y0 = math.exp(np.mean([math.log(r[key]) for r in pts if r["T"] == T0]))
        top = 10 * max(r[key] for r in pts)
        for power, label in ((1, "∝ T (linear)"), (2, "∝ T² (quadratic)")):
            end = min(T1, T0 * (top / y0) ** (1 / power))
            items.append(hv.Curve(([T0, end], [y0, y0 * (end / T0) ** power]), HORIZON, vdim, label=label).opts(
                color="#868e96", line_dash="dotted" if power == 1 else "dotdash", line_width=2))
    return hv.Overlay(items)


def wp_opts(title, xlabel, ylabel):
    return hv.opts.Overlay(responsive=True, height=WP_HEIGHT, show_grid=True, logx=True, logy=True, title=title,
                           xlabel=xlabel, ylabel=ylabel, legend_position="right", toolbar="right",
                           legend_opts={"label_text_font_size": "8pt", "spacing": 0},
                           default_tools=["pan", "wheel_zoom", "box_zoom", "reset", "save"])


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


def _seconds(x):
    return f"{x:.2e} s" if finite(x) else "–"


def _ratio(x):
    return f"{x:.3g}×" if finite(x) else "–"


TARGETS_TEXT = ("<p class='doc'>Time to reach an error: the wall time at which a solver's curve crosses it "
                "(interpolated log–log between its cheapest run below the error and the run before it); – where "
                "it does not get there in this measurement. The ratios compare the costs at the same error: "
                "scipy's DOP853 over cosymp's fastest method (above 1: cosymp is faster), and cosymp's fastest "
                "symplectic method over its RK4 (below 1: structure preservation costs nothing here).</p>")


def reference_html(rows):
    """The reference the errors are measured against, and its largest uncertainty."""
    if not rows:
        return ""
    unc = max((r["reference_uncertainty"] for r in rows if finite(r["reference_uncertainty"])), default=0.0)
    return (f"<p class='doc'>Reference: {html.escape(str(rows[0]['reference']))}"
            + (f" (relative uncertainty up to {unc:.1e}: smaller errors are not resolved)" if unc > 0 else "")
            + ".</p>")


def targets_html(rows):
    """Time to reach 1e-6 and 1e-9 per solver, and the two ratios (cosymp.workprecision.targets)."""
    if not rows:
        return ""
    t = wp.targets(rows)
    errors = list(t["cost"])
    solvers = list(t["cost"][errors[0]])
    head = "<tr><th>time to reach</th>" + "".join(f"<th>error {e:.0e}</th>" for e in errors) + "</tr>"
    body = "".join(f"<tr><th><span class='swatch' style='background:{solver_color(s)}'></span>{html.escape(s)}</th>"
                   + "".join(f"<td>{_seconds(t['cost'][e][s])}</td>" for e in errors) + "</tr>" for s in solvers)
    ratios = t["ratios"]

    def named(e, ratio, who):
        name = ratios[e][who]
        return f"{_ratio(ratios[e][ratio])}" + (f" ({html.escape(name)})" if name else "")

    body += ("<tr><th>scipy DOP853 / fastest cosymp</th>"
             + "".join(f"<td>{named(e, 'dop853_over_fastest', 'fastest')}</td>" for e in errors) + "</tr>"
             "<tr><th>best symplectic / rk4</th>"
             + "".join(f"<td>{named(e, 'symplectic_over_rk4', 'best_symplectic')}</td>" for e in errors) + "</tr>")
    return f"<table class='numbers'>{head}{body}</table>"


GROWTH_TEXT = ("<p class='doc'>Growth exponent: the slope of log(error) against log(T), fitted over the horizons "
               "before the error first reaches 0.1 (where it saturates at the orbit's size) and where it is above "
               "ten times the reference's uncertainty, and the slope of log(max |H~|); 1 is linear growth, 2 "
               "quadratic, 0 bounded; – with fewer than three usable horizons. Grey: the slopes T and T² for "
               "comparison.</p>")


def growth_html(rows):
    """The fitted growth exponents of the error and of max |H~| per method."""
    if not rows:
        return ""
    solvers = list(dict.fromkeys(r["solver"] for r in rows))
    head = "<tr><th>method</th><th>order</th><th>preserves</th><th>error ∝ T^</th><th>max |H~| ∝ T^</th></tr>"
    body = ""
    for s in solvers:
        first = next(r for r in rows if r["solver"] == s)
        body += (f"<tr><th><span class='swatch' style='background:{solver_color(s)}'></span>{html.escape(s)}</th>"
                 f"<td>{first['order']}</td><td>{html.escape(str(first['preserves']))}</td>"
                 + "".join(f"<td>{_exponent(wp.growth_exponent(rows, s, key))}</td>" for key in DRIFT_KEYS) + "</tr>")
    return f"<table class='numbers'>{head}{body}</table>"


def _exponent(g):
    return f"{g:.2f}" if finite(g) else "–"


WP_TEXT = ("<p>What each method costs for the accuracy it delivers, on the sidebar's scene, parameters, θ and T: "
           "each of cosymp's methods over step sizes (refined by √2 until the error stops improving or a run "
           "reaches {steps} steps), and scipy's adaptive <code>solve_ivp</code> over tolerances 1e-3 … 1e-12 on "
           "the same extended ODE. Wall time: the best of repeated runs after an untimed warm-up (so no "
           "compilation). Top, the relative error at T against the exact flow, or else a DOP853 run tighter than "
           "any peer's; below, the largest |H~| = |H + p_t| over the run. <b>Click a point</b> of one of cosymp's "
           "methods to open that method and step in the Orbits view.</p>")
LONG_TEXT = ("<h4>Long horizons</h4><p>Each method at one step h, carried from T = 100 to the largest horizon: the "
             "error at each horizon and the largest |H~| so far. Where the error grows linearly (slope 1) the "
             "method errs mostly in phase; quadratic growth (slope 2) is the drift that structure preservation "
             "is meant to prevent.</p>")


def run_controls(bg, start_label):
    """Start and Cancel buttons, a progress bar, the current run's label and the status line."""
    start = pn.widgets.Button(name=start_label, button_type="primary", disabled=bg.param.running)
    start.on_click(lambda event: bg.start())
    cancel = pn.widgets.Button(name="Cancel", button_type="danger", disabled=pn.bind(lambda r: not r, bg.param.running))
    cancel.on_click(lambda event: bg.cancel())
    progress = pn.indicators.Progress(value=pn.bind(lambda p: round(100 * p), bg.param.progress), max=100, width=220,
                                      bar_color="primary", margin=(22, 10, 10, 10))
    label = pn.bind(lambda running, text: f"<p class='doc wplabel'>{html.escape(text)}</p>" if running else "",
                    bg.param.running, bg.param.label)
    status = pn.bind(lambda st, setting: (f"<p class='doc'><b class='wpstatus'>{html.escape(st)}</b>"
                                          + (f"<br>Shown: {html.escape(setting)}" if setting else "") + "</p>"),
                     bg.param.status, bg.param.setting)
    return (pn.Row(start, cancel, progress, note(label, width=320, sizing_mode=None, margin=(18, 5)),
                   sizing_mode="stretch_width"),
            note(status))


def rows_plot(rows, figure, key, title, xlabel, ylabel, on_tap=None, hint=""):
    """The plot of `figure(rows, key)`, or the hint before the first measurement; with on_tap, a
    tap on a point calls on_tap(its index among the Scatter's points)."""
    if not rows:
        return note(f"<p class='doc'>{hint}</p>" if hint else "")
    overlay = figure(rows, key).opts(wp_opts(title, xlabel, ylabel), hv.opts.Curve(line_width=1.5),
                                     hv.opts.Scatter(size=7, tools=["hover", "tap"] if on_tap else [],
                                                     **({"hover_tooltips": HOVER, "color": "color",
                                                         "marker": "marker", "nonselection_alpha": 1.0}
                                                        if on_tap else {})))
    if on_tap is not None:
        scatter = overlay.get(len(overlay) - 1)
        stream = hv.streams.Selection1D(source=scatter)
        stream.add_subscriber(lambda index: index and on_tap(index[0]))
    return pn.pane.HoloViews(overlay, sizing_mode="stretch_width", min_height=WP_HEIGHT + 10, linked_axes=False)


class WorkPrecisionView(pn.viewable.Viewer):
    """Work against precision (error and max |H~| against wall time per method and scipy peer,
    the time to reach 1e-6 and 1e-9), and the long-horizon drift of the error and of |H~|."""

    measure = param.ClassSelector(class_=WorkPrecision)
    long = param.ClassSelector(class_=LongHorizons)

    def __panel__(self):
        m, lh = self.measure, self.long
        wide = {"sizing_mode": "stretch_width"}
        wp_row, wp_status = run_controls(m, "Start work–precision")
        long_row, long_status = run_controls(lh, "Start long horizons")
        rows = m.param.rows

        def tapped(key):
            return lambda i: m.open_row(wp_points(m.rows, key)[i])

        hints = ("Nothing measured yet: press Start.", "")
        wp_plots = [pn.panel(pn.bind(rows_plot, rows, wp_plot, key, title, "wall time (s)", WP_KEYS[key],
                                     tapped(key), hint), **wide)
                    for (key, title), hint in zip((("error", "relative error at T against wall time"),
                                                   ("H_ext_max_abs", "max |H~| = max |H + p_t| against wall time")),
                                                  hints)]
        long_plots = [pn.panel(pn.bind(rows_plot, lh.param.rows, drift_plot, key, title, "horizon T",
                                       DRIFT_KEYS[key], None, hint), **wide)
                      for (key, title), hint in zip((("error", "relative error at T, at fixed h"),
                                                     ("H_ext_max_abs", "max |H~| up to T, at fixed h")), hints)]
        return pn.Column(
            note(WP_TEXT.format(steps=f"{WP_MAX_STEPS:,}")),
            pn.widgets.MultiChoice.from_param(m.param.methods, name="Methods", **wide),
            pn.widgets.Checkbox.from_param(m.param.peers),
            wp_row, wp_status,
            note(pn.bind(failed_html, rows)),
            *wp_plots,
            note(pn.bind(lambda r: reference_html(r) + TARGETS_TEXT + targets_html(r) if r else "", rows)),
            pn.layout.Divider(),
            note(LONG_TEXT),
            pn.Row(pn.widgets.MultiChoice.from_param(lh.param.methods, name="Methods", **wide),
                   pn.widgets.FloatInput.from_param(lh.param.h, format="0.[000000]", width=140),
                   pn.widgets.Select.from_param(lh.param.T_max, width=140), **wide),
            long_row, long_status,
            note(pn.bind(failed_html, lh.param.rows, lambda r: f"T = {r['T']:g}")),
            *long_plots,
            note(pn.bind(lambda r: reference_html(r) + GROWTH_TEXT + growth_html(r) if r else "", lh.param.rows)),
            **wide,
        )


MAP_TEXT = ("<p>One measure of the sidebar's method over a grid of two varied quantities (scene parameters, h, T "
            "or θ), every other value taken from the sidebar. Each cell is one run from the scene's initial "
            "state: <b>growth</b> is ln σ<sub>max</sub> of the product of the method's one-step maps, over T (a "
            "finite-time Lyapunov exponent of the method: 0 where its map stays bounded, the Floquet exponent "
            "inside a parametric-resonance tongue, ln|R(ih)|/h for RK4 beyond its stability limit); "
            "<b>H_ext_max_abs</b> the largest |H~| = |H + p_t| over the run; <b>det_max_dev</b> the largest "
            "|det M<sub>k</sub> − 1| of the one-step maps; <b>error_final</b> the relative error at T against the "
            "exact flow or a fine RK8 run. Black cells: the run failed (the line below the map says why). The "
            "same grid runs from the command line, also on a Dask cluster: <code>{command}</code>. "
            "<b>Click a cell</b> to open that run in the Orbits view.</p>")
MAP_HEIGHT = 480
LOG_MEASURES = ("H_ext_max_abs", "det_max_dev", "error_final")
LOG_FLOOR = 1e-17


def map_command(plan):
    """The `cosymp sweep` command line of a plan."""
    fixed = "".join(f" --set {k}={v}" for k, v in plan.values)
    vary = "".join(f" --vary {a.name}={a.values[0]:g}:{a.values[-1]:g}:{len(a.values)}" + (":log" if a.log else "")
                   for a in plan.axes)
    theta = f" --theta {plan.theta:g}" if plan.theta is not None else ""
    return (f"cosymp sweep {plan.scene} --method {plan.method}{vary} --measure {' '.join(plan.measures)} "
            f"--h {plan.h:g} --T {plan.T:g}{theta}{fixed} -o map.csv")


def map_plot(result, on_tap):
    """The heat map of a sweep's single measure over its two axes; a tap calls on_tap(i, j)."""
    plan = result.plan
    ax, ay = plan.axes
    key = plan.measures[0]
    Z = result.values[key].T
    log = [ax.log, ay.log]
    opts = {"cmap": "RdBu_r", "colorbar": True, "clipping_colors": {"NaN": "black"}}
    if key in LOG_MEASURES:
        Z = np.where(np.isnan(Z), np.nan, np.maximum(Z, LOG_FLOOR))
        opts.update(cmap="viridis", logz=True)
    else:
        top = float(np.nanmax(np.abs(Z))) if np.any(np.isfinite(Z)) else 1.0
        opts.update(clim=(-top or -1.0, top or 1.0))
    mesh = hv.QuadMesh((np.array(ax.values), np.array(ay.values), Z), kdims=[ax.name, ay.name], vdims=[key])
    mesh = mesh.opts(responsive=True, height=MAP_HEIGHT, logx=log[0], logy=log[1], tools=["hover", "tap"],
                     title=f"{key} of {plan.method} on {plan.scene}", toolbar="right",
                     default_tools=["pan", "wheel_zoom", "box_zoom", "reset", "save"], **opts)
    tap = hv.streams.Tap(source=mesh)

    def nearest(axis, v, is_log):
        vals = np.log(axis.values) if is_log else np.array(axis.values)
        return int(np.argmin(np.abs(vals - (np.log(v) if is_log else v))))

    tap.add_subscriber(lambda x, y: None if x is None or y is None
                       else on_tap(nearest(ax, x, log[0]), nearest(ay, y, log[1])))
    return pn.pane.HoloViews(mesh, sizing_mode="stretch_width", min_height=MAP_HEIGHT + 10)


def map_failures(result):
    if result is None:
        return ""
    failed, first = result.failures()
    if not failed:
        return (f"<p class='doc'>Every one of the {result.plan.size} runs completed ({html.escape(result.where)}, "
                f"{result.wall_s:.1f} s).</p>")
    return (f"<p class='doc'><b>{failed} of {result.plan.size} runs failed</b> (black cells), e.g.: "
            f"{html.escape(first)}</p>")


class StabilityMapView(pn.viewable.Viewer):
    """The Stability map: controls for the two axes and the measure, Start/Cancel with progress,
    the heat map (click a cell to open it), and the runs that failed."""

    stability = param.ClassSelector(class_=StabilityMap)

    def __panel__(self):
        m = self.stability
        row, status = run_controls(m, "Compute map")

        def axis(prefix):
            p = m.param
            return pn.Row(pn.widgets.Select.from_param(p[prefix], width=120),
                          pn.widgets.FloatInput.from_param(p[f"{prefix}_start"], width=110),
                          pn.widgets.FloatInput.from_param(p[f"{prefix}_stop"], width=110),
                          pn.widgets.IntInput.from_param(p[f"n{prefix}"], width=100),
                          pn.widgets.Checkbox.from_param(p[f"{prefix}_log"], margin=(30, 10, 10, 10)))

        def shown(result):
            if result is None:
                return note("<p class='doc'>No map yet: choose the axes and press Compute map.</p>")
            return map_plot(result, m.open_cell)

        return pn.Column(
            note(pn.bind(lambda r: MAP_TEXT.format(command=html.escape(map_command(r.plan)) if r else
                                                   "cosymp sweep SCENE --vary NAME=START:STOP:NUM ..."),
                         m.param.result)),
            pn.widgets.Select.from_param(m.param.measure, width=200),
            axis("x"), axis("y"),
            row, status,
            pn.panel(pn.bind(shown, m.param.result), sizing_mode="stretch_width"),
            note(pn.bind(map_failures, m.param.result)),
            sizing_mode="stretch_width",
        )
