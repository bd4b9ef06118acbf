"""Orbits: phase portraits of both methods, H~ = H + p_t, the error against the exact flow, and
the numbers over every step. It shows the sidebar's comparison (no state of its own)."""
import pandas as pd
import panel as pn

from cosymp.scenes import SCENES

from ..plotting import Pair, Raster, figure, grid, note, pane, path, reset_ranges, table
from .base import Feature, FeatureView
from .common import color_key, comparisons, names, numbers, over_time, phase_axes, zcols

NUMBERS_TEXT = "<h4>Numbers</h4><p class='doc'>From the full-resolution runs: maxima over every step.</p>"


class Figures:
    """The figures of one layout: the scene's portraits (lines, or rasters when dense), H~ and,
    with an exact flow, the error."""

    def __init__(self, scene, dense):
        self.scene = scene
        self.axes = phase_axes(scene)
        self.portraits = []
        for _, _, xl, yl, title in self.axes:
            fig = figure(title, xl, yl)
            self.portraits.append((fig, Raster(fig) if dense else Pair(fig, start=True)))
        self.energy = Pair(figure("H~ = H + p_t (per-bin min and max)", "t", "H + p_t"))
        self.error = Pair(figure("error |z − z_exact|", "t", "|z − z_exact|", logy=True)) \
            if SCENES[scene].has_flow else None
        figs = [f for f, _ in self.portraits] + [self.energy.fig] + ([self.error.fig] if self.error else [])
        self.panes = [pane(f) for f in figs]

    def update(self, runs):
        cs = comparisons(runs)
        for (i, j, *_), (_, drawn) in zip(self.axes, self.portraits):
            drawn.colors(names(runs))
            drawn.set({slot: (zcols(c.run, i, j) if isinstance(drawn, Raster) else path(*zcols(c.run, i, j)))
                       for slot, c in cs.items()})
        self.energy.colors(names(runs))
        self.energy.set(over_time(runs, lambda c: (c.run.t, c.run.H_ext[:, 0])))
        if self.error is not None:
            self.error.colors(names(runs))
            self.error.set(over_time(runs, lambda c: (c.run.t, c.error), logy=True))

    def reset(self):
        for fig, _ in self.portraits:
            reset_ranges(fig)
        for p in (self.energy, self.error):
            if p is not None:
                reset_ranges(p.fig)


class OrbitsView(FeatureView):
    NAME = "compare"

    def layout(self):
        self._figures = {}
        self._shown = None
        self.key = note("")
        self.grid = grid()
        self.remark = note("")
        self.table = table(["quantity"])
        self.follow(self.study, "results")
        return pn.Column(self.key, self.grid, self.remark, note(NUMBERS_TEXT), self.table,
                         sizing_mode="stretch_width")

    def update(self):
        runs = self.study.results
        if runs is None:
            return
        which = (runs.scene, runs.dense)
        figs = self._figures.get(which)
        if figs is None:
            figs = self._figures[which] = Figures(*which)
        if which != self._shown:
            if self._shown is None or self._shown[0] != runs.scene:
                figs.reset()
            self.grid.ncols = 3 if len(figs.panes) == 3 else 2
            self.grid.objects = list(figs.panes)
            self._shown = which
            self.remark.object = "" if SCENES[runs.scene].has_flow else (
                f"<p class='doc'>No closed-form flow for '{runs.scene}', so no error plot (the command line's "
                "<code>cosymp run</code> measures the error at T against a fine RK8 reference).</p>")
        figs.update(runs)
        self.key.object = color_key(runs)
        self.table.value = pd.DataFrame(numbers(runs))


FEATURE = Feature("compare", "Orbits", OrbitsView)
