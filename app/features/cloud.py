"""Cloud: a loop of initial states carried by each method, and its area over time. It shows the
sidebar's comparison."""
import html

import numpy as np
import panel as pn

from cosymp.report.style import pair_colors

from ..plotting import SLOTS, drawable, figure, grid, note, pane, path, scattered, source
from .base import Feature, FeatureView
from .common import color_key, comparisons, loops_text, names, record_at
from .structure import time_plots, update_plots

CLOUD_TEXT = ("<h4>Phase-space cloud</h4><p class='doc'>A loop of initial states (radius 0.05 around the "
              "initial condition, first coordinate pair) carried by each method (A left, B right), drawn at "
              "t = 0 (light) and at T/4, T/2, 3T/4 and T (dark) over the trajectory (grey). Its area is the "
              "polygon's through the loop's points: a symplectic method keeps it exactly on a linear scene; on a "
              "nonlinear one the flow bends the loop between its points, and the polygon loses area as 1/N² in "
              "its N points for every method (gauss4 on Kapitza's first view: 1 − 1.7e-4 with 64 points, "
              "1 − 1.0e-5 with 256), while the tangent-map checks (Structure) stay at round-off.</p>")


def closed(q, p):
    """A loop's points, closed, as drawn (`drawable`)."""
    return drawable(np.append(q, q[0])), drawable(np.append(p, p[0]))


QUARTERS = ((0.25, "T/4"), (0.5, "T/2"), (0.75, "3T/4"), (1.0, "T"))  # the later loops drawn


def undrawn_text(runs):
    """Which of the later loops the plots' titles name are not drawn, and why: the carried loop
    ends before them, where its run stopped or where the loop itself did (`loops_text`); the loop
    at its end is drawn instead."""
    parts = []
    for slot, e in zip(SLOTS, runs.entries):
        c = e.comparison
        if c is None or c.cloud is None:
            continue
        missing = [label for f, label in QUARTERS if record_at(c.cloud.t, runs.T * f) is None]
        if missing:
            end = c.cloud.t[-1]
            why = " (where its run stopped)" if c.run.t[-1] <= end else ""
            drawn = ", drawn there" if len(c.cloud.t) > 1 else ""
            parts.append(f"{slot}, {html.escape(e.label)}: no loop at {', '.join(missing)}, its carried loop ends at "
                         f"t = {end:.6g}{why}{drawn}.")
    return f"<p class='doc'>{' '.join(parts)}</p>" if parts else ""


GREY = "#ced4da"  # the trajectory beneath the loops


class Snapshots:
    """One method's carried loop: the trajectory (grey), the loop at t = 0 (light) and at T/4, T/2,
    3T/4 and T (dark; one curve broken between loops)."""

    def __init__(self, title):
        self.fig = figure(title, "q1", "p1")
        self.trajectory, self.first, self.later = source(), source(), source()
        # a coarse orbit (a few points a turn) as its points, as Orbits draws it: as a line its chords
        # filled a ring between the radii of the points ('RK4 just past its stability limit', h = 2.9)
        self.orbit = (self.fig.line("x", "y", source=self.trajectory, line_color=GREY, line_width=1),
                      self.fig.scatter("x", "y", source=self.trajectory, color=GREY, size=3, visible=False))
        self.lines = [self.fig.line("x", "y", source=self.first, line_width=2, line_alpha=0.35),
                      self.fig.line("x", "y", source=self.later, line_width=2)]

    def set(self, c, color, T):
        """Method c's trajectory and loops (its colour), these at 0, T/4, T/2, 3T/4 and T but those
        beyond the loop's end, and then the loop at its end (`undrawn_text` says so)."""
        for line in self.lines:
            line.glyph.line_color = color
        empty = {"x": np.empty(0), "y": np.empty(0)}
        self.trajectory.data = empty if c is None else dict(zip("xy", path(c.run.q[:, 0, 0], c.run.p[:, 0, 0])))
        dots = c is not None and scattered(c.run.q[:, 0, 0], c.run.p[:, 0, 0])
        for renderer, shown in zip(self.orbit, (not dots, dots)):
            if renderer.visible != shown:
                renderer.visible = shown
        if c is None or c.cloud is None:  # none, or its loops follow (LateLoops)
            self.first.data = self.later.data = empty
            return
        self.first.data = dict(zip("xy", closed(c.cloud.q[0, :, 0], c.cloud.p[0, :, 0])))
        at = [k for k in (record_at(c.cloud.t, T * f) for f, _ in QUARTERS) if k is not None]
        last = len(c.cloud.t) - 1
        if last > 0 and last not in at:  # the loop ends before T: its last loop is drawn too (`undrawn_text`)
            at.append(last)
        later = [closed(c.cloud.q[k, :, 0], c.cloud.p[k, :, 0]) for k in at] or [(np.empty(0),) * 2]
        gap = np.array([np.nan])
        self.later.data = {"x": np.concatenate([np.concatenate([x, gap]) for x, _ in later]),
                           "y": np.concatenate([np.concatenate([y, gap]) for _, y in later])}


SMALL = 0.05  # loops this small against the trajectory's extent show as dots or dashes
STRETCHED = 10.0  # a loop stretched or squeezed this much in a coordinate is a needle


def shape_note(runs):
    """What a loop's shape at its end is, A's (or else B's) where one reaches T, when the plots alone
    mislead: loops tiny against the trajectory, or stretched into needles. It names the method, and
    the time where the loop ends before T."""
    loops = [(e.label, e.comparison) for e in runs.entries if e.comparison is not None and e.comparison.cloud is not None]
    if not loops:
        return ""
    reaching = [(n, c) for n, c in loops if record_at(c.cloud.t, runs.T) is not None]
    name, c = (reaching or loops)[0]
    when = "At T," if reaching else f"At t = {c.cloud.t[-1]:.6g}, where it ends,"
    q, p = c.cloud.q[:, :, 0], c.cloud.p[:, :, 0]
    width = np.ptp(q, axis=1)
    height = np.ptp(p, axis=1)
    if not (np.all(np.isfinite(width[[0, -1]])) and np.all(np.isfinite(height[[0, -1]])) and width[0] > 0
            and height[0] > 0):
        return ""
    wide, tall = width[-1] / width[0], height[-1] / height[0]
    span = max(np.ptp(finite_part(c.run.q[:, 0, 0])), np.ptp(finite_part(c.run.p[:, 0, 0])), 1e-300)
    parts = []
    if max(wide, 1 / wide, tall, 1 / tall) > STRETCHED:
        shape = " (stretched one way, squeezed the other: a needle)" if (wide - 1) * (tall - 1) < 0 else ""
        parts.append(f"{when} {html.escape(name)}'s loop is {wide:.3g}× as wide (q1) and {tall:.3g}× as tall (p1) as "
                     f"at t = 0{shape}.")
    if max(width[-1], height[-1]) < SMALL * span:
        parts.append("The loops are small against the trajectory at this scale (zoom in with the mouse wheel "
                     "to see one).")
    if not parts:
        return ""
    return ("<p class='doc'>" + " ".join(parts) + " What a symplectic method keeps is the loop's action ∮ p·dq "
            "(its area in one degree of freedom), below.</p>")


def finite_part(x):
    x = x[np.isfinite(x)]
    return x if x.size else np.zeros(1)


def loops(runs, snapshots):
    cs = comparisons(runs)
    for (slot, snap), color in zip(snapshots.items(), pair_colors(*names(runs))):
        snap.set(cs.get(slot), color, runs.T)


class CloudView(FeatureView):
    NAME = "cloud"

    def layout(self):
        self.snapshots = {slot: Snapshots(f"{slot}: loop at t = 0 (light), T/4, T/2, 3T/4, T (dark)") for slot in SLOTS}
        self.plots = time_plots(["area"])
        self.key = note("")
        self.shape = note("")
        self.follow(self.study, "results")
        return pn.Column(self.key, note(CLOUD_TEXT), grid(*[pane(s.fig) for s in self.snapshots.values()]),
                         self.shape, grid(self.plots["area"].panel), sizing_mode="stretch_width")

    def update(self):
        runs = self.study.results
        if runs is None:
            return
        loops(runs, self.snapshots)
        update_plots(self.plots, runs)
        self.key.object = color_key(runs)
        self.shape.object = loops_text(runs) + undrawn_text(runs) + shape_note(runs)


FEATURE = Feature("cloud", "Cloud", CloudView)
