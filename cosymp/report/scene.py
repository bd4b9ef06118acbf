"""The report of one comparison: a scene, its parameters, two methods, their views and figures."""
import shlex

import numpy as np

from ..diagnostics import ORBIT_ERROR
from ..errors import RunError
from ..reference import reference_states, unresolved
from ..study import compare_until_failure, drawn_uncertainty, with_reference
from . import Figure, Report, Section, Series, Table
from .style import pair_colors

DELTA = 1e-4
UNCERTAINTY_COLOR = "#868e96"


def command(setups, h, T, out="report.html"):
    """The `cosymp report` command line that reproduces a report of these setups."""
    first, other = setups
    scene = first.scene
    args = ["cosymp", "report", scene.name, "--method", first.method.name, "--vs", other.method.name]
    theta = first.theta if first.theta is not None else other.theta
    if theta is not None:
        args += ["--theta", f"{theta:g}"]
    args += ["--h", f"{h:g}", "--T", f"{T:g}"]
    defaults = {p.name: p.default for p in scene.params}
    for k, v in first.values.items():
        if v != defaults.get(k):
            args += ["--set", f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"]
    return " ".join(shlex.quote(a) for a in args + ["-o", out])


def scene_report(setups, h, T, cmd, progress=None, computed=None):
    """A Report of the setups (method and the method it is compared with) on their scene.
    computed: their (Comparison or None, failure message) pairs if already at hand (the app's)."""
    report = progress or (lambda done, total, what: None)
    scene = setups[0].scene
    total = 2 * len(setups)
    runs = []
    reference = None
    unmeasured = ""  # why no error is measured, where the reference failed (the app says it the same way)
    for i, s in enumerate(setups):
        report(2 * i, total, f"{s.method.label(s.theta)}: run and diagnostics")
        if computed is None:
            c, failure = compare_until_failure(s, h, T, delta=DELTA)  # no carried loop: no figure draws it
        else:
            c, failure = computed[i]
        report(2 * i + 1, total, f"{s.method.label(s.theta)}: reference")
        if c is not None and c.error is None and not unmeasured:  # no exact flow: one reference serves both
            try:
                reference = reference or reference_states(s, h, T)
            except RunError as e:
                unmeasured = f"No error is measured: {e}."
            else:
                c = with_reference(c, reference, h)
        err = float(c.error[-1]) if c is not None and c.error is not None and not failure else None
        runs.append((s, c, failure, err))
    report(total, total, "done")
    values = setups[0].values
    unused = scene.unused(values)  # e.g. B0, eps and w beside a typed beta(t)
    params = Table(["parameter", "value", "meaning"],
                   [[p.name, values[p.name], p.doc] for p in scene.params if p.name not in unused],
                   caption="Parameters" + (f" ({', '.join(unused)}: no effect with these values)" if unused else ""))
    numbers = Table(["method", "max |H + p_t|", "max |det M_k − 1|", "max |M_kᵀ J M_k − J|", "final relative error", "steps",
                     "integration time (s)", "stopped"],
                    [_numbers(s, c, failure, err) for s, c, failure, err in runs],
                    caption="Figures over every step (final relative error |z − z_ref| / |z_ref| against "
                            + (against(runs) or "the exact flow or a reference run")
                            + "; integration time of the run with its nearby trajectories)")
    ok = [(s, c) for s, c, _, _ in runs if c is not None]
    sections = [
        Section("Scene and methods", [scene.summary, "Look for: " + scene.look_for, *scene.notes,
                                      *[f"{s.method.label(s.theta)}: {s.method.doc}." for s in setups]], [params, numbers]),
        Section("Orbits and the extended Hamiltonian", [
            ("The phase portrait of each method and H + p_t along the run (0 for the exact flow; a symplectic "
            "method keeps it bounded, a non-preserving one lets it drift).")], _orbit_figures(scene, ok)),
        Section("Structure", [
            ("|det M_k − 1| and ||M_kᵀ J M_k − J|| of the one-step tangent maps M_k (rigorous: round-off for a "
            f"structure-preserving method), and the paper's estimators as printed: ω(X¹, X²) and {volume_name(scene)} "
            "of the one-step increments of nearby trajectories (they follow the increments' size, so they are "
            "not constant even for a symplectic map). On a linear scene the volume estimator is "
            "(−1)ⁿ h det(M_k − I) det[zⁱ − z¹]: where M_k has the eigenvalue 1 (the charged scene's, twice) "
            "it is 0 for every method and its plot is round-off.")], _structure_figures(scene, ok)),
    ]
    return Report(f"cosymp report: {scene.title}, {' vs '.join(s.method.label(s.theta) for s in setups)}",
                  [f"h = {h:g}, T = {T:g}.", *([unmeasured] if unmeasured else [])], sections, cmd)


def volume_name(scene):
    """The paper's volume estimator for the scene's 2n + 1 increments: det[X¹ X² X³] for one degree
    of freedom, det[X¹ … X⁵] for two."""
    k = 2 * scene.ndof + 1
    sup = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")
    return "det[X¹ X² X³]" if k == 3 else f"det[X¹ … X{str(k).translate(sup)}]"


def _numbers(s, c, failure, err):
    if c is None:
        return [s.method.label(s.theta), np.nan, np.nan, np.nan, np.nan, 0, np.nan, failure]
    n = c.summary
    if failure:  # stopped before T: no error at T (the app's table shows none either; its stop is in 'stopped')
        final = np.nan
    else:
        final = n["final relative error"] if n["final relative error"] is not None else (np.nan if err is None else err)
    own = unresolved(final, None if c.uncertainty is None or failure else float(c.uncertainty[-1]))
    if own:  # the reference is further off than the method: the error says nothing of the method
        final = f"{final:.3g}{own}"
    return [s.method.label(s.theta), n["max |H + p_t|"], n["max |det M_k − 1|"], n["max |M_kᵀ J M_k − J|"], final, n["steps"],
            c.run.wall_s, failure or "no"]


A_ALPHA = 0.7
"""The first method is drawn over the second and slightly transparent, so that the second shows
where they cross (the app's A_ALPHA)."""


def _series(runs, get):
    """One Series per method of get(comparison) -> (x, y), in the methods' colours: the first solid
    and on top, translucent, the second dashed beneath it (as the app draws A over B)."""
    colors = pair_colors(*[st.method.name for st, _ in runs], *([""] if len(runs) < 2 else []))
    return [Series(st.method.label(st.theta), *get(c), dash=i == 1, color=color,
                   alpha=A_ALPHA if i == 0 and len(runs) > 1 else 1.0)
            for i, ((st, c), color) in enumerate(zip(runs, colors))]


def _orbit_figures(scene, runs):
    if scene.ndof > 1:
        a, b = scene.coordinates[:2]
        figs = [Figure(f"Orbit in the ({a}, {b}) plane", a, b, _series(runs, lambda c: (c.run.q[:, 0, 0], c.run.q[:, 0, 1])),
                       parametric=True)]
    else:
        figs = [Figure("Phase portrait", "q", "p", _series(runs, lambda c: (c.run.q[:, 0, 0], c.run.p[:, 0, 0])),
                       parametric=True)]
    figs.append(Figure("Extended Hamiltonian H + p_t", "t", "H + p_t", _series(runs, lambda c: (c.run.t, c.run.H_ext[:, 0]))))
    if all(c.error is not None for _, c in runs):
        # with the reference run's own uncertainty, relative as the errors are (0 at t = 0: drawn from the first step)
        own = drawn_uncertainty([c for _, c in runs])
        drawn = own is not None and not own.side
        figs.append(Figure(f"Trajectory error against {runs[0][1].against}, relative to the orbit's size", "t",
                           ORBIT_ERROR, _series(runs, lambda c: (c.run.t, c.orbit_error))
                           + ([Series("the reference's own uncertainty", own.t, own.y, dash=True, color=UNCERTAINTY_COLOR)]
                              if drawn else []), logy=True, caption=own.text if own else ""))
    return figs


def against(runs):
    """What the runs' errors are measured against (the exact flow, or the reference run), or None."""
    return next((c.against for _, c, _, _ in runs if c is not None and c.against), None)


def _structure_figures(scene, runs):
    return [
        Figure("|det M_k − 1| of the one-step maps", "t", "|det M_k − 1|",
               _series(runs, lambda c: (c.run.t[:-1], c.det_dev)), logy=True, zeros=True),
        Figure("||M_kᵀ J M_k − J|| of the one-step maps", "t", "symplecticity defect",
               _series(runs, lambda c: (c.run.t[:-1], c.symp_dev)), logy=True, zeros=True),
        Figure("The paper's symplectic-form estimator ω(X¹, X²)", "t", "ω(X¹, X²)",
               _series(runs, lambda c: (c.run.t[1:], c.paper_omega))),
        Figure(f"The paper's volume-form estimator {volume_name(scene)}", "t", "det",
               _series(runs, lambda c: (c.run.t[1:], c.paper_volume))),
    ]
