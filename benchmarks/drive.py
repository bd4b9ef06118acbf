"""What a run's diagnostics cost: the fused driver against the step alone and a plain C loop.

    python benchmarks/drive.py [--steps N] [--repeats R]

The paper's longest run (damped, gamma = 2e-4, implicit midpoint, h = 0.1; 5e6 steps by default),
timed in one process, interleaved, best of R, after an untimed warm-up:

* C: a plain C -O3 implicit-midpoint loop for this scene (two exponentials per step, p_t summed),
  compiled here with gcc: the floor.
* step: cosymp's compiled loop alone (`simulate`, recording only the final state).
* run: the fused driver with every figure `cosymp run` gives (max |H + p_t|, max |det M_k - 1|,
  the symplecticity defect, absolute and relative), as run_summary drives it;
* fused: the same and the growth product of every step's map (what a sweep's point forms).
* long run: the app's Long run view (summary.long_drive): every figure of `run`, the paper's
  volume estimator from three nearby members, and min/max envelopes over 20,000 bins.
* two passes: what `cosymp run` did before the fused driver (every step recorded in chunks of
  2^18, tangent maps formed in a second pass, det and M^T J M - J in NumPy).

Prints ns/step and the ratios to C; the final states of C and cosymp must agree.
"""
import argparse
import ctypes
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cosymp.diagnostics import det_deviation, symplecticity_defect, tangent_maps
from cosymp.drive import CHUNK, Drive
from cosymp.integrate import Setup, simulate
from cosymp.summary import long_drive

LONG_BINS = 20_000  # app.features.longrun's (the benchmark imports no app code)

C_SOURCE = r"""
#include <math.h>
/* Implicit midpoint for H = e^(g t) p^2/(2m) + e^(-g t) m w0 q^2/2: one linear 2 x 2 solve per step. */
void midpoint(double m, double w0, double g, double h, long n, double *z, double *pt) {
    double q = z[0], p = z[1], s = *pt;
    for (long k = 0; k < n; k++) {
        double t = (k + 0.5) * h;
        double a = exp(g * t) / m, b = m * w0 * exp(-g * t);
        double al = 0.5 * h * a, be = 0.5 * h * b, d = 1.0 / (1.0 + al * be);
        double r1 = q + al * p, r2 = p - be * q;
        double q1 = (r1 + al * r2) * d, p1 = (r2 - be * r1) * d;
        double qm = 0.5 * (q + q1), pm = 0.5 * (p + p1);
        s -= h * (0.5 * g * a * pm * pm - 0.5 * g * b * qm * qm);
        q = q1; p = p1;
    }
    z[0] = q; z[1] = p; *pt = s;
}
"""


def c_loop():
    folder = Path(tempfile.mkdtemp())
    (folder / "mid.c").write_text(C_SOURCE)
    subprocess.run(["gcc", "-O3", "-march=native", "-fno-math-errno", "-fPIC", "-shared", "-o", str(folder / "mid.so"),
                    str(folder / "mid.c"), "-lm"], check=True)
    fn = ctypes.CDLL(str(folder / "mid.so")).midpoint
    fn.argtypes = [ctypes.c_double] * 4 + [ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p]
    return fn


def two_passes(setup, h, steps):
    z0 = pt0 = None
    done = 0
    H = det = symp = 0.0
    while done < steps:
        n = min(CHUNK, steps - done)
        tr = simulate(setup, h, n * h, z0=z0, stride=1, t0=done * h, pt0=pt0)
        M = tangent_maps(tr)
        H = max(H, float(np.max(np.abs(tr.H_ext))))
        det = max(det, float(np.max(det_deviation(M))))
        symp = max(symp, float(np.max(symplecticity_defect(M))))
        z0, pt0 = tr.z[-1], tr.pt[-1]
        done += n
    return z0[0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=5_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    setup = Setup.make("damped", "midpoint", {"gamma": 2e-4})
    P, h, n = setup.P, 0.1, args.steps
    c = c_loop()

    def run_c():
        z, pt = np.array(setup.start[0]), np.array([-0.5 * (P.m * P.w0 * setup.start[0, 0] ** 2
                                                             + setup.start[0, 1] ** 2 / P.m)])
        c(P.m, P.w0, P.gamma, h, n, z.ctypes.data, pt.ctypes.data)
        return z

    def run_step():
        return simulate(setup, h, n * h, stride=n).z[-1, 0]

    def run_fused(growth):
        d = Drive(setup, h, growth=growth)
        d.run(n)
        return d.Z[0]

    def run_long():
        d = long_drive(setup, h, math.ceil(n / LONG_BINS))
        d.run(n)
        return d.Z[0]

    cases = {"C": run_c, "step": run_step, "run": lambda: run_fused(False), "fused": lambda: run_fused(True),
             "long run": run_long, "two passes": lambda: two_passes(setup, h, n)}
    finals = {name: fn() for name, fn in cases.items()}  # warm-up (and compilation)
    best = dict.fromkeys(cases, math.inf)
    for _ in range(args.repeats):
        for name, fn in cases.items():
            start = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - start)
    scale = np.max(np.abs(finals["C"]))
    for name, z in finals.items():
        if not np.allclose(z, finals["C"], rtol=1e-6, atol=1e-9 * scale):
            sys.exit(f"{name}'s final state {z} does not agree with C's {finals['C']}")
    print(f"damped midpoint, gamma 2e-4, h 0.1, {n:.3g} steps; best of {args.repeats}, interleaved")
    print(f"{'':12} {'ns/step':>9} {'x C':>7} {'run (s)':>8}")
    for name in cases:
        print(f"{name:12} {best[name] / n * 1e9:9.1f} {best[name] / best['C']:7.2f} {best[name]:8.3f}")


if __name__ == "__main__":
    main()
