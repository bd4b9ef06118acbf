"""Gauges (a scene with a gauge parameter: the charged particle): q, p and Π in the five gauges,
per-gauge runs beside the transported maps, their differences from the original gauge, and
where the paper's gauges do not satisfy the condition their names promise."""
import html

import numpy as np
import panel as pn
import param

from cosymp.errors import RunError
from cosymp.integrate import Setup
from cosymp.methods import METHODS
from cosymp.report.style import GAUGE_COLORS
from cosymp.scenes import SCENES
from cosymp.study import gauge_study

from ..jobs import Note
from ..plotting import equation, figure, grid, note, pane, path, peaks, series, source, swatch
from ..presets import case_state
from ..study import comparison_bytes, theta_for
from .base import Feature, FeatureView, Follower

KINDS = (("per-gauge", "Per-gauge runs", "the method applied in each gauge"),
         ("transported", "Transported runs", "the original gauge's run mapped by G_χ"))
QUANTITIES = {"orbit": ("orbit (x, y)", "x", "y"), "p": ("canonical p_x (gauge-dependent)", "t", "p_x"),
              "Pi": ("mechanical Π_x = p_x − e A_x (gauge-invariant)", "t", "Π_x"),
              "diff": ("|q − q_orig| + |Π − Π_orig|, max per bin", "t", "difference")}


def gauged_scene():
    """The scene this tab studies: the first with gauges (Scene.gauges)."""
    return next(s for s in SCENES.values() if s.has_gauges)


def gauge_figure():
    """The gauged scene's case this tab shows: the one it declares with view 'gauges' (the paper's
    gauge figure, also a link of the sidebar's Paper figures)."""
    return next(c for c in gauged_scene().cases if c.view == "gauges")


def open_gauge_figure(study):
    """Put the study in the state the gauge figure's link opens, in this page: the scene first (a
    change of scene opens the scene's first view, Study._on_change), then the figure's methods, h, T,
    values and the Gauges tab over that first view. (In one update, a value the study already held
    would be no change, and the first view's would stand.)"""
    state = case_state(gauged_scene(), gauge_figure())
    study.scene = state.pop("scene")
    study.param.update(**state)


class GaugeStudy(Follower):
    """The charged particle in all five gauges with the study's method, h, T and parameters."""

    NAME = "gauges"
    KIND = "gauge study"
    WHAT = "the gauge study"
    HOLD = True
    WATCHED = ("scene", "method", "theta", "h", "T", "values")
    results = param.Dict(default=None, allow_None=True, doc="{gauge: {'per-gauge': (t, q, p, Pi), 'transported': ...}}.")
    method = param.String(default="", doc="The method of the results.")

    def applies(self):
        return self.study.scene_obj.has_gauges

    def _inputs(self):
        s = self.study
        s.check_horizon()
        values = {k: v for k, v in s.values.items() if k != "gauge"}
        theta = theta_for(s.method, s.theta)
        setup = Setup.make(s.scene, s.method, values, theta)
        return s.method, values, float(s.h), float(s.T), theta, setup

    def _bytes(self, inputs):
        # bounded above: six single-member runs and five transports use less than one comparison
        return comparison_bytes([inputs[5]], inputs[2], inputs[3])

    def _compute(self, inputs, run):
        method, values, h, T, theta, setup = inputs
        try:
            return METHODS[method].label(theta), gauge_study(setup.scene, method, values, h, T, theta), ""
        except RunError as err:
            return METHODS[method].label(theta), None, str(err)

    def _finish(self, inputs, result):
        label, data, failure = result
        if failure:
            self.say(Note("warning", f"gauge study with {label}: {failure}"))
            return
        self.method = label
        self.results = data

    def _done_in(self, inputs, elapsed):
        """A live view keeps no status line."""


WINDOW = 40  # time scales: the orbit, p and Π plots show the last this many of a run much longer


def shown_from(t):
    """The first time the orbit, p and Π plots show: the run's start, or WINDOW time scales before
    its end where it is longer than 1.5 times that. The first view's 300 time units (100 gyrations)
    drew each as one solid band, in which the gauges' curves could not be told apart."""
    span = WINDOW * gauged_scene().time_scale
    return float(t[-1] - span) if t[-1] - t[0] > 1.5 * span else float(t[0])


def gauge_series(data, kind, quantity):
    """{gauge: (x, y)} of one quantity of every gauge's run (the difference: not the original's);
    the orbit, p and Π from `shown_from` on, the difference over the whole run."""
    out = {}
    for g in data:
        if quantity == "diff" and g == "original":
            continue
        t, q, p, Pi = data[g][kind]
        if quantity != "diff":
            k = np.searchsorted(t, shown_from(t))
            t, q, p, Pi = t[k:], q[k:], p[k:], Pi[k:]
        if quantity == "orbit":
            out[g] = path(q[:, 0], q[:, 1])
        elif quantity == "p":
            out[g] = series(t, p[:, 0])
        elif quantity == "Pi":
            out[g] = series(t, Pi[:, 0])
        else:
            _, q0, _, Pi0 = data["original"][kind]
            out[g] = peaks(t, np.linalg.norm(q - q0, axis=-1) + np.linalg.norm(Pi - Pi0, axis=-1))
    return out


def floor_text(largest):
    """What the difference plots show: their largest values, and the gauges whose difference is
    exactly 0 (drawn at the log axis' floor)."""
    same = [name for name, x in gauged_scene().gauges.items() if name != "original" and not np.any(x.C)]
    text = (f"The two difference plots share their axis. Largest difference from the original gauge: "
            f"{largest.get('per-gauge', 0.0):.1e} per gauge (the "
            f"method's error differs between gauges), {largest.get('transported', 0.0):.1e} transported (round-off:"
            " G_χ maps the run exactly).")
    if same:
        text += (f" {', '.join(same)}: χ depends on t only, so A, the orbit and Π are the original gauge's; "
                 "the difference is exactly 0, drawn at the bottom of the axis.")
    return text


class GaugeView(FeatureView):
    NAME = "gauges"

    def layout(self):
        g = self.state
        gauges = gauged_scene().gauges
        self.sources = {}
        columns, differences = [], []
        for kind, heading, text in KINDS:
            figs = []
            for quantity, (title, xl, yl) in QUANTITIES.items():
                fig = figure(title, xl, yl, logy=quantity == "diff")
                if quantity == "diff":
                    differences.append(fig)
                for name in gauges:
                    if quantity == "diff" and name == "original":
                        continue
                    src = self.sources[kind, quantity, name] = source()
                    fig.line("x", "y", source=src, line_color=GAUGE_COLORS[name], line_width=1.5,
                             line_dash="solid" if name == "original" or quantity == "diff" else "dashed")
                figs.append(pane(fig))
            # One line of heading and one of text each: the two columns' plots start level.
            columns.append(pn.Column(note(f"<h4>{heading}</h4><p class='doc'>{html.escape(text)}</p>"), *figs,
                                     sizing_mode="stretch_width"))
        # The two difference plots on one axis: the transported runs' round-off then lies flat, orders of
        # magnitude below the per-gauge differences (on an axis of its own it filled the plot).
        differences[1].y_range = differences[0].y_range
        rows = [pn.Row(note(f"<b>{name}</b>", width=90, sizing_mode=None),
                       equation(f"\\chi = {x.chi}", width=230),
                       note(f"<span class='doc'>condition: {html.escape(x.condition)}</span>"
                            + (f"<br><span class='caveat'>{html.escape(x.caveat)}</span>" if x.caveat else "")),
                       sizing_mode="stretch_width")
                for name, x in gauges.items()]
        key = "&emsp;".join(swatch(GAUGE_COLORS[name], name, dashed=name != "original") for name in gauges)
        self.method = note("")
        self.follow(g, "results", "method")
        self.study.param.watch(lambda e: self.changed(), "scene")
        button = pn.widgets.Button(name="Open the paper's gauge figure", button_type="primary")
        button.on_click(lambda event: open_gauge_figure(self.study))
        self.away = pn.Column(note(f"<p>The gauge study is about the scene <b>{html.escape(gauged_scene().title)}</b>: "
                                   f"the paper's figure is <b>{html.escape(gauge_figure().name)}</b>.</p>"),
                              button)
        self.floor = note("")
        self.body = pn.Column(self.method, *rows, note(f"<div class='colorkey'>{key}</div>"),
                              grid(*columns), self.floor, sizing_mode="stretch_width")
        return pn.Column(self.away, self.body, sizing_mode="stretch_width")

    def update(self):
        g = self.state
        on = self.study.scene_obj.has_gauges
        self.away.visible, self.body.visible = not on, on
        if not on or g.results is None:
            return
        self.method.object = (f"<p>Method: <b>{html.escape(g.method)}</b>. q and the mechanical momentum Π agree "
                              "across gauges (to the method's order for per-gauge runs, to round-off when "
                              "transported); the canonical momentum p does not.</p>")
        largest = {}
        for kind, *_ in KINDS:
            for quantity in QUANTITIES:
                for name, (x, y) in gauge_series(g.results, kind, quantity).items():
                    self.sources[kind, quantity, name].data = {"x": x, "y": y}
                    if quantity == "diff":
                        largest[kind] = max(largest.get(kind, 0.0), float(np.max(y, initial=0.0)))
        t = next(iter(g.results.values()))["per-gauge"][0]
        start = shown_from(t)
        window = (f" The orbit, p<sub>x</sub> and Π<sub>x</sub> plots show the run's last {t[-1] - start:g} time "
                  f"units (t from {start:g} to {t[-1]:g}): over all of it their curves fill one band. The "
                  "difference plots cover the whole run." if start > t[0] else "")
        self.floor.object = f"<p class='doc'>{html.escape(floor_text(largest))}{window}</p>"


# Not built ahead: ten figures and five equations (a second of the page's time) that only the charged
# particle uses; built ahead once a scene change made them worth it, they froze the page a second later.
FEATURE = Feature("gauges", "Gauges", GaugeView, GaugeStudy, ahead=False)
