"""Round-off in H + p_t over long runs: does a method's band drift, or only wander?

    python benchmarks/roundoff.py [--methods M ...] [--steps N] [--starts K] [--ratio-steps N] [--ratio-starts K]

Each method on damped (gamma = 2e-4) and modulated at h = 0.1, from nearby starts q0 = 1 + 0.001 k:

* drift: H + p_t at the end of --steps steps from --starts starts; their mean against its standard
  error. Unbiased round-off wanders (the mean near 0, within a few standard errors); a systematic
  error drifts (the mean many standard errors from 0).
* ratio: max |H + p_t| over the last tenth of --ratio-steps steps over the max over the first tenth
  (the fused driver's bins), for each of --ratio-starts starts. Where a method's band is its own
  oscillation this is about 1; where the band is round-off, a random walk gives about sqrt(10),
  and each start's ratio is one draw.
"""
import argparse

import numpy as np

from cosymp.drive import Drive
from cosymp.integrate import Setup, simulate

SCENES = (("damped", {"gamma": 2e-4}), ("modulated", {}))
H = 0.1


def nearby(scene, values, method, k):
    return Setup.make(scene, method, {**values, "q0": 1.0 + 0.001 * k})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", nargs="+", default=["gauss6", "blanes-moan6"])
    ap.add_argument("--steps", type=int, default=2_000_000)
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--ratio-steps", type=int, default=5_000_000)
    ap.add_argument("--ratio-starts", type=int, default=8)
    args = ap.parse_args(argv)
    for scene, values in SCENES:
        for method in args.methods:
            ends = np.array([simulate(nearby(scene, values, method, k), H, args.steps * H, stride=args.steps)
                             .H_ext[-1, 0] for k in range(args.starts)])
            se = ends.std() / np.sqrt(args.starts)
            ratios = []
            for k in range(args.ratio_starts):
                bins = Drive(nearby(scene, values, method, k), H, width=args.ratio_steps // 10,
                             maps=False).run(args.ratio_steps)
                band = np.maximum(np.abs(bins["H_min"]), np.abs(bins["H_max"]))
                ratios.append(band[-1] / band[0])
            print(f"{scene:10} {method:13} end mean {ends.mean():+.2e}, spread {ends.std():.2e}, "
                  f"{ends.mean() / se:+.1f} standard errors; ratio {' '.join(f'{r:.2f}' for r in ratios)} "
                  f"(median {np.median(ratios):.2f})", flush=True)


if __name__ == "__main__":
    main()
