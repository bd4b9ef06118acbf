"""Every figure of the app: built once per page with Bokeh, later changed only by sending data.

A view builds its figures when it is first shown and keeps them; a new result replaces the data of
their sources (one message per update, `push`), so nothing is re-laid-out and a user's zoom is kept
(a scene or layout change sends fresh auto ranges instead). Figure options, colours, tick labels and
the reductions of long series (per-bin envelopes, rasterized portraits) live here, once.

Colours are the methods' own (cosymp.report.style), shared with the reports. Of two compared
methods the first (A) is drawn solid and on top, the second (B) dashed beneath it, so both show
where they overlap (A is slightly transparent, so B shows where the orbits cross; a dense band of A
still hides B).
"""
import html
import math
import re
from functools import cache, lru_cache
from pathlib import Path

import numpy as np
import panel as pn
import quickjs
from bokeh.models import (
    ColumnDataSource,
    CustomJS,
    CustomJSTicker,
    CustomJSTickFormatter,
    DataRange1d,
    Legend,
    LegendItem,
    Span,
)
from bokeh.plotting import figure as bokeh_figure
from panel.io.document import unlocked

from cosymp.report import log_axis_js
from cosymp.report.style import pair_colors
from cosymp.series import FLOOR, envelope, thin, zero_floor

SLOTS = ("A", "B")
A_ALPHA = 0.7  # A is drawn over B, slightly transparent so B shows where they cross
HEIGHT = 260
POINTS = 1200  # a long series is reduced to this many points (per-bin minima and maxima)
PATH_POINTS = 4000  # a phase portrait keeps this many points in order
SCATTERED = 0.3  # a curve whose consecutive points are further apart than this of its extent is drawn as dots
DENSE = 100_000  # a portrait of more recorded states is rasterized
RASTER = (480, 360)
TOOLS = "pan,wheel_zoom,box_zoom,reset,save"
ASSETS = Path(__file__).resolve().parent.parent / "assets"

TICKS = """
const finite = ticks.filter(Number.isFinite);
const lo = Math.min(...finite), hi = Math.max(...finite);
const span = hi - lo, big = Math.max(Math.abs(lo), Math.abs(hi));
const step = finite.length > 1 ? span / (finite.length - 1) : 0;
const nonzero = finite.filter((v) => Math.abs(v) > 1e-9 * step).map(Math.abs);
const exp = big >= 1e5 || (nonzero.length > 0 && Math.min(...nonzero) < 1e-3);  // one form per axis
const alone = (a) => a >= 1e5 || a < 1e-3;
function places(step) {  // the decimals that write every multiple of step exactly
  for (let d = 0; d < 12; d++) if (Math.abs(step * 10 ** d - Math.round(step * 10 ** d)) < 1e-6 * step * 10 ** d) return d;
  return 12;
}
function trim(s) {
  let [m, e] = s.split("e");
  if (m.includes(".")) m = m.replace(/0+$/, "").replace(/\\.$/, "");
  return e === undefined ? m : m + "e" + e.replace("+", "");
}
function fmt(v, step, exp) {
  if (v === 0 || (step > 0 && Math.abs(v) < 1e-9 * step)) return "0";
  const a = Math.abs(v);
  if (!exp) {
    return trim(v.toFixed(step > 0 ? places(step) : 3));
  }
  const mantissa = step > 0 ? Math.min(2, places(step / 10 ** Math.floor(Math.log10(step)))) : 2;
  const digits = step > 0 ? Math.max(1, Math.min(15, Math.floor(Math.log10(a)) - Math.floor(Math.log10(step)) + 1 + mantissa)) : 3;
  return trim(v.toExponential(digits - 1));
}
if (span > 0 && span < 1e-4 * big) {
  // The reference is the tick written with the fewest significant digits (1, not 0.999997), the
  // one nearest the middle among equals; the others are offsets from it. A tick is "written" to a
  // few ulps of its own: BokehJS's 1 can be 0.9999999999999999, which a tolerance of the step
  // alone (5e-17 for steps of 5e-11) read as 17 digits, making 1.00000000005 the reference.
  const sig = (v) => { for (let p = 1; p < 17; p++) if (Math.abs(Number(v.toPrecision(p)) - v) <= Math.max(1e-6 * step, 4 * Number.EPSILON * Math.abs(v))) return p; return 17; };
  const mid = Math.floor(finite.length / 2);
  let at = mid;
  finite.forEach((v, i) => { if ((sig(v) - sig(finite[at]) || Math.abs(i - mid) - Math.abs(at - mid)) < 0) at = i; });
  const ref = finite[at];
  const label = trim(alone(Math.abs(ref)) ? ref.toExponential(11) : ref.toPrecision(12));
  if (tick === ref) return label;
  const d = Math.abs(tick - ref);
  // A short reference is written out (1−3e-6): a bare −3e-6 read as a value near zero.
  return (label.length <= 4 ? label : "") + (tick > ref ? "+" : "\\u2212") + fmt(d, step, alone(d));
}
return fmt(tick, step, exp);
"""
"""Compact tick labels: 4e-4, 1e5, 2500; values that differ only in late digits as offsets from the
roundest tick (1, 1+2e-16; a long reference is written once: 2.408e-11, +1e-14). (A model belongs to one page: each axis gets its own formatter.)"""
@cache
def log_axis_code(call):
    """A Bokeh callback's code that runs the report's log-axis rule (cosymp/report/logaxis.js): its
    functions, then `call`."""
    return f"{log_axis_js()}\nreturn {call};"


def log_ticker():
    """Log-axis ticks: whole decades over 2 decades or more, 1-2-5 under 2, as in the report."""
    return CustomJSTicker(major_code=log_axis_code("logTicks(cb_data.start, cb_data.end)"))


def log_formatter():
    """Log-axis tick labels, as in the report: 1e-5, 0.01, 100, with the digits a narrow axis needs."""
    return CustomJSTickFormatter(code=log_axis_code("logLabel(tick, ticks)"))


def figure(title, x_label="t", y_label="", logx=False, logy=False, height=HEIGHT, aspect=False):
    """A figure with the app's tools, compact ticks and auto ranges that follow the data."""
    fig = bokeh_figure(title=title, height=height, sizing_mode="stretch_width", tools=TOOLS,
                       toolbar_location="right", x_axis_type="log" if logx else "linear",
                       y_axis_type="log" if logy else "linear", x_axis_label=x_label, y_axis_label=y_label,
                       x_range=DataRange1d(), y_range=DataRange1d(), match_aspect=aspect,
                       output_backend="canvas")
    fig.toolbar.autohide = True
    fig.title.text_font_size = "10.5pt"
    for axis, log in ((fig.xaxis, logx), (fig.yaxis, logy)):
        axis.formatter = log_formatter() if log else CustomJSTickFormatter(code=TICKS)
        axis.axis_label_text_font_style = "normal"
        if log:
            axis.ticker = log_ticker()
    fig.min_border_left = 78  # room for "1.2e-15" and the axis label when new data brings wider ticks
    fig.js_on_change("tags", CustomJS(code=RESET_RANGES))
    return fig


RESET_RANGES = "for (const r of [cb_obj.x_range, cb_obj.y_range]) r.reset();"
"""Back to following the data (a DataRange1d stops once the user has zoomed or panned)."""


def reset_ranges(fig):
    """Auto ranges again, from the next data on (after a scene change: a user's zoom of the old
    data goes). A counter in the figure's tags tells the page: new range models would cost the
    server their serialization and the browser new views."""
    fig.tags = [fig.tags[0] + 1 if fig.tags else 1]


def source():
    return ColumnDataSource({"x": np.empty(0), "y": np.empty(0)})


class Pair:
    """The two compared methods' curves (A solid on top, B dashed beneath) on one figure, with an
    optional marker of each curve's first point (`start`) or of every point (`dots`). A is drawn
    translucent, so that B shows where they cross. An `emphasis` (a part of the curves drawn bold
    over them) draws A opaque and B's dashes over it, so that both show where they coincide.
    `orbit`: a curve whose points lie far apart (`scattered`) is drawn as dots of that size, not as
    lines: the chords of a coarse step (implicit midpoint at h = 2.9: two points a turn) filled the
    annulus around the circle its points lie on. `colors(names)` colours them by their methods,
    `set(data)` replaces their data."""

    def __init__(self, fig, width=1.8, start=False, dots=False, emphasis=False, orbit=0):
        self.fig = fig
        self.sources = {slot: source() for slot in SLOTS}
        self.starts = {slot: source() for slot in SLOTS} if start else {}
        self.lines, self.marks = {}, {}
        for slot in SLOTS if emphasis else reversed(SLOTS):
            self.lines[slot] = fig.line("x", "y", source=self.sources[slot], line_width=width,
                                        line_dash="dashed" if slot == "B" else "solid",
                                        line_alpha=A_ALPHA if slot == "A" and not emphasis else 1.0)
            if dots:
                self.marks[slot + "."] = fig.scatter("x", "y", source=self.sources[slot], size=4)
            if orbit:
                self.marks[slot + ":"] = fig.scatter("x", "y", source=self.sources[slot], size=orbit, visible=False,
                                                     marker="circle" if slot == "A" else "square",
                                                     fill_alpha=A_ALPHA if slot == "A" and not emphasis else 1.0)
            if start:
                self.marks[slot] = fig.scatter("x", "y", source=self.starts[slot], size=9, line_color="white")

    def colors(self, names):
        for slot, color in zip(SLOTS, pair_colors(*names)):
            self.lines[slot].glyph.line_color = color
            for key, r in self.marks.items():
                if key[0] == slot:
                    r.glyph.fill_color = color
                    if key[1:] in (".", ":"):
                        r.glyph.line_color = color

    def set(self, data, apart=None):
        """data: {slot: (x, y)} (a missing slot is emptied); apart: {slot: whether its points are drawn
        as dots} for an `orbit` (by default whether they are `scattered`)."""
        for slot in SLOTS:
            x, y = data.get(slot, (np.empty(0), np.empty(0)))
            self.sources[slot].data = {"x": x, "y": y}
            if self.starts:
                self.starts[slot].data = {"x": x[:1], "y": y[:1]}
            dots = self.marks.get(slot + ":")
            if dots is not None:
                dotted = scattered(x, y) if apart is None else apart.get(slot, False)
                if dots.visible != dotted:
                    dots.visible, self.lines[slot].visible = dotted, not dotted


def scattered(x, y):
    """Whether consecutive points of a curve lie far apart: their median distance above SCATTERED of the
    curve's extent (a step of more than about 35 degrees of a circle: fewer than ten points a turn)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return False
    x, y = x[ok], y[ok]
    extent = max(np.ptp(x), np.ptp(y))
    return bool(extent > 0 and np.median(np.hypot(np.diff(x), np.diff(y))) > SCATTERED * extent)


def finite(y):
    """y with its infinities as NaN (a gap in the curve; an infinity would break the axis' range)."""
    y = np.asarray(y, float)
    return np.where(np.isinf(y), np.nan, y)


LINEAR_MAX = 1e300
"""The largest |value| drawn on a linear axis; a larger one is a gap. The page takes an auto range's
span as the difference of its ends: the portrait of 'Damped beyond floating point', from -1.4e308 to
1.5e308 in q, had a span of inf and drew nothing (the same data to 1e300 is an orbit seen blowing up)."""
LOG_RANGE = (1e-250, 1e250)
"""The |values| drawn on a log axis; others are gaps. The page pads a log axis' auto range by a share
of its decades: RK4's |H + p_t| past its stability limit, from 1e-32 to 1e308, ended at 1e325 = inf."""


def drawable(y, log=False):
    """y as drawn on a linear axis (log: on a log axis): infinities, and values out of LINEAR_MAX
    (LOG_RANGE), as NaN. Exact zeros stay (a log axis' series draws them at a floor)."""
    y = np.asarray(y, dtype=float)
    a = np.abs(y)
    with np.errstate(invalid="ignore"):
        out = (a > LOG_RANGE[1]) | ((a > 0) & (a < LOG_RANGE[0])) if log else a > LINEAR_MAX
        return np.where(out, np.nan, y)


DECADES = 1e4  # curves this many times apart in size are drawn as |y| on a log axis


class Curves:
    """Both methods' series over time: on a linear axis, or as |y| on a log axis when the curves are
    decades apart (one method blowing up, or a log quantity). `show(data, names)` takes the
    unreduced {slot: (t, y)} and the methods' names, and draws the series (envelopes). The log
    axis' figure of a linear series is built when first needed: most never need it, and a figure
    costs the server 15-35 ms when its tab is first shown. Once built, both figures stay in the page
    and the inactive one is hidden: a figure taken out of the document and put back comes back with
    the start and end its auto ranges last had, which pins them (the next scene's data, t to 25, was
    drawn on the previous scene's axes, t to 1050, and looked like an empty plot)."""

    def __init__(self, title, x_label, y_label, log=False):
        self.always_log = log
        self.labels = (title, x_label, y_label)
        self.decorations = []
        self.linear = None if log else Pair(figure(title, x_label, y_label))
        self.log = None
        self.active = self.logarithmic() if log else self.linear
        self.panes = {self.active: pane(self.active.fig)}
        self.panel = pn.Column(self.panes[self.active], sizing_mode="stretch_width", margin=0)

    @property
    def sources(self):
        return self.active.sources

    def logarithmic(self):
        """The log axis' Pair (built, and decorated, on the first call)."""
        if self.log is None:
            title, x_label, y_label = self.labels
            self.log = Pair(figure(title if self.always_log else f"{title} (|·|, log axis)",
                                   x_label, y_label if self.always_log else f"|{y_label}|", logy=True))
            for add in self.decorations:
                add(self.log.fig)
        return self.log

    def decorate(self, add):
        """Call add(fig) on each of its figures: those built and those built later."""
        self.decorations.append(add)
        for p in (self.linear, self.log):
            if p is not None:
                add(p.fig)

    def show(self, data, names):
        sizes = [np.nanmax(np.abs(finite(y))) for _, y in data.values() if np.any(np.isfinite(y))]
        typical = [np.nanmedian(np.abs(finite(y))) for _, y in data.values() if np.any(np.isfinite(y))]
        apart = bool(sizes) and min(typical) > 0 and max(sizes) > DECADES * min(typical)
        active = self.logarithmic() if self.always_log or apart else self.linear
        if active is not self.active:
            self.active = active
            if active not in self.panes:
                self.panes[active] = pane(active.fig)
                self.panel.append(self.panes[active])
            for shown, p in self.panes.items():
                p.visible = shown is active
        active.colors(names)
        floor = zero_floor([y for _, y in data.values()]) if active is self.log else FLOOR
        active.set({slot: series(t, y, logy=active is self.log, floor=floor) for slot, (t, y) in data.items()})


def series(x, y, logy=False, floor=FLOOR):
    """A time series for display: the per-bin envelope of at most POINTS points; on a log axis its
    absolute value, exact zeros at `floor`."""
    x, y = envelope(x, drawable(np.abs(y) if logy else y, log=logy), POINTS)
    return x, (drawable(np.where(y == 0, floor, y), log=True) if logy else y)


def peaks(x, y):
    """The maximum of each of at most POINTS bins of a deviation, at FLOOR where it is exactly zero:
    a bound drawn as a clean band, not the noise of round-off."""
    y = drawable(np.maximum(finite(y), FLOOR), log=True)
    if len(y) <= POINTS:
        return np.asarray(x, float), y
    width = math.ceil(len(y) / POINTS)
    padded = np.full(math.ceil(len(y) / width) * width, np.nan)
    padded[:len(y)] = y
    # fmax: NaN only for a bin of gaps, without nanmax's warning for it
    return np.asarray(x, float)[::width], np.fmax.reduce(padded.reshape(-1, width), axis=1)


def path(x, y):
    """A parametric curve (an orbit) thinned to PATH_POINTS points in order."""
    return thin(drawable(x), drawable(y), PATH_POINTS)


class Raster:
    """A dense portrait: the recorded states counted on a pixel grid and shown as an image whose
    opacity grows with the count, one image per method."""

    def __init__(self, fig):
        self.fig = fig
        self.sources = {slot: ColumnDataSource({"image": [], "x": [], "y": [], "dw": [], "dh": []})
                        for slot in SLOTS}
        for slot in reversed(SLOTS):
            fig.image_rgba(image="image", x="x", y="y", dw="dw", dh="dh", source=self.sources[slot])
        self.colors_ = ("#000000", "#000000")

    def colors(self, labels):
        self.colors_ = pair_colors(*labels)

    def set(self, data):
        data = {slot: (drawable(x), drawable(y)) for slot, (x, y) in data.items()}
        pts = [xy for xy in data.values() if len(xy[0])]
        if not pts:
            for s in self.sources.values():
                s.data = {"image": [], "x": [], "y": [], "dw": [], "dh": []}
            return
        xs = np.concatenate([x[np.isfinite(x)] for x, _ in pts])
        ys = np.concatenate([y[np.isfinite(y)] for _, y in pts])
        x0, x1 = _bounds(xs)
        y0, y1 = _bounds(ys)
        for slot, color in zip(SLOTS, self.colors_):
            x, y = data.get(slot, (np.empty(0), np.empty(0)))
            img = rasterize(x, y, (x0, x1), (y0, y1), RASTER, color)
            self.sources[slot].data = {"image": [img], "x": [x0], "y": [y0], "dw": [x1 - x0], "dh": [y1 - y0]}


def _bounds(v):
    if not len(v):
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    pad = 0.02 * (hi - lo) or 0.5 * max(abs(lo), 1e-300)
    return lo - pad, hi + pad


def rasterize(x, y, x_range, y_range, shape, color):
    """RGBA image (uint32, rows from the bottom) of how many points fall in each pixel: the colour
    with an opacity growing with the logarithm of the count."""
    w, h = shape
    ok = np.isfinite(x) & np.isfinite(y)
    i = ((x[ok] - x_range[0]) / (x_range[1] - x_range[0]) * w).astype(np.int64).clip(0, w - 1)
    j = ((y[ok] - y_range[0]) / (y_range[1] - y_range[0]) * h).astype(np.int64).clip(0, h - 1)
    counts = np.bincount(j * w + i, minlength=w * h).reshape(h, w)
    alpha = np.where(counts > 0, 80 + 175 * np.log1p(counts) / math.log1p(max(1, counts.max())), 0)
    r, g, b = (int(color[k:k + 2], 16) for k in (1, 3, 5))
    return (alpha.astype(np.uint32) << 24 | b << 16 | g << 8 | r).astype(np.uint32)


def legend_outside(fig, items):
    """A legend to the right of the plot (never over the data): items [(label, [renderers])]."""
    legend = Legend(items=[LegendItem(label=label, renderers=rs) for label, rs in items], click_policy="hide",
                    label_text_font_size="9pt", spacing=0, padding=4)
    fig.add_layout(legend, "right")
    return legend


def vline(fig, color="#868e96"):
    """A vertical line (a cursor) on the figure; set its `location`."""
    span = Span(location=0.0, dimension="height", line_color=color, line_dash="dashed", line_width=1.5)
    fig.add_layout(span)
    return span


def push(update):
    """Run update() (which changes Bokeh models) so that its changes reach the page as one message.
    While a page's document is being built its changes are simply in it: its first figures arrive
    with their data (they were sent empty and filled by a second message, drawn twice). Once the
    session exists and until the page has loaded, when it has loaded (a background run's first
    results): a change made while the browser pulls the document could be lost for good. BokehJS
    drops a change message that arrives before the document, which it expects to hold the change,
    but the server writes the document it serialised before the change after the change's message
    (a map finished while its page connected was never drawn). The document's map of its models is
    brought up to date once, at the end (Bokeh's freeze; app/graph.py makes it follow what changed),
    even where update() raises: Bokeh's own freeze() stays frozen then, and no model added to the
    page afterwards would have reached it."""
    doc = pn.state.curdoc
    context = getattr(doc, "session_context", None)
    if context is not None and context.session is not None and not pn.state.loaded:
        pn.state.onload(update)
        return
    with unlocked():
        if doc is None:
            update()
            return
        doc.models._push_freeze()
        try:
            update()
        finally:
            doc.models._pop_freeze()


def pane(fig, **kw):
    return pn.pane.Bokeh(fig, sizing_mode="stretch_width", **kw)


def grid(*items, ncols=2):
    return pn.GridBox(*items, ncols=ncols, sizing_mode="stretch_width")


@cache
def stylesheet():
    """The app's CSS, given to each HTML pane (Panel renders components in shadow roots)."""
    return (ASSETS / "app.css").read_text()


KATEX = Path(__file__).resolve().parent / "static" / "katex"
KATEX_URL = "app/static/katex/"  # where the app's server serves KATEX, relative to the page
# KaTeX's renderToString, the one call the server makes of it: inline math, an error shown as the
# source in red (its message in the title) rather than raised, no command that loads or links.
KATEX_CALL = """
var console = {log() {}, warn() {}, error() {}};
function typeset(tex) {
  return katex.renderToString(tex, {displayMode: false, throwOnError: false, strict: "ignore", trust: false});
}
"""


@cache
def katex_css():
    """KaTeX's own stylesheet (app/static/katex: the release whose script typesets, with its
    fonts), its font URLs made relative to the page and woff2 only. Panel inlines a local
    stylesheet, so URLs relative to the sheet's file would not resolve. The font families are
    renamed (cosymp-KaTeX_Main, ...): with the sheet's names, Chromium also fetched the faces of
    Panel's bundled copy (which names files it does not ship: 404s)."""
    css = re.sub(r"(?<![/A-Za-z])KaTeX_", "cosymp-KaTeX_", (KATEX / "katex.min.css").read_text())
    return re.sub(r'url\((fonts/[^)]+)\.woff2\) format\("woff2"\)(,url\([^)]*\) format\("[a-z]+"\))*',
                  rf'url({KATEX_URL}\1.woff2) format("woff2")', css)


@cache
def katex_fonts_css():
    """The @font-face rules of katex_css(), for the document (a shadow root's are not enough)."""
    return "\n".join(re.findall(r"@font-face\{[^}]*\}", katex_css()))


@cache
def katex():
    """KaTeX (app/static/katex/katex.min.js) in a QuickJS interpreter of its own, loaded once per
    process, by the server's first session (25-40 ms). quickjs.Function runs every call on one
    thread of its own, as QuickJS requires; a call stops after 2 s or 64 MB."""
    render = quickjs.Function("typeset", (KATEX / "katex.min.js").read_text() + KATEX_CALL, own_executor=True)
    render.set_time_limit(2)
    render.set_memory_limit(64 << 20)
    return render


@lru_cache(maxsize=256)
def typeset(tex):
    """The HTML of inline math tex, typeset by KaTeX on the server (about 1 ms; the scenes'
    equations come back with their scene). Pages then load no KaTeX script and typeset nothing:
    the script (277 kB) and its typesetting took 40-60 ms of a first page's main thread. Text KaTeX
    cannot typeset shows as its source in red; text that exhausts the interpreter (time or memory)
    as plain text."""
    try:
        return katex()(tex, run_gc=False)
    except quickjs.JSException:
        return f"<code>{html.escape(tex)}</code>"


def equation(tex, **kw):
    """An HTML pane showing the math tex typeset (empty tex: nothing), with KaTeX's stylesheet (and
    Panel's search for TeX to give MathJax off: the HTML is typeset already)."""
    return pn.pane.HTML(typeset(tex) if tex else "", stylesheets=[katex_css()], disable_math=True, **kw)


def note(obj, **kw):
    """An HTML pane with the app's stylesheet."""
    return pn.pane.HTML(obj, stylesheets=[stylesheet()], **{"sizing_mode": "stretch_width", **kw})


def rule():
    """A horizontal rule. Not Panel's Divider: its stylesheet is linked from Panel's CDN unless the
    page's HTML was written by its own session (see page.serve_locally)."""
    return note("<hr class='rule'>")


def swatch(color, label, dashed=False, dotted=False):
    style = f"border-top: 3px {'dashed' if dashed else 'dotted' if dotted else 'solid'} {color}"
    return f"<span class='swatch' style='{style}'></span>{html.escape(label)}"


def table(columns, **kw):
    """A read-only table of the given columns (set its `object` to a DataFrame): a plain HTML table
    written and escaped by pandas. Not Panel's Tabulator: in Panel 1.9 its resize handling can spin
    forever once new data arrives below other models (the page froze when work-precision finished),
    and it costs the browser far more per update."""
    import pandas as pd

    return pn.pane.DataFrame(pd.DataFrame(columns=columns), index=False, escape=True, border=0,
                             stylesheets=[stylesheet()], **{"sizing_mode": "stretch_width", **kw})


def fmt(v, digits=3):
    """A number as a table shows it: compact, – for a missing value."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, (int, np.integer)):
        return f"{v:,}"
    return f"{v:.{digits}g}"
