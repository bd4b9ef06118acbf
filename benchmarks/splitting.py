"""The splitting methods' cost per step in cosymp against a plain numba loop of the same method.

    python benchmarks/splitting.py [--steps N] [--repeats R]

The plain loops are written for one scene each (modulated and kapitza), in the form a user of
this field would write them: time as a coordinate, kicks at their times, drifts, and the p_t
increment of each kick (-tau dV/dt; the drifts leave p_t alone, T = p^2/2 does not depend on t),
so that they do the same work as cosymp's step, which must track p_t for H + p_t. Both run the
same steps from the same state; the final states must agree to round-off. Times are the minimum
over interleaved repeats after a warm-up, in one process, and the ratio is taken within a run.
"""
import argparse
import math
import time

import numpy as np
from numba import njit

from cosymp.integrate import Setup, simulate
from cosymp.methods import METHODS

AGREE = 1e-10


@njit(cache=False, fastmath={"contract"}, error_model="numpy")
def plain_modulated(a, b, eps, alpha, q, p, t0, h, n):
    pt = 0.0
    for k in range(n):
        t = t0 + k * h
        c = 0.0
        for i in range(len(b)):
            if b[i] != 0.0:
                tau, tk = b[i] * h, t + c * h
                p -= tau * (1.0 + eps * math.sin(alpha * tk)) * q
                pt -= tau * 0.5 * eps * alpha * math.cos(alpha * tk) * q * q
            if a[i] != 0.0:
                q += a[i] * h * p
                c += a[i]
    return q, p, pt


@njit(cache=False, fastmath={"contract"}, error_model="numpy")
def plain_kapitza(a, b, w0, amp, nu, q, p, t0, h, n):
    pt = 0.0
    for k in range(n):
        t = t0 + k * h
        c = 0.0
        for i in range(len(b)):
            if b[i] != 0.0:
                tau, tk = b[i] * h, t + c * h
                p -= tau * (w0 * w0 - amp * nu * nu * math.cos(nu * tk)) * math.sin(q)
                pt += tau * amp * nu * nu * nu * math.sin(nu * tk) * math.cos(q)
            if a[i] != 0.0:
                q += a[i] * h * p
                c += a[i]
    return q, p, pt


def plain(setup, h, n):
    """A call of the scene's plain loop from the setup's initial state (n steps of h)."""
    D, P = setup.data, setup.P
    q0, p0 = setup.start[0]
    if setup.scene.name == "modulated":
        return lambda: plain_modulated(D.a, D.b, P.eps, P.alpha, q0, p0, 0.0, h, n)
    return lambda: plain_kapitza(D.a, D.b, P.w0, P.a, P.nu, q0, p0, 0.0, h, n)


def ours(setup, h, n):
    def call():
        run = simulate(setup, h, n * h, stride=n)
        return run.q[-1, 0, 0], run.p[-1, 0, 0], run.pt[-1, 0] - run.pt[0, 0]
    return call


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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print(f"{'scene':<10} {'method':<13} {'cosymp ns/step':>15} {'plain ns/step':>14} {'ratio':>6}  agree")
    splitting = [m.name for m in METHODS.values() if m.requires == "separable"]
    for scene in ("modulated", "kapitza"):
        for name in splitting:
            setup = Setup.make(scene, name)
            h = setup.scene.h
            (a, b), (ta, tb) = best_of([ours(setup, h, args.steps), plain(setup, h, args.steps)], args.repeats)
            agree = np.allclose(np.array(a, float), np.array(b, float), rtol=AGREE, atol=AGREE)
            print(f"{scene:<10} {name:<13} {1e9 * ta / args.steps:>15.1f} {1e9 * tb / args.steps:>14.1f} "
                  f"{ta / tb:>6.2f}  {'yes' if agree else 'NO'}")


if __name__ == "__main__":
    main()
