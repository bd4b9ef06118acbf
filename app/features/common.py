"""What the comparison views share: the two methods' slots, their colour key, the numbers table,
the phase portraits' axes and series taken from a comparison."""
import html
import math

import numpy as np

from cosymp.methods import METHODS
from cosymp.reference import is_resolved, unresolved
from cosymp.report.style import pair_colors
from cosymp.scenes import SCENES
from cosymp.workprecision import ROUNDOFF, roundoff_bound

from ..plotting import PATH_POINTS, SLOTS, fmt, series, swatch

EMPTY = np.empty(0)


def comparisons(runs):
    """{slot: Comparison} of the runs that could be computed."""
    entries = runs.entries if runs is not None else ()
    return {slot: e.comparison for slot, e in zip(SLOTS, entries) if e.comparison is not None}


def names(runs):
    """The two methods' names (their colours)."""
    return tuple(e.method for e in runs.entries) if runs is not None else ("", "")


def record_at(t, when):
    """The index of the record of times `t` nearest `when`, or None where `when` lies beyond the last
    (the run or its carried loop stopped before it) by more than check_step's 1e-9 relative: a run to
    T ends within it (h = 0.03333333333, a link's rounded 10/300, ends 300 steps on at 9.999999999)."""
    if not len(t) or when > t[-1] + 2e-9 * max(abs(when), 1.0):
        return None
    k = int(np.searchsorted(t, when))
    return k - 1 if k == len(t) or (k > 0 and when - t[k - 1] < t[k] - when) else k


def stops_text(runs):
    """Where each run that stopped before T stopped, and why ('' if none did): said beside a view that
    draws them up to a time (Play), where the notice that said it may have gone."""
    parts = [f"{html.escape(e.label)}'s run stopped at t = {e.comparison.run.t[-1]:.6g} ({html.escape(e.failure)})."
             for e in runs.entries if e.failure and e.comparison is not None]
    return f"<p class='doc'>{' '.join(parts)}</p>" if parts else ""


def loops_text(runs):
    """What the tabs drawing the carried loops say of them beside the plots: being computed (they
    follow the runs, LateLoops), or where one stopped ('' otherwise)."""
    if runs.loops_pending:
        return "<p class='doc'><b>The carried loops are being computed</b>: their plots follow.</p>"
    if runs.loops_failure:
        return f"<p class='doc'><b>{html.escape(runs.loops_failure)}</b>.</p>"
    return ""


def color_key(runs, more=""):
    """Which method each curve is (colour, solid A or dashed B), what it preserves, its order; then
    `more` (HTML: another curve's key)."""
    if runs is None:
        return ""
    parts = []
    for i, (e, color) in enumerate(zip(runs.entries, pair_colors(*names(runs)))):
        m = METHODS[e.method]
        theta = e.comparison.setup.theta if e.comparison is not None else None
        theta = 0.5 if theta is None else theta
        parts.append(f"<b>{SLOTS[i]}</b> {swatch(color, e.label, dashed=i == 1)} <span class='doc'>"
                     f"{html.escape(m.title)}; preserves: {html.escape(m.preserves_at(theta))}; order "
                     f"{m.order_at(theta)}</span>")
    return "<div class='colorkey'>" + "&emsp;&emsp;".join(parts + ([more] if more else [])) + "</div>"


BAND_GROWTH = 2.0
RESOLVED = 0.1  # a relative |H + p_t| from which a method no longer follows a growing solution's energy
BIASED = 2.0  # a band within BIASED eps |H| N of N steps is their rounding, accumulated with a bias
APART_BANDS = 2.0  # two symplectic methods' bands closer than this are about as wide
# Trajectory errors from this fraction of the orbit's size on (a phase error of 29 degrees) no longer
# rank two methods by their order: neither follows the solution along its orbit.
PHASE_LOST = 0.5
EARLY = 0.01  # a method leaving the band within this fraction of the run leaves it almost at once


def verdict(runs):
    """One sentence on what the |H + p_t| plot shows, from the data: where a method that preserves
    nothing leaves the band of one that is symplectic (and how far above it its maximum over the
    run's last tenth is), or that it has not (yet) at this T. The band is called bounded only when
    the data show it: its maximum over the run's last tenth is at most BAND_GROWTH times that over
    its first tenth (an adiabatic change of the scene can widen it). A band within round-off of its
    N steps (`within_roundoff`) is called round-off, not wider: rounding accumulates over the steps
    (gauss6 on charged at h = 0.001: 2.3e-14, its last tenth's maximum 9.8 times its first tenth's);
    so is a band that grows but stays within BIASED eps |H| N, where each step's rounding has a bias
    (midpoint at h = 2.9 on modulated: 1.5e-13 over 1000 steps, 9.4 times wider at the end; "rk4
    drifts faster than midpoint" was said of it). Where both methods' are round-off, whatever they
    preserve, the verdict says that neither method's own error shows. Where the band
    grows and |H| with it, the exact solution grows: `growing_verdict` compares relative errors.
    Two symplectic methods: `both_symplectic` compares their bands."""
    kept, lost = {}, {}
    shown = [e for e in (runs.entries if runs is not None else ()) if e.comparison is not None]
    if len(shown) == 2 and not any(e.failure for e in shown) and all(within_roundoff(e.comparison.run) for e in shown):
        return both_roundoff(runs, shown)
    for e in shown:
        kind = preserves(e)
        (kept if kind == "symplectic" else lost if kind == "none" else {})[e.label] = e
    if len(kept) == 2:
        return both_symplectic(runs, shown)
    if len(kept) != 1 or len(lost) != 1:
        return ""
    (p, ke), (n, le) = next(iter(kept.items())), next(iter(lost.items()))
    kr, lr = ke.comparison.run, le.comparison.run
    until = until_text(runs, (le, ke))
    b = Band(ke)
    if b.grown:
        return growing_verdict(until, ke, le, b.grown)
    if b.lost:
        return b.lost_text(until)
    what = b.text()
    drift = np.abs(lr.H_ext[:, 0])
    above = np.flatnonzero(drift > b.size)
    if not above.size:
        orders = [order(e) for e in (le, ke)]
        smaller = (f"the error of {html.escape(n)}'s higher order ({orders[0]} against {orders[1]}) is the smaller"
                   if orders[0] > orders[1] else
                   f"{html.escape(n)}'s error is the smaller, though its order is not higher ({orders[0]} against "
                   f"{orders[1]})")
        return (f"<p class='verdict'>{until}, {html.escape(n)}'s |H + p_t| (at most {np.nanmax(drift):.2g}) "
                f"stays below {what}: at this h and T {smaller}. "
                "Nothing bounds it over longer runs; whether it leaves the band there depends on the scene (the "
                f"Long run tab measures it).{phase_note(ke, le, b.bounded)}</p>")
    end = float(np.nanmax(drift[-max(len(drift) // 10, 1):]))  # not its last value: |H + p_t| oscillates
    left = float(lr.t[above[0]])  # "at t ≈ 0.05" of a run to 2000 read as a moment, where it is at once
    when = f"at t ≈ {left:.3g}" if left > EARLY * float(lr.t[-1]) else f"almost at once (t ≈ {left:.3g})"
    return (f"<p class='verdict'>{html.escape(n)}'s |H + p_t| leaves {what} {when} and ends "
            f"{end / b.size:.3g}× above it (its maximum over the run's last tenth, to t = {lr.t[-1]:g}): "
            + (f"{html.escape(n)}'s is the method's error, {html.escape(p)}'s its steps' rounding." if b.rounding else f"{html.escape(n)} drifts, {html.escape(p)} does not." if b.bounded else
               f"{html.escape(n)} drifts faster than {html.escape(p)}.")
            + (f" {html.escape(p)}'s run stopped at t = {kr.t[-1]:.6g} (see the message): its band is measured up to "
               "there." if ke.failure else "") + f"{phase_note(ke, le, b.bounded)}</p>")


def until_text(runs, entries):
    """How far the verdict's data go: to T (or the last whole step past it), or to where the run that
    stopped first stopped (the others' stops said too). Runs that did not stop end where the first
    entry's does."""
    stopped = sorted((e.comparison.run.t[-1], e.label) for e in entries if e.failure)
    if not stopped:
        run = entries[0].comparison.run
        return f"Up to T = {runs.T:g}" if reached(run, runs.T) else f"Up to t = {past(run.t[-1], runs.T)}"
    earliest = [label for t, label in stopped if t == stopped[0][0]]
    return (f"Up to t = {stopped[0][0]:.6g}, where {html.escape(' and '.join(earliest))} stopped ("
            + "".join(f"{html.escape(label)} stopped at t = {t:.6g}; " for t, label in stopped[len(earliest):])
            + f"see the message{'s' if len(stopped) > 1 else ''})")


class Band:
    """A structure-preserving run's |H + p_t| as the verdict reads it: its largest value (size); how
    much wider it is over the run's last tenth than over its first (growth; the tenths from the first
    step: H + p_t is 0 by construction at t = 0, and a run of fewer than 20 records had that 0 as its
    whole first tenth, a band "5.1e+304× wider" at its end); whether it is the rounding of its steps
    (within round-off, or growing but within BIASED eps |H| N: biased); bounded (growth at most
    BAND_GROWTH, or rounding); grown: how much |H| itself grew where the band is not bounded (0 where
    it did not: then the exact solution grows, `growing_verdict`); lost: whether it reaches RESOLVED
    times the largest |H| (a band that wide bounds nothing)."""

    def __init__(self, entry):
        self.entry = entry
        run = self.run = entry.comparison.run
        err = np.abs(run.H_ext[:, 0])
        self.size = float(np.nanmax(err))
        first, last = tenths(err)
        self.growth = last / max(first, np.finfo(float).tiny)
        self.energy = max_energy(run)
        rounding = within_roundoff(run)
        self.biased = (not rounding and self.growth > BAND_GROWTH
                       and self.size <= BIASED * np.finfo(float).eps * self.energy * run.steps)
        self.rounding = rounding or self.biased
        self.bounded = self.growth <= BAND_GROWTH or self.rounding
        self.grown = 0.0
        if not self.bounded:
            h_first, h_last = tenths(np.abs(run.H[:, 0]))
            self.grown = h_last / h_first if h_last > BAND_GROWTH * h_first else 0.0
        self.lost = self.size >= RESOLVED * self.energy

    def lost_text(self, until):
        p = html.escape(self.entry.label)
        return (f"<p class='verdict'>{until}, {p}'s |H + p_t| reaches {self.size:.2g}, {self.size / self.energy:.2g}× "
                f"the largest |H| of its run ({self.energy:.2g}): at this h it does not follow the solution's energy, "
                "and a band that wide bounds nothing; reduce h before comparing the methods.</p>")

    def text(self):
        """'{method}'s band (size, what it is)'."""
        p, size, steps = html.escape(self.entry.label), self.size, self.run.steps
        if self.biased:
            return (f"{p}'s band ({size:.2g}, its steps' rounding: within {BIASED:g} ε |H| N of its {steps} steps, "
                    f"{self.growth:.2g}× wider in the run's last tenth than in its first, as a rounding bias of each "
                    "step adds up)")
        if self.rounding:
            return f"{p}'s band ({size:.2g}, round-off: within {ROUNDOFF:g} ε |H| √N of its {steps} steps)"
        if self.bounded:
            return f"{p}'s bounded band ({size:.2g})"
        return f"{p}'s band ({size:.2g}, itself {self.growth:.2g}× wider in the run's last tenth than in its first)"


def both_symplectic(runs, entries):
    """The verdict where both methods are symplectic (and not both within round-off of a run to T):
    each keeps |H + p_t| in a band, whose width is what their order and h decide: which is the
    narrower and by how much, whether order explains it, or that the narrower (or both) is only its
    steps' rounding; bands within APART_BANDS of each other are called about as wide. As the
    one-symplectic verdict where either band is lost or the solution's |H| grows."""
    until = until_text(runs, entries)
    bands = [Band(e) for e in entries]
    grown = max(b.grown for b in bands)
    if grown:
        return growing_verdict(until, *entries, grown)
    lost = [b for b in bands if b.lost]
    if lost:
        return lost[0].lost_text(until)
    narrow, wide = sorted(bands, key=lambda b: b.size)
    n, w = html.escape(narrow.entry.label), html.escape(wide.entry.label)
    orders = order(narrow.entry), order(wide.entry)
    text = (f"<p class='verdict'>{until}, both methods are symplectic"
            + (", and each keeps |H + p_t| in a band: " if all(b.bounded for b in bands) else "; their |H + p_t|: ")
            + f"{narrow.text()} and {wide.text()}. ")
    ratio = wide.size / max(narrow.size, np.finfo(float).tiny)
    if wide.rounding:
        text += (f"At this h neither method's own error shows: {w}'s band is its steps' rounding, and {n}'s is "
                 "narrower still.")
    elif narrow.rounding:
        text += (f"{n}'s own error does not show at this h; {w}'s band is its error (order {orders[1]}, "
                 f"{n}'s {orders[0]}).")
    elif ratio < APART_BANDS:
        text += f"The two are about as wide ({times(ratio)}): at this h neither method's order sets it apart."
    else:
        text += (f"{n}'s is {times(ratio)} narrower: "
                 + (f"its higher order ({orders[0]} against {orders[1]})." if orders[0] > orders[1] else
                    f"the same order ({orders[0]}), a smaller error constant." if orders[0] == orders[1] else
                    f"though its order is lower ({orders[0]} against {orders[1]}), at this h its error constant "
                    "is the smaller."))
    for b in bands:
        if b.entry.failure:
            text += (f" {html.escape(b.entry.label)}'s run stopped at t = {b.run.t[-1]:.6g} (see the message): its band "
                     "is measured up to there.")
    if not all(b.bounded for b in bands):
        text += " A band that widens over the run bounds nothing beyond it (the Long run tab measures it)."
    return text + "</p>"


def times(ratio):
    """A ratio as the verdicts say it: 1.04×, 36×, 3,600×."""
    return f"{ratio:.3g}×" if ratio < 10 else f"{ratio:,.0f}×"


def both_roundoff(runs, entries):
    """The verdict where both runs' |H + p_t| are within round-off of their steps (`within_roundoff`),
    whatever the methods preserve: neither method's own error shows."""
    run = entries[0].comparison.run
    until = f"Up to T = {runs.T:g}" if reached(run, runs.T) else f"Up to t = {run.t[-1]:.6g}"
    bands = ", ".join(f"{float(np.nanmax(np.abs(e.comparison.run.H_ext[:, 0]))):.2g} for {html.escape(e.label)}"
                      for e in entries)
    return (f"<p class='verdict'>{until}, both methods' |H + p_t| are round-off (at most {bands}: within "
            f"{ROUNDOFF:g} ε |H| √N of N steps, the size unbiased rounding reaches): at this h neither method's own "
            "error shows." + (" A larger h separates them." if any(preserves(e) == "none" for e in entries) else "")
            + "</p>")


def preserves(entry):
    """What a computed entry's method preserves at its θ (METHODS' `preserves_at`; midpoint's where it
    takes none)."""
    theta = entry.comparison.setup.theta
    return METHODS[entry.method].preserves_at(0.5 if theta is None else theta)


def order(entry):
    """The order of a computed entry's method at its θ (1/2 where it takes none)."""
    theta = entry.comparison.setup.theta
    return METHODS[entry.method].order_at(0.5 if theta is None else theta)


def max_energy(run):
    return float(np.nanmax(np.abs(run.H[:, 0])))


def within_roundoff(run):
    """Whether a run's max |H + p_t| is within round-off of its N steps, ROUNDOFF eps |H| sqrt(N) (the
    rule of work-precision's `at_roundoff`); never where |H| overflowed."""
    bound = roundoff_bound(max_energy(run), max(run.steps, 1))
    return bool(np.isfinite(bound) and np.nanmax(np.abs(run.H_ext[:, 0])) <= bound)


def tenths(x):
    """The maxima of x over its first and its last tenth (from its second record: the first is t = 0)."""
    after = x[1:] if len(x) > 1 else x
    tenth = max(len(after) // 10, 1)
    return float(np.nanmax(after[:tenth])), float(np.nanmax(after[-tenth:]))


def growing_verdict(until, kept, lost, grown):
    """The verdict where |H| itself grows over the run (a parametric resonance, a field that grows:
    the exact solution grows, and both methods' |H + p_t| with it, so neither error is a band): each
    method's |H + p_t| relative to the largest |H| so far, over the run's last tenth. A method whose
    relative error reaches RESOLVED no longer follows the solution's energy; where one does, the two
    are not ranked (an absolute 'drifts faster' ranked a method 100 % wrong above one 2 % wrong)."""
    ends = []
    for e in (kept, lost):
        run = e.comparison.run
        scale = np.fmax.accumulate(np.abs(run.H[:, 0]))
        ends.append(tenths(np.abs(run.H_ext[:, 0]) / np.where(scale > 0, scale, np.inf))[1])
    p, n = (html.escape(e.label) for e in (kept, lost))
    text = (f"<p class='verdict'>{until}, |H| itself grows {grown:.2g}× (the exact solution grows too), and both "
            "methods' |H + p_t| with it: their sizes say little. Relative to the largest |H| so far, "
            f"{p}'s |H + p_t| reaches {ends[0]:.2g} over the run's last tenth and {n}'s {ends[1]:.2g}: ")
    off = [name for name, end in zip((p, n), ends) if end >= RESOLVED]
    if len(off) == 2:
        text += "neither method follows the solution's energy at this h; reduce h before comparing them."
    elif off:
        text += f"{off[0]} no longer follows the solution's energy at this h, {n if off[0] == p else p} does."
    else:
        text += f"both follow the growing solution, {p if ends[0] <= ends[1] else n} the more closely."
    return text + f"{phase_note(kept, lost, False)}</p>"


def largest_error(c):
    """(the comparison's largest trajectory error over its run, relative to the orbit's size, the
    reference's own uncertainty there (0 against the exact flow), and whether the error tells the
    method's order: resolved (reference.is_resolved) and above the rounding of the run's steps,
    BIASED eps N (a rounding of the frequency moves the phase by up to eps a step: gauss6 against rk8
    on kapitza at h = 0.001, 1.8e-13 against 8.7e-14 over 5,000 steps, was called gauss6's lower
    order))."""
    i = int(np.nanargmax(c.orbit_error))
    e = float(c.orbit_error[i])
    own = 0.0 if c.orbit_uncertainty is None else float(c.orbit_uncertainty[i])
    return e, own, is_resolved(e, own) and e > BIASED * np.finfo(float).eps * c.run.steps


def phase_note(kept, lost, bounded):
    """A sentence when the symplectic method's trajectory error is the larger one over the run (a
    method of lower order; over the run, not at T: an error of phase comes back near 0 each time
    the phase has gone round): it says so, and, when its energy error stays in a bounded band (its
    orbit keeps its size), that what it loses is phase: structure preservation bounds the energy
    error, not the phase along the orbit. Where both errors reach PHASE_LOST of the orbit's size,
    it says that neither method follows the solution (an order explains nothing there), and where
    the orders are equal, it claims none."""
    if kept.final_error is None or lost.final_error is None:  # a run stopped early, or no reference
        return ""
    (a, own_a, tells), (b, own_b, _) = (largest_error(e.comparison) for e in (kept, lost))
    if not (tells and a - own_a > b + own_b):  # larger whatever the reference's own error, and not rounding
        return ""
    if b >= PHASE_LOST:
        return (f" Both trajectory errors reach at least half the orbit's size (up to {a:.2g} and {b:.2g} of it): at "
                "this h and T neither method follows the solution along its orbit, and the trajectory error no "
                "longer ranks them; the energy error still does.")
    orders = [order(e) for e in (kept, lost)]
    p = html.escape(kept.label)
    why = (f"of the same order as {html.escape(lost.label)} ({orders[0]}), {p} " if orders[0] == orders[1] else
           f"of order {orders[0]} against {orders[1]}, {p} ")
    return (f" {p}'s trajectory error is the larger, though (up to {a:.2g} against {b:.2g} of the orbit's size "
            f"over the run): {why}"
            + ("runs out of phase along its orbit sooner at this h. What structure preservation bounds is the energy "
               "error, not the phase." if bounded else "follows the trajectory less closely at this h."))


NUMBER_ROWS = ("max |H + p_t|", "max |det M_k − 1|", "max |M_kᵀ J M_k − J|", "final relative error", "steps",
               "integration time, wall clock (s)", "CPU time with diagnostics, its thread (s)")


def numbers(runs):
    """The numbers table (Comparison.summary, maxima over every step) as columns of text."""
    cols = {f"h = {runs.h:g}, T = {runs.T:g}" if runs is not None else "": list(NUMBER_ROWS) + ["run"]}
    for e in runs.entries if runs is not None else ():
        summary = {**(e.comparison.summary if e.comparison is not None else {}),
                   "final relative error": e.final_error}
        cells = [fmt(summary.get(k)) for k in NUMBER_ROWS]
        cells[NUMBER_ROWS.index("final relative error")] += unresolved(e.final_error, e.final_uncertainty)
        cols[e.label] = cells + [e.failure or (ended(e.comparison.run, runs.T) if e.comparison is not None else "")]
    return cols


def reached(run, T):
    """Whether a run that did not stop ended at T, not at the end of its last whole step past T (a
    run takes T/h rounded up steps of h)."""
    return math.isclose(float(run.t[-1]), T, rel_tol=1e-8)


def ended(run, T):
    """Where a run that did not stop reached (`reached`)."""
    return "reached T" if reached(run, T) else f"ran to t = {past(run.t[-1], T)} (T/h is not a whole number)"


def past(t, T):
    """t, the end of a run's last whole step past T, with the digits it takes to differ from T (h =
    0.15 to T = 40000 ends at 40000.05, said as "ran to t = 40000")."""
    for digits in range(6, 18):
        text = f"{t:.{digits}g}"
        if text != f"{T:.{digits}g}":
            return text
    return repr(float(t))


TAIL = 0.02  # the last part of a run drawn bold over its whole orbit in the portraits
PORTRAIT_MARKS = (f"Portraits: a dot at the start, the last {TAIL:.0%} of each run bold; an orbit drawn with fewer "
                  f"than about ten points a turn (a coarse step, or a long run's {PATH_POINTS} points drawn) is drawn "
                  "as those points, not as chords between them.")  # said below them


def tail(x, y):
    """The last TAIL of an orbit (at least two points): where each method ends up, visible even
    when the whole orbits fill the same band."""
    k = max(2, int(np.ceil(TAIL * len(x))))
    return x[-k:], y[-k:]


def phase_axes(scene):
    """(x index, y index, x label, y label, title) of the scene's phase portraits in z = (q, p)."""
    s = SCENES[scene]
    n = s.ndof
    names_ = list(s.coordinates)
    if n == 1:
        return [(0, 1, "q", "p", "phase portrait")]
    return [(0, 1, names_[0], names_[1], f"orbit ({names_[0]}, {names_[1]})")] + [
        (i, n + i, names_[i], f"p_{names_[i]}", f"({names_[i]}, p_{names_[i]})") for i in range(n)]


def zcols(run, i, j):
    """Columns i and j of z = (q, p) of the trajectory."""
    n = run.q.shape[-1]

    def col(k):
        return run.q[:, 0, k] if k < n else run.p[:, 0, k - n]

    return col(i), col(j)


def over_time(runs, get, logy=False):
    """{slot: (t, y)} of get(comparison) -> (t, y) for display (envelopes; |y| on a log axis)."""
    out = {}
    for slot, c in comparisons(runs).items():
        t, y = get(c)
        if y is not None:
            out[slot] = series(t, y, logy)
    return out
