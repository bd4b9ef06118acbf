"""Structure: volume and symplectic form of both methods, the paper's estimators beside the
rigorous checks. It shows the sidebar's comparison."""
import numpy as np
import pandas as pd
import panel as pn

from ..plotting import Curves, grid, note, table
from .base import Feature, FeatureView
from .common import color_key, comparisons, loops_text, names, numbers
from .orbits import NUMBERS_TEXT

VOLUME_TEXT = ("<h4>Volume form</h4><p class='doc'>Left, the paper's estimator as printed: the determinant "
               "of the one-step increments X<sup>i</sup> = z<sup>i</sup><sub>k+1</sub> − z<sup>i</sup><sub>k</sub> "
               "of 2n+1 nearby runs in (q, t, p) (three for one degree of freedom). Right, the rigorous "
               "check: |det M<sub>k</sub> − 1| of the one-step tangent map on the time slice, 0 to round-off "
               "for a volume-preserving method (exact zeros are drawn at 1e-17, or a decade below the smallest nonzero value). "
               "On a linear scene the increments' differences are (M<sub>k</sub> − I)(z<sup>i</sup> − z<sup>1</sup>), "
               "so the estimator is (−1)<sup>n</sup> h det(M<sub>k</sub> − I) det[z<sup>i</sup> − z<sup>1</sup>]: "
               "on the charged scene M<sub>k</sub> has the eigenvalue 1 (twice), the estimator is 0 for every "
               "method, and its plot shows round-off, not the method: the rounding of the increments, "
               "many decades apart between methods and step sizes (1e-48 to 1e-22 on this scene's "
               "presets).</p>")
SYMPLECTIC_TEXT = ("<h4>Symplectic form</h4><p class='doc'>The paper's estimator as printed: ω(X¹, X²) of "
                   "the one-step increments of two nearby runs. Rigorous checks: max |M<sub>k</sub>ᵀ J "
                   "M<sub>k</sub> − J| of the one-step tangent map (0 to round-off when symplectic), "
                   "ω(δ¹, δ²)/δ² of the separations δ<sup>i</sup> = z<sup>i</sup> − z<sup>0</sup> of "
                   "two nearby runs started δ = 1e-4 away along q₁ and along p₁, and the area enclosed "
                   "by a carried loop of initial states (radius 0.05): both stay 1 for a symplectic method while the flow keeps them small, and "
                   "drift for every method once it stretches them past its linear range (kapitza's "
                   "fast-driven pendulum), where only the tangent-map checks still tell the methods "
                   "apart.</p>")

# (title, value label, log axis, the series of a comparison)
PLOTS = {
    "energy": ("H~ = H + p_t", "H + p_t", False, lambda c: (c.run.t[1:], c.run.H_ext[1:, 0])),  # 0 at t = 0
    "paper_volume": ("paper's estimator: det[X¹ … X²ⁿ⁺¹]", "det[X¹ … X²ⁿ⁺¹]", False,
                     lambda c: (c.run.t[1:], c.paper_volume)),
    "det": ("rigorous: |det M_k − 1|", "|det M_k − 1|", True, lambda c: (c.run.t[:-1], c.det_dev)),
    "paper_omega": ("paper's estimator: ω(X¹, X²)", "ω(X¹, X²)", False, lambda c: (c.run.t[1:], c.paper_omega)),
    "symp": ("rigorous: max |M_kᵀ J M_k − J|", "|M_kᵀ J M_k − J|", True, lambda c: (c.run.t[:-1], c.symp_dev)),
    "separation": ("rigorous: ω(δ¹, δ²)/δ² of nearby runs", "ω(δ¹, δ²) / δ²", False,
                   lambda c: (c.run.t, c.separation_omega)),
    "area": ("carried loop: area / initial area", "area / initial area", False,
             lambda c: (c.cloud.t, c.cloud_area) if c.cloud is not None else (np.empty(0), np.empty(0))),
}


def time_plots(keys, log=()):
    """{key: Curves} of the PLOTS named; those in `log` on a log axis from the start whatever PLOTS says."""
    return {k: Curves(PLOTS[k][0], "t", PLOTS[k][1], log=PLOTS[k][2] or k in log) for k in keys}


def update_plots(plots, runs):
    for k, p in plots.items():
        get = PLOTS[k][3]
        p.show({slot: get(c) for slot, c in comparisons(runs).items()}, names(runs))


class StructureView(FeatureView):
    NAME = "structure"

    def layout(self):
        self.plots = time_plots([k for k in PLOTS if k != "energy"])
        self.key = note("")
        self.loops = note("")
        self.table = table(["quantity"])
        self.follow(self.study, "results")
        return pn.Column(
            self.key, note(VOLUME_TEXT),
            grid(*[self.plots[k].panel for k in ("paper_volume", "det")]),
            note(SYMPLECTIC_TEXT), self.loops,
            grid(*[self.plots[k].panel for k in ("paper_omega", "symp", "separation", "area")]),
            note(NUMBERS_TEXT), self.table, sizing_mode="stretch_width")

    def update(self):
        runs = self.study.results
        if runs is None:
            return
        update_plots(self.plots, runs)
        self.key.object = color_key(runs)
        self.loops.object = loops_text(runs)
        self.table.object = pd.DataFrame(numbers(runs))


FEATURE = Feature("structure", "Structure", StructureView)
