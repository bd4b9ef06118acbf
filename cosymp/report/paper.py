"""The paper's Sections 4 and 5, figure by figure with its printed parameters, and a
work-precision diagram: `paper_report(progress)` returns the Report.

What it recomputes comes from the scenes' declarations (Scene.paper: the section, the printed
values and the long run): an oscillator section for each such scene, a gauge section for one
with gauges, and a work-precision section for each oscillator."""
from functools import partial

import numpy as np

from .. import workprecision as wp
from ..integrate import Setup
from ..methods import applicable
from ..scenes import SCENES
from ..study import compare, gauge_study
from ..summary import long_envelopes
from . import Figure, Report, Section, Series, Table
from .style import GAUGE_COLORS, method_color, method_marker

SCHEME = "symplectic-euler"
REFERENCE = "rk4"
DELTA = 1e-4
LONG_BINS = 2000
WP_METHODS = ("rk4", "rk8", "midpoint", "symplectic-euler", "gauss4", "gauss6", "leapfrog", "blanes-moan6", "aba864")
GAUGE_QUANTITIES = (("x", "q", 0), ("y", "q", 1), ("p_x", "p", 0), ("p_y", "p", 1), ("Π_x", "Pi", 0), ("Π_y", "Pi", 1))


def kernels(work_precision=True):
    """{scene: the methods its runs use}, for compiling their kernels ahead (cosymp.warm): the
    scheme and RK4 on each oscillator with its exact flow, the scheme in every gauge, and the
    work-precision methods with their reference (the exact flow, or scipy checked against rk8)."""
    out = {}
    for s in SCENES.values():
        if s.paper is None:
            continue
        methods = [SCHEME] if s.has_gauges else [SCHEME, REFERENCE]
        if work_precision and not s.has_gauges:
            methods += applicable(WP_METHODS, s) + ["rk8"]
        out[s.name] = methods + (["exact"] if s.has_flow else [])
    return out


def paper_report(progress=None, long=True, work_precision=True, command="cosymp report paper -o paper.html"):
    """The report; `long=False` and `work_precision=False` leave out the long runs and the
    work-precision diagram (each a Section saying so) for a quick look."""
    printed = [s for s in SCENES.values() if s.paper is not None]
    oscillators = [s for s in printed if not s.has_gauges]
    stages = [("oscillator", s) for s in oscillators] + [("gauges", s) for s in printed if s.has_gauges]
    stages += [("wp", s.name) for s in oscillators] if work_precision else []
    total = len(stages)
    tell = progress or (lambda done, total, what: None)
    sections = []
    for i, (kind, arg) in enumerate(stages):
        if kind == "oscillator":
            tell(i, total, arg.paper.section)
            sections.append(_oscillator(arg, long=long, progress=partial(_percent, tell, i, total)))
        elif kind == "gauges":
            tell(i, total, arg.paper.section)
            sections.append(_gauges(arg))
        else:
            tell(i, total, f"work-precision, {arg}")
            sections.append(_work_precision(arg, partial(_relay, tell, i, total, f"work-precision {arg}")))
    if not work_precision:
        sections.append(Section("Work against precision", ["Left out of this report (--no-work-precision)."]))
    tell(total, total, "done")
    intro = [
        ("Colombo, Martín de Diego, Muradore, Rigo, Sansonetto: discrete-time generalized canonical "
        "transformations for non-autonomous systems. Every figure of the paper's Sections 4 and 5 recomputed "
        "with its printed parameters by cosymp: the paper's implicit symplectic Euler-type scheme (the lifted "
        "θ-method at θ = 0) against RK4. The paper's figures are not in its source, only their captions and "
        "parameters; where its printed formulas needed correcting, the section says so."),
        ("Long runs are shown as per-bin envelopes (the minimum and maximum over each bin of steps), so every "
        "step counts and no peak is lost while the file stays small."),
    ]
    return Report("cosymp: the paper's numerical sections, recomputed", intro, sections, command)


def _percent(tell, i, total, done, steps, what):
    tell(i, total, f"{what} {100 * done / steps:.0f}%")


def _relay(tell, i, total, prefix, done, steps, what):
    tell(i, total, f"{prefix}: {what}")


def _oscillator(scene, long, progress):
    name, title, values = scene.name, scene.paper.section, scene.paper.values
    long_values, T_long = scene.paper.long_values, scene.paper.T_long
    runs = [(m, compare(Setup.make(name, m, values), scene.h, scene.T, delta=DELTA)) for m in (SCHEME, REFERENCE)]
    text = [f"{scene.summary} Printed parameters: h = {scene.h:g}, T = {scene.T:g}"
            + "".join(f", {k} = {v:g}" for k, v in values.items()) + ".", *scene.notes]
    items = [
        Figure("Extended Hamiltonian H + p_t", "t", "H + p_t", [Series(m, c.run.t, c.run.H_ext[:, 0], color=method_color(m)) for m, c in runs],
               caption="The paper's Fig. 'extended Hamiltonian': H + p_t is conserved by the exact flow (0 with "
                       "p_t(0) = −H(z0, 0)). The first-order symplectic scheme's H + p_t oscillates with an "
                       "amplitude set by h and does not grow; fourth-order RK4 errs less at first but drifts, which "
                       "shows over the long run below."),
        Figure("Symplectic form: the paper's estimator ω(X¹, X²)", "t", "ω(X¹, X²)",
               [Series(m, c.run.t[1:], c.paper_omega, color=method_color(m)) for m, c in runs],
               caption="As printed: ω of the one-step increments X = z_(k+1) − z_k of two nearby trajectories "
                       f"(δ = {DELTA:g}). It follows the increments' size, not only the map's structure; the "
                       "rigorous check is below."),
        Figure("|det M_k − 1| and ||M_kᵀ J M_k − J|| (rigorous)", "t", "defect",
               [Series(f"{m} |det M − 1|", c.run.t[:-1], c.det_dev, color=method_color(m)) for m, c in runs]
               + [Series(f"{m} ||MᵀJM − J||", c.run.t[:-1], c.symp_dev, dash=True, color=method_color(m))
                  for m, c in runs], logy=True, zeros=True,
               caption="The one-step tangent maps on the time slice: round-off for the symplectic scheme, not for "
                       "RK4."),
    ]
    if long:
        items += _long_figures(name, long_values, T_long, progress)
    else:
        items.append(Table(["left out"], [[f"the long run to T = {T_long:g} (--quick)"]]))
    return Section(title, text, items)


def _long_figures(name, values, T_long, progress):
    scene = SCENES[name]
    env = {}
    failures = []
    for m in (SCHEME, REFERENCE):
        env[m], failure = long_envelopes(Setup.make(name, m, values), scene.h, T_long, LONG_BINS, DELTA,
                                         lambda d, n, m=m: progress(d, n, f"{name} long run, {m}"))
        if failure:
            failures.append(f"{m}: {failure}")
    setting = ", ".join(f"{k} = {v:g}" for k, v in values.items())
    where = f"h = {scene.h:g}, T = {T_long:g}" + (f", {setting}" if setting else "")
    figs = [
        Figure(f"Volume form over the long run ({where}): the paper's estimator det[X¹ X² X³]", "t", "det",
               [Series(f"{m} {side}", e["t"], e[f"vol_{side}"], dash=side == "min", color=method_color(m))
                for m, e in env.items() for side in ("max", "min")],
               caption="The paper's volume-form figure: det of the increments in (q, t, p) of three nearby "
                       "trajectories, per-bin minimum (dashed) and maximum. It tracks the increments' size (the "
                       "orbit's growth for the damped oscillator as printed)."),
        Figure(f"Extended Hamiltonian over the long run ({where})", "t", "H + p_t",
               [Series(f"{m} {side}", e["t"], e[f"H_{side}"], dash=side == "min", color=method_color(m))
                for m, e in env.items() for side in ("max", "min")],
               caption="Per-bin envelope of H + p_t: bounded for the symplectic scheme, drifting for RK4 (plus the "
                       "round-off of summing p_t over millions of steps). " + drift_against_band(env, T_long)),
        Figure(f"max |det M_k − 1| per bin over the long run ({where})", "t", "|det M_k − 1|",
               [Series(m, e["t"], e["det"], color=method_color(m)) for m, e in env.items()], logy=True, zeros=True,
               caption="The rigorous volume check over every step of the long run."),
    ]
    if failures:
        figs.append(Table(["stopped early"], [[f] for f in failures]))
    return figs


def drift_against_band(env, T):
    """Where RK4's drift of H + p_t stands against the symplectic scheme's band, from the long run's
    envelopes: at the paper's parameters it is still inside at T, which the figure alone makes look
    like RK4's smaller energy error."""
    def reach(e):
        return np.maximum(np.abs(e["H_min"]), np.abs(e["H_max"]))

    if not (len(env[SCHEME]["t"]) and len(env[REFERENCE]["t"])):  # a run that stopped at once
        return ""
    band = float(np.nanmax(reach(env[SCHEME])))
    drift = reach(env[REFERENCE])
    out = np.flatnonzero(drift > band)
    if len(out):
        return (f"RK4's |H + p_t| leaves the symplectic scheme's band (±{band:.2g}) near "
                f"t = {env[REFERENCE]['t'][out[0]]:.3g} and reaches {drift[-1]:.2g} at T.")
    rate = (f": at its average rate so far it would leave the band near t = {T * band / drift[-1]:.2g}, while the "
            "band does not grow." if drift[-1] > 0 else ".")
    return (f"At T = {T:g}, RK4's |H + p_t| ({drift[-1]:.2g}) is still inside the symplectic scheme's band "
            f"(±{band:.2g}){rate}")


def _gauges(scene):
    study = gauge_study(scene, SCHEME, {}, scene.h, scene.T)
    text = [
        (f"{scene.summary} Printed parameters: h = {scene.h:g}, T = {scene.T:g}, the paper's Euler-type scheme in "
        "each gauge (per-gauge runs). Positions and mechanical momenta Π = p − eA agree across gauges up to the "
        "method's error; the canonical momenta p differ by e ∇χ, as they must."),
        ("Corrections: each gauge (original, Coulomb, symmetric, Landau, Lorenz) is built here from its gauge "
        "function χ (A' = A + ∇χ, φ' = φ − ∂_t χ), not transcribed from the paper's printed Hamiltonians:"),
        *scene.notes,
    ]
    items = []
    for name, kind, k in GAUGE_QUANTITIES:
        items.append(Figure(f"{name} in the five gauges", "t", name,
                            [Series(g, *_quantity(study[g]["per-gauge"], kind, k), color=GAUGE_COLORS[g])
                             for g in scene.gauges],
                            caption="The paper's Fig. 'gauge' (trajectories, canonical and mechanical momenta), "
                                    "one curve per gauge; curves that coincide (x, y and Π in every gauge) hide "
                                    "each other: click legend entries to compare."))
    t0, _ = _quantity(study["original"]["per-gauge"], "q", 0)
    for name, kind, k in GAUGE_QUANTITIES:
        base = _quantity(study["original"]["per-gauge"], kind, k)[1]
        series = [Series(g, t0, np.abs(_quantity(study[g]["per-gauge"], kind, k)[1] - base), color=GAUGE_COLORS[g])
                  for g in scene.gauges if g != "original"]
        items.append(Figure(f"|{name} − {name} (original gauge)|", "t", "difference", series, logy=True,
                            caption="The paper's Fig. 'differences with respect to the original gauge': for x, y and "
                                    "Π the per-gauge runs differ at the method's order (the discrete map is not "
                                    "gauge-covariant); the transported map (G_χ applied to the original run) agrees "
                                    "to round-off (tests/test_gauges.py). A gauge whose χ depends on t only leaves x, y and Π unchanged "
                                    "(zero, not drawn)."))
    return Section(scene.paper.section, text, items)


def _quantity(run, kind, k):
    t, q, p, Pi = run
    return t, {"q": q, "p": p, "Pi": Pi}[kind][:, k]


def _work_precision(name, progress):
    methods = applicable(WP_METHODS, SCENES[name])
    rows = wp.measure(name, methods, T=SCENES[name].T, peers=True, max_steps=1 << 17, budget=0.05,
                      progress=progress)
    solvers = list(dict.fromkeys(r["solver"] for r in rows))

    def series(key):
        return [Series(s, [r["wall_s"] for r in rows if r["solver"] == s], [r[key] for r in rows if r["solver"] == s],
                       dash=s.startswith("scipy"), points=True, color=method_color(s), marker=method_marker(s))
                for s in solvers]

    t = wp.targets(rows)
    costs = Table(["solver", "s to error 1e-6", "s to error 1e-9"],
                  [[s, t["cost"][1e-6][s], t["cost"][1e-9][s]] for s in solvers],
                  caption="Wall time to reach each error (log–log interpolation; – where not reached).")
    ratios = Table(["at error", "fastest cosymp method", "scipy DOP853 / fastest", "best symplectic",
                    "best symplectic / rk4"],
                   [[f"{e:.0e}", r["fastest"], r["dop853_over_fastest"], r["best_symplectic"], r["symplectic_over_rk4"]]
                    for e, r in t["ratios"].items()], caption="The ratios of the costs above.")
    scene = SCENES[name]
    return Section(f"Work against precision: {name} (T = {scene.T:g})", [
        ("Each cosymp method over step sizes and scipy's solve_ivp (RK45, DOP853, LSODA) over tolerances on the same "
        f"extended ODE; error at T relative to {rows[0]['reference']}; wall time the minimum of repeated runs "
        "after a warm-up. Not in the paper: it answers what each method costs for its accuracy.")], [
        Figure("Relative error at T against wall time", "wall time (s)", "relative error",
               series("error"), logx=True, logy=True, parametric=True,
               caption="Each line joins one solver's runs in order of step size or tolerance. Markers by family: "
                       "triangles the Runge–Kutta methods, circles the θ-methods (midpoint, symplectic Euler), "
                       "diamonds Gauss–Legendre, hexagons the splittings (leapfrog, Blanes–Moan), crosses the "
                       "near-integrable splitting (aba864, where H0's flow is known), squares scipy's solvers (dashed)."),
        Figure("max |H + p_t| against wall time", "wall time (s)", "max |H + p_t|", series("H_ext_max_abs"),
               logx=True, logy=True, parametric=True),
        costs, ratios])
