"""cosymp's compiled loops against plain numba loops of the same method on the same scene.

    python benchmarks/plain.py [--steps N] [--repeats R]
    python benchmarks/plain.py --overhead

The plain loops are written per scene, in scalars, the way a user of this field writes them:
the extended state (q, p, t, p_t), so that they do the work cosymp's step must do to give
H + p_t; the Newton of implicit midpoint stops where cosymp's does. Explicit Euler and RK4 are
written out; RK8, the compositions and the splittings loop over their coefficients (aba864, on
modulated only, turns H0 exactly). Each is timed twice: bare (p_t summed plainly, nothing
checked) and guarded, doing what cosymp's loops do besides the method every step: p_t summed
with Kahan's compensation (README, round-off) and the state checked finite (a run stops at an
overflow, with a message). The guarded loop is the like-for-like baseline (the ratio the targets
are read on); the bare one shows what those guarantees cost. Two of cosymp's loops are timed
against them:

* step: `simulate` from the scene's initial state, recording the final state only (the member
  loop of one trajectory, kernels.loops.propagate_one);
* fused: `Drive` with max |H + p_t| (kernels.survey), against the plain loop that also
  evaluates H after every step and keeps max |H + p_t|.

Both run the same steps from the same state, in one process, interleaved, best of R after a
warm-up call; the final states (and max |H + p_t|) must agree to 1e-9.

--overhead: the fixed cost of a call instead, what a run costs beyond its steps (a one-step run
less a hundredth of the 100 steps more of a 101-step one), of `simulate` as a user calls it (its
default stride: every step recorded, H included) and of the plain loop called through numba's
dispatch, in blocks of CALLS calls, interleaved, best of 25 blocks.
"""
import argparse
import math
import time

import numpy as np
from numba import njit

from cosymp.drive import Drive
from cosymp.integrate import Setup, simulate
from cosymp.methods import METHODS as METHOD_TABLE
from cosymp.scenes import SCENES

AGREE = 1e-9
FLAGS = {"cache": False, "fastmath": {"contract"}, "error_model": "numpy"}
NEWTON_TOL = 4e-15


# ---- the scenes in scalars: H, its gradient, dH/dt and d2H/dq2 (both have H_pp = 1, H_qp = 0)

@njit(**FLAGS)
def modulated(P, t, q, p):
    """(H, H_q, H_p, H_t, H_qq) of H = ((1 + eps sin(alpha t)) q^2 + p^2) / 2."""
    w = 1.0 + P.eps * math.sin(P.alpha * t)
    wt = P.eps * P.alpha * math.cos(P.alpha * t)
    return 0.5 * (w * q * q + p * p), w * q, p, 0.5 * wt * q * q, w


@njit(**FLAGS)
def kapitza(P, t, q, p):
    """(H, H_q, H_p, H_t, H_qq) of H = p^2/2 - (w0^2 - a nu^2 cos(nu t)) cos q."""
    g = P.w0 * P.w0 - P.a * P.nu * P.nu * math.cos(P.nu * t)
    gt = P.a * P.nu * P.nu * P.nu * math.sin(P.nu * t)
    s, c = math.sin(q), math.cos(q)
    return 0.5 * p * p - g * c, g * s, p, -gt * c, g * c


# ---- what cosymp's loops also do every step (the `guarded` loops): p_t summed with Kahan's
# compensation (S, Cc), and the state and p_t checked finite (an overflow stops the run)

@njit(**FLAGS)
def add(S, Cc, d, guard):
    """(S, Cc) after adding a step's p_t increment d: S - Cc is p_t (Cc = 0 unguarded)."""
    if not guard:
        return S + d, Cc
    y = d - Cc
    s = S + y
    return s, (s - S) - y


@njit(**FLAGS)
def broken(q, p, S, guard):
    """Whether a guarded loop stops: the state or p_t not finite."""
    return guard and not (math.isfinite(q) and math.isfinite(p) and math.isfinite(S))


# ---- the methods, each a plain loop over n steps of h from (q, p, p_t) at t0

@njit(**FLAGS)
def euler(H, P, t0, h, q, p, pt, n, track, guard):
    hmax, S, Cc = 0.0, pt, 0.0
    for k in range(n):
        _, Hq, Hp, Ht, _ = H(P, t0 + k * h, q, p)
        q, p = q + h * Hp, p - h * Hq
        S, Cc = add(S, Cc, -h * Ht, guard)
        if broken(q, p, S, guard):
            break
        if track:
            hmax = max(hmax, abs(H(P, t0 + (k + 1) * h, q, p)[0] + (S - Cc)))
    return q, p, S - Cc, hmax


@njit(**FLAGS)
def rk4(H, P, t0, h, q, p, pt, n, track, guard):
    hmax, S, Cc = 0.0, pt, 0.0
    for k in range(n):
        t = t0 + k * h
        _, q1, p1, e1, _ = H(P, t, q, p)
        _, q2, p2, e2, _ = H(P, t + 0.5 * h, q + 0.5 * h * p1, p - 0.5 * h * q1)
        _, q3, p3, e3, _ = H(P, t + 0.5 * h, q + 0.5 * h * p2, p - 0.5 * h * q2)
        _, q4, p4, e4, _ = H(P, t0 + (k + 1) * h, q + h * p3, p - h * q3)
        q += h / 6.0 * (p1 + 2.0 * p2 + 2.0 * p3 + p4)
        p -= h / 6.0 * (q1 + 2.0 * q2 + 2.0 * q3 + q4)
        S, Cc = add(S, Cc, -h / 6.0 * (e1 + 2.0 * e2 + 2.0 * e3 + e4), guard)
        if broken(q, p, S, guard):
            break
        if track:
            hmax = max(hmax, abs(H(P, t0 + (k + 1) * h, q, p)[0] + (S - Cc)))
    return q, p, S - Cc, hmax


@njit(**FLAGS)
def explicit(A, b, c, H, P, t0, h, q, p, pt, n, track, guard):
    """Any explicit Runge-Kutta tableau (A row-major)."""
    s = len(b)
    kq, kp = np.empty(s), np.empty(s)
    hmax, S, Cc = 0.0, pt, 0.0
    for k in range(n):
        t = t0 + k * h
        dq = dp = de = 0.0
        for i in range(s):
            yq, yp = q, p
            for j in range(i):
                yq += h * A[i * s + j] * kq[j]
                yp += h * A[i * s + j] * kp[j]
            _, Hq, Hp, Ht, _ = H(P, t + c[i] * h, yq, yp)
            kq[i], kp[i] = Hp, -Hq
            dq += b[i] * Hp
            dp -= b[i] * Hq
            de += b[i] * Ht
        q, p = q + h * dq, p + h * dp
        S, Cc = add(S, Cc, -h * de, guard)
        if broken(q, p, S, guard):
            break
        if track:
            hmax = max(hmax, abs(H(P, t0 + (k + 1) * h, q, p)[0] + (S - Cc)))
    return q, p, S - Cc, hmax


@njit(**FLAGS)
def midpoint_step(H, P, t, h, q, p):
    """One implicit midpoint step, Newton on (q1, p1) from (q, p), stopped as cosymp stops it
    (kernels.families._newton_done); returns (q1, p1, the p_t increment)."""
    q1, p1 = q, p
    prev = math.inf
    for _ in range(50):
        qm, pm = 0.5 * (q + q1), 0.5 * (p + p1)
        _, Hq, Hp, _, Hqq = H(P, t, qm, pm)
        f1 = q - q1 + h * Hp
        f2 = p - p1 - h * Hq
        # Jacobian [[-1, h/2], [-h Hqq/2, -1]] (H_pp = 1, H_qp = 0)
        a, b, c, d = -1.0, 0.5 * h, -0.5 * h * Hqq, -1.0
        det = a * d - b * c
        d1 = -(d * f1 - b * f2) / det
        d2 = -(a * f2 - c * f1) / det
        q1 += d1
        p1 += d2
        size = max(1.0, abs(q1), abs(p1))
        corr = max(abs(d1), abs(d2))
        if corr <= NEWTON_TOL * size or (corr <= 1e-10 * size and corr >= 0.5 * prev):
            break
        prev = corr
    _, _, _, Ht, _ = H(P, t, 0.5 * (q + q1), 0.5 * (p + p1))
    return q1, p1, -h * Ht


@njit(**FLAGS)
def midpoint(H, P, t0, h, q, p, pt, n, track, guard):
    hmax, S, Cc = 0.0, pt, 0.0
    for k in range(n):
        q, p, dpt = midpoint_step(H, P, t0 + (k + 0.5) * h, h, q, p)
        S, Cc = add(S, Cc, dpt, guard)
        if broken(q, p, S, guard):
            break
        if track:
            hmax = max(hmax, abs(H(P, t0 + (k + 1) * h, q, p)[0] + (S - Cc)))
    return q, p, S - Cc, hmax


@njit(**FLAGS)
def composition(gammas, H, P, t0, h, q, p, pt, n, track, guard):
    """Midpoint sub-steps of sizes gammas[i] h."""
    hmax, S, Cc = 0.0, pt, 0.0
    for k in range(n):
        t = t0 + k * h
        d = 0.0
        for g in gammas:
            q, p, dpt = midpoint_step(H, P, t + 0.5 * g * h, g * h, q, p)
            d += dpt
            t += g * h
        S, Cc = add(S, Cc, d, guard)
        if broken(q, p, S, guard):
            break
        if track:
            hmax = max(hmax, abs(H(P, t0 + (k + 1) * h, q, p)[0] + (S - Cc)))
    return q, p, S - Cc, hmax


@njit(**FLAGS)
def splitting(a, b, H, P, t0, h, q, p, pt, n, track, guard):
    """Kick b[i] h at its time (p -= tau V_q, p_t -= tau V_t), then drift a[i] h (q += tau p:
    T = p^2/2 does not depend on t on these two scenes)."""
    hmax, S, Cc = 0.0, pt, 0.0
    for k in range(n):
        t = t0 + k * h
        c = d = 0.0
        for i in range(len(b)):
            if b[i] != 0.0:
                _, Vq, _, Vt, _ = H(P, t + c * h, q, 0.0)
                p -= b[i] * h * Vq
                d -= b[i] * h * Vt
            if a[i] != 0.0:
                q += a[i] * h * p
                c += a[i]
        S, Cc = add(S, Cc, d, guard)
        if broken(q, p, S, guard):
            break
        if track:
            hmax = max(hmax, abs(H(P, t0 + (k + 1) * h, q, p)[0] + (S - Cc)))
    return q, p, S - Cc, hmax


@njit(**FLAGS)
def near(a, b, P, t0, h, q, p, pt, n, track, guard):
    """The modulated oscillator split as H0 = (q^2 + p^2)/2, turned exactly (t moving), and
    H - H0 = eps sin(alpha t) q^2/2, kicked at its time (p_t -= tau (H - H0)_t)."""
    hmax, S, Cc = 0.0, pt, 0.0
    for k in range(n):
        t = t0 + k * h
        c = d = 0.0
        for i in range(len(b)):
            if b[i] != 0.0:
                tau, s = b[i] * h, P.alpha * (t + c * h)
                p -= tau * P.eps * math.sin(s) * q
                d -= tau * 0.5 * P.eps * P.alpha * math.cos(s) * q * q
            if a[i] != 0.0:
                co, si = math.cos(a[i] * h), math.sin(a[i] * h)
                q, p = co * q + si * p, co * p - si * q
                c += a[i]
        S, Cc = add(S, Cc, d, guard)
        if broken(q, p, S, guard):
            break
        if track:
            hmax = max(hmax, abs(modulated(P, t0 + (k + 1) * h, q, p)[0] + (S - Cc)))
    return q, p, S - Cc, hmax


def plain(setup, h, n, track, guard=False):
    """A call of the method's plain loop on the setup's scene from its initial state (with
    `guard`, doing what cosymp's loop also does every step: see add and broken)."""
    D, P, name = setup.data, setup.P, setup.method.name
    H = {"modulated": modulated, "kapitza": kapitza}[setup.scene.name]
    (q0, p0), H0 = setup.start[0], H(P, 0.0, *setup.start[0])[0]
    if name in ("euler", "rk4", "midpoint"):
        loop = {"euler": euler, "rk4": rk4, "midpoint": midpoint}[name]
        return lambda: loop(H, P, 0.0, h, q0, p0, -H0, n, track, guard)
    if name == "rk8":
        c = D.offsets[D.stage]
        return lambda: explicit(D.A, D.b, c, H, P, 0.0, h, q0, p0, -H0, n, track, guard)
    if name == "aba864":
        return lambda: near(D.a, D.b, P, 0.0, h, q0, p0, -H0, n, track, guard)
    if name.startswith("composition"):
        return lambda: composition(D.gammas, H, P, 0.0, h, q0, p0, -H0, n, track, guard)
    return lambda: splitting(D.a, D.b, H, P, 0.0, h, q0, p0, -H0, n, track, guard)


def ours(setup, h, n, track):
    """The same run in cosymp: simulate recording the final state, or the fused Drive."""
    if track:
        def fused():
            drive = Drive(setup, h, every=0, energy=True, maps=False)
            drive.advance(n)
            q, p = drive.Z[0]
            return q, p, drive.PT[0], drive.H_ext_max_abs
        return fused

    def step():
        run = simulate(setup, h, n * h, stride=n)
        return run.q[-1, 0, 0], run.p[-1, 0, 0], run.pt[-1, 0], 0.0
    return step


def best_of(calls, repeats):
    """Minimum seconds of each call over interleaved repeats (after one warm-up call each)."""
    results = [c() for c in calls]
    best = [math.inf] * len(calls)
    for _ in range(repeats):
        for i, c in enumerate(calls):
            start = time.perf_counter()
            c()
            best[i] = min(best[i], time.perf_counter() - start)
    return results, best


CALLS = 2000


def fixed_cost(make, setup, h):
    """Microseconds of a call of make(setup, h, n) beyond its n steps (see --overhead)."""
    one, more = make(setup, h, 1), make(setup, h, 101)
    for _ in range(CALLS):
        one(), more()

    def block(call):
        start = time.perf_counter()
        for _ in range(CALLS):
            call()
        return (time.perf_counter() - start) / CALLS

    best = [math.inf, math.inf]
    for _ in range(25):
        best = [min(b, block(c)) for b, c in zip(best, (one, more))]
    return 1e6 * (best[0] - (best[1] - best[0]) / 100)


def overhead():
    print(f"{'scene':<10} {'method':<9} {'simulate, fixed us':>19} {'plain call, fixed us':>21} {'ratio':>6}")
    for scene, name in (("modulated", "rk8"), ("modulated", "midpoint"), ("kapitza", "rk4"), ("kapitza", "midpoint")):
        setup = Setup.make(scene, name)
        ours_us = fixed_cost(lambda s, h, n: lambda: simulate(s, h, n * h), setup, setup.scene.h)
        plain_us = fixed_cost(lambda s, h, n: plain(s, h, n, False), setup, setup.scene.h)
        print(f"{scene:<10} {name:<9} {ours_us:>19.2f} {plain_us:>21.2f} {ours_us / plain_us:>6.2f}")


METHODS = ("euler", "rk4", "rk8", "midpoint", "composition4", "composition6", "leapfrog", "yoshida4",
           "yoshida6", "blanes-moan4", "blanes-moan6", "mclachlan8", "aba864")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=50_000)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--overhead", action="store_true", help="the fixed cost of a call instead")
    args = parser.parse_args()
    if args.overhead:
        overhead()
        return
    n = args.steps
    print(f"{'':<31} {'ns/step':^26}  {'cosymp /':^15}")
    print(f"{'scene':<10} {'method':<13} {'loop':<6} {'cosymp':>8} {'guarded':>8} {'bare':>8}  "
          f"{'guarded':>7} {'bare':>7}  agree")
    worst = {"guarded": (0.0, ""), "bare": (0.0, "")}
    for scene in ("modulated", "kapitza"):
        for name in METHODS:
            if METHOD_TABLE[name].refusal(SCENES[scene]) is not None:
                continue
            setup = Setup.make(scene, name)
            h = setup.scene.h
            for loop, track in (("step", False), ("fused", True)):
                calls = [ours(setup, h, n, track), plain(setup, h, n, track, guard=True), plain(setup, h, n, track)]
                results, (ta, tg, tb) = best_of(calls, args.repeats)
                agree = all(np.allclose(np.array(results[0], float), np.array(r, float), rtol=AGREE, atol=AGREE)
                            for r in results[1:])
                where = f"{scene} {name} {loop}"
                worst = {"guarded": max(worst["guarded"], (ta / tg, where)), "bare": max(worst["bare"], (ta / tb, where))}
                print(f"{scene:<10} {name:<13} {loop:<6} {1e9 * ta / n:>8.1f} {1e9 * tg / n:>8.1f} {1e9 * tb / n:>8.1f}  "
                      f"{ta / tg:>7.2f} {ta / tb:>7.2f}  {'yes' if agree else 'NO'}")
    for base, (ratio, where) in worst.items():
        print(f"worst ratio to the {base} loop {ratio:.2f} ({where})")


if __name__ == "__main__":
    main()
