"""Orbits: phase portraits of both methods, their error split in two (the energy error |H~| =
|H + p_t| over the run, and the trajectory's relative error against the exact flow or a reference
run), and the numbers over every step. It shows the sidebar's comparison."""
import html
from functools import partial

import numpy as np
import pandas as pd
import panel as pn

from cosymp.diagnostics import ORBIT_ERROR
from cosymp.scenes import SCENES
from cosymp.study import drawn_uncertainty

from ..plotting import (
    SLOTS,
    Pair,
    Raster,
    figure,
    grid,
    note,
    pane,
    path,
    peaks,
    reset_ranges,
    scattered,
    source,
    swatch,
    table,
)
from ..study import LATE_REFERENCE_STEPS
from .base import Feature, FeatureView
from .common import (
    EMPTY,
    PORTRAIT_MARKS,
    color_key,
    comparisons,
    names,
    numbers,
    over_time,
    phase_axes,
    tail,
    verdict,
    zcols,
)

NUMBERS_TEXT = ("<h4>Numbers</h4><p class='doc'>From the full-resolution runs: maxima over every step. The times are "
                "this comparison's: each method's run together with the 2n + 1 nearby trajectories of its volume "
                "form, beside the other method's and the reference run on this server's cores; not what a method "
                "costs alone, which Work–precision measures (the best of repeated runs, each alone).</p>")
FLOOR_COLOR = "#868e96"
APART = 1e3  # two orbits whose sizes differ by more than this are drawn in portraits of their own


def apart(runs):
    """Whether the two methods' orbits differ so much in size (one blowing up) that one portrait
    would hide the smaller."""
    sizes = []
    for c in comparisons(runs).values():
        z = c.run.z[:, 0]
        z = z[np.isfinite(z)]
        sizes.append(np.max(np.abs(z)) if z.size else 0.0)
    return len(sizes) == 2 and min(sizes) > 0 and max(sizes) > APART * min(sizes)


def shape(scene, dense, split):
    """What a layout's figures depend on: scenes of one shape share them, relabelled (new figures
    cost the server 10-20 ms each, and figures shown or hidden the browser a layout of the page)."""
    return len(phase_axes(scene)), dense, split


class Figures:
    """The figures of one layout shape: the portraits (lines, or rasters when dense; one per
    method when their sizes are far apart), max |H~| per bin and the relative error (against the
    exact flow or the reference run; empty where there is neither). `label(scene)` titles them for
    a scene."""

    def __init__(self, portraits, dense, split):
        self.split = split
        self.scene = None
        self.portraits = []
        self.tails = []
        for _ in range(portraits):
            for slot in (SLOTS if split else (None,)):
                fig = figure("")
                self.portraits.append((slot, fig, Raster(fig) if dense else Pair(fig, start=True, orbit=4)))
                self.tails.append(Pair(fig, width=3.2, emphasis=True, orbit=8))
        # The error split in two, each titled by what it measures: the energy error (what structure
        # preservation bounds) beside the trajectory error (which also counts the phase, where order
        # wins). One title for every scene (a changed title makes the page lay out the tab): what
        # the trajectory is measured against is said below the plots (remark). Titles short enough for
        # three plots a row on a 1280-pixel projector (longer ones were cut: "energy error: max |H + p_t|
        # per bi"); the axes say what is drawn.
        self.energy = Pair(figure("energy error |H + p_t|", "t", "max |H + p_t| per bin", logy=True))
        self.error = Pair(figure("trajectory error", "t", ORBIT_ERROR, logy=True))
        # the reference run's own uncertainty, relative as the errors are: below it they are not resolved
        self.floor = source()
        self.error.fig.line("x", "y", source=self.floor, line_color=FLOOR_COLOR, line_dash="dotted", line_width=2)
        figs = [f for _, f, _ in self.portraits] + [self.energy.fig, self.error.fig]
        self.grid = grid(*[pane(f) for f in figs], ncols=3 if len(figs) in (3, 6) else 2)

    def label(self, scene):
        """Titles and axis labels for the scene's portraits, and fresh ranges for its data."""
        self.scene = scene
        self.axes = phase_axes(scene)
        per_axis = len(SLOTS) if self.split else 1
        for k, (slot, fig, _) in enumerate(self.portraits):
            _, _, xl, yl, title = self.axes[k // per_axis]
            fig.title.text = title if slot is None else f"{slot}: {title}"
            fig.xaxis.axis_label, fig.yaxis.axis_label = xl, yl
        self.reset()

    def update(self, runs, own):
        """Draw the runs, and the reference's uncertainty `own` (study.drawn_uncertainty)."""
        cs = comparisons(runs)
        per_axis = len(SLOTS) if self.split else 1
        for k, ((slot, _, drawn), last) in enumerate(zip(self.portraits, self.tails)):
            i, j = self.axes[k // per_axis][:2]
            drawn.colors(names(runs))
            last.colors(names(runs))
            shown = {s: c for s, c in cs.items() if slot is None or s == slot}
            paths = {s: (zcols(c.run, i, j) if isinstance(drawn, Raster) else path(*zcols(c.run, i, j)))
                     for s, c in shown.items()}
            drawn.set(paths)
            # the last part drawn as its whole orbit is: dots where that is (its fewer points lie further apart)
            last.set({s: path(*tail(*zcols(c.run, i, j))) for s, c in shown.items()},
                     apart={s: not isinstance(drawn, Raster) and scattered(*xy) for s, xy in paths.items()})
        self.energy.colors(names(runs))
        # From the first step: H + p_t is 0 by construction at t = 0, and drawn at FLOOR it stretched
        # the log axis over a dozen empty decades.
        self.energy.set({slot: peaks(c.run.t[1:], np.abs(c.run.H_ext[1:, 0])) for slot, c in cs.items()})
        self.error.colors(names(runs))
        self.error.set(over_time(runs, lambda c: (c.run.t[1:], c.orbit_error[1:]) if c.error is not None
                                 else (None, None), logy=True))  # 0 at t = 0
        # An empty frame says why in its title (retitled only then: a new title lays the tab out)
        title = ("trajectory error" if any(c.error is not None for c in cs.values()) else
                 "trajectory error (computing…)" if runs.awaits is not None else "trajectory error: see below")
        if self.error.fig.title.text != title:
            self.error.fig.title.text = title
        x, y = peaks(own.t, own.y) if own and not own.side else (EMPTY, EMPTY)
        self.floor.data = {"x": x, "y": y}

    def reset(self):
        for _, fig, _ in self.portraits:
            reset_ranges(fig)
        for p in (self.energy, self.error):
            reset_ranges(p.fig)


SPLIT = ("Two errors. <b>Energy</b>: |H + p_t|, 0 for the exact flow, which a structure-preserving method keeps in "
         "a bounded band. <b>Trajectory</b>: |z − z_ref| {against}, which also counts how far along its orbit each "
         "method has run (its phase): there a higher order wins. It is divided by the orbit's size so far, the "
         "largest |z_ref| up to t (|z_ref| itself passes near 0 on an orbit stretched as the damped oscillator's); "
         "the table's final relative error divides by |z_ref| at T.")

OWN_KEY = swatch(FLOOR_COLOR, "the reference's own uncertainty (trajectory error)", dotted=True)


def remark(runs, own, done=0.0):
    """How the portraits mark a run, the two errors the plots split, and what the trajectory is
    measured against: the exact flow, or a reference run for a scene without one, with its own
    uncertainty `own` (study.drawn_uncertainty); a reference computed after the runs are shown
    (runs.awaits) is said to be under way, `done` its fraction; one too long for a live view is
    said to be left out."""
    against = next((e.comparison.against for e in runs.ok if e.comparison.against), None)
    if SCENES[runs.scene].has_flow:
        errors = SPLIT.format(against="against the exact flow")
    elif runs.reference_failure:  # said here too: the message's notice goes after a few seconds
        errors = (f"No closed-form flow for this scene, and no trajectory error: "
                  f"{html.escape(runs.reference_failure)}.")
    elif runs.awaits is not None:
        errors = (f"No closed-form flow for this scene: the trajectory error is measured against a reference run, "
                  f"{runs.awaits.label}, {runs.awaits.steps:.3g} steps, longer than a live view computes with its "
                  f"runs. It is being computed ({100 * done:.0f} % done): the trajectory error and the final errors "
                  "follow.")
    elif against is None:
        errors = (f"No closed-form flow for this scene, and its reference would take more than "
                  f"{LATE_REFERENCE_STEPS:.0e} rk8 steps here: no trajectory error plot; the report or "
                  "<code>cosymp run</code> measure the final error.")
    else:
        errors = SPLIT.format(against=f"against a reference run, {against}, as in the report (this scene has no "
                                      "closed-form flow)") + (f" {own.text}" if own else "")
    return f"<p class='doc'>{PORTRAIT_MARKS} {errors}</p>"


class OrbitsView(FeatureView):
    NAME = "compare"

    def layout(self):
        self._figures = {}
        self._shown = None
        self.key = note("")
        self.grids = pn.Column(sizing_mode="stretch_width", margin=0)
        self.remark = note("")
        self.table = table([""])
        self.study.param.watch(self._on_results, "results")
        self.study.late.param.watch(lambda event: self._progress(), ["progress"])
        return pn.Column(self.key, self.grids, self.remark, note(NUMBERS_TEXT), self.table,
                         sizing_mode="stretch_width")

    def figures(self, key):
        """The figures of a layout shape: they join the page once, then are shown or hidden."""
        if key not in self._figures:
            figs = self._figures[key] = Figures(*key)
            figs.grid.visible = False
            self.grids.append(figs.grid)
        return self._figures[key]

    def ahead(self):
        """Besides the data, the figures of every scene's usual shape (one or two degrees of
        freedom), hidden, one shape a step: a scene change to another shape then shows them, and
        builds nothing."""
        shapes = dict.fromkeys(shape(name, False, False) for name in SCENES)
        return super().ahead() + [partial(self.figures, key) for key in shapes]

    def _on_results(self, event):
        """Redraw, unless only the runs' carried loops changed (LateLoops): nothing here draws them."""
        if event.new is None or not event.new.only_loops_differ(event.old):
            self.changed()

    def _progress(self):
        """The awaited reference's progress, in the text under the plots."""
        runs = self.study.results
        if self.visible and runs is not None and runs.awaits is not None:
            self.remark.object = remark(runs, None, self.study.late.progress)

    def update(self):
        runs = self.study.results
        if runs is None:
            return
        which = (runs.scene, runs.dense, apart(runs))
        figs = self.figures(shape(*which))
        if self._shown is None or self._shown[0] != runs.scene or figs.scene != runs.scene:
            figs.label(runs.scene)
        for other in self._figures.values():
            other.grid.visible = other is figs
        self._shown = which
        own = drawn_uncertainty(comparisons(runs).values())
        self.remark.object = remark(runs, own, self.study.late.progress)
        figs.update(runs, own)
        self.key.object = color_key(runs, OWN_KEY if own and not own.side else "") + verdict(runs)
        self.table.object = pd.DataFrame(numbers(runs))


FEATURE = Feature("compare", "Orbits", OrbitsView)
