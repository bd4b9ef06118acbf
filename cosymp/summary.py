"""Whole-run figures (maxima over every step) and long runs' envelopes, by the fused driver (cosymp.drive)."""
import dataclasses
import math
import time

import numpy as np

from .diagnostics import det_deviation, nearby_states, symplecticity_defect, tangent_maps
from .drive import CHUNK, Drive
from .integrate import check_step, simulate
from .kernels.loops import energies
from .kernels.survey import ACC, ENV
from .reference import check_reference, reference_final, refinement, relative_final


def transport(traj, target):
    """Map a trajectory of a scene with gauges into the gauge of setup `target` by G_chi at each time.

    G_(t_(k+1)) o Phi o G_(t_k)^-1 telescopes, so the transported run is G applied to every
    state of the run in the source gauge; H is re-evaluated in the target gauge.
    """
    src = traj.setup
    t = traj.t
    gauge_map = src.scene.gauge_map
    q, p, pt = gauge_map(src.P, t, traj.q, traj.p, traj.pt, inverse=True)
    q, p, pt = gauge_map(target.P, t, q, p, pt)
    z = np.ascontiguousarray(np.concatenate([q, p], axis=-1))
    H = np.empty(pt.shape)
    energies(target.P, np.ascontiguousarray(t), z, H)
    return dataclasses.replace(traj, setup=target, z=z, pt=pt, H=H)


def transported_maps(M, src, target, t, h):
    """Tangent maps of the transported step: DG(t + h) M DG(t)^-1, DG the Jacobian of the change
    of gauge (Scene.gauge_jacobian)."""
    jacobian = src.scene.gauge_jacobian
    return jacobian(src.P, target.P, t + h) @ M @ jacobian(target.P, src.P, t)


def _transported_run(setup, h, steps, source, progress):
    """The run in gauge `source`, shown in setup's gauge (transport): (final Trajectory,
    figures, compiled seconds). Every step is recorded, chunk by chunk, and transported."""
    z0 = pt0 = None
    done = 0
    wall = 0.0
    fig = dict.fromkeys(("H_ext_max_abs", "det_max_dev", "symp_max_dev", "symp_max_rel"), 0.0)
    while done < steps:
        n = min(CHUNK, steps - done)
        tr = simulate(source, h, n * h, z0=z0, stride=1, t0=done * h, pt0=pt0)
        wall += tr.wall_s
        M = transported_maps(tangent_maps(tr), source, setup, tr.t[:-1], h)
        shown = transport(tr, setup)
        for key, values in (("H_ext_max_abs", np.abs(shown.H_ext)), ("det_max_dev", det_deviation(M)),
                            ("symp_max_dev", symplecticity_defect(M)),
                            ("symp_max_rel", symplecticity_defect(M, relative=True))):
            fig[key] = max(fig[key], float(np.max(values)))
        z0, pt0 = tr.z[-1], tr.pt[-1]
        done += n
        if progress:
            progress(done, steps)
    return shown, fig, wall


SKIP_ERROR = "skip the error at T (--no-error)"


def run_summary(setup, h, T, transport_from=None, with_error=True, progress=None):
    """The CLI's figures for one run: finals, max |H + p_t|, max |det M - 1|, max symplecticity
    defect (absolute and relative) over every step, the error at T against the exact flow or
    the reference, wall time (wall_s: the compiled run with its diagnostics)."""
    steps = check_step(h, T)
    setup.scene.check_horizon(setup.values, steps * h)
    if with_error:
        check_reference(setup, h, T, SKIP_ERROR)
    start = time.perf_counter()
    if transport_from:
        final, fig, wall = _transported_run(setup, h, steps, setup.with_values(gauge=transport_from), progress)
        t, z, pt, H_ext = final.t[-1], final.z[-1, 0], final.pt[-1, 0], final.H_ext[-1, 0]
    else:
        drive = Drive(setup, h)
        began = time.perf_counter()
        drive.run(steps, progress)
        wall = time.perf_counter() - began
        fig = {k: float(v) for k, v in zip(ACC, drive.acc)}
        t, z, pt = drive.t, drive.Z[0], drive.PT[0]
        H = np.empty((1, 1))
        energies(setup.P, np.array([t]), drive.Z[None, :1], H)
        H_ext = H[0, 0] + pt
    n = setup.scene.ndof
    out = {
        "scene": setup.scene.name,
        "method": setup.method.name,
        "theta": setup.theta,
        "gauge": setup.values.get("gauge"),
        "transport_from": transport_from,
        "h": h,
        "T": T,
        "steps": steps,
        "t_final": float(t),
        "q_final": z[:n].tolist(),
        "p_final": z[n:].tolist(),
        "pt_final": float(pt),
        "H_ext_final": float(H_ext),
        **fig,
        "error_final": None,
        "reference": None,
        "wall_s": wall,
    }
    Pi = setup.scene.momentum(setup.P, np.array([t]), z[None, :n], z[None, n:])
    if Pi is not None:
        out["Pi_final"] = Pi[0].tolist()
    if with_error:
        zr, spread = reference_final(setup, h, T, skip=SKIP_ERROR)
        out["error_final"], uncertainty = relative_final(z, zr[0], spread[0])
        out["reference"] = "exact flow" if setup.scene.has_flow else f"rk8 at h/{refinement(setup, h)}"
        # None where it is infinite (the check at twice its step overflowed): JSON has no inf
        out["reference_uncertainty"] = uncertainty if math.isfinite(uncertainty) else None
    out["wall_total_s"] = time.perf_counter() - start
    return out


def long_drive(setup, h, width, delta=1e-4):
    """A long run of setup with the 2n + 1 nearby states of the paper's estimators, reduced to bins
    of `width` steps (drive.Drive: advance() returns each call's bins, kernels.survey.ENV: t, the
    time after each bin's first step; min and max of H + p_t and of the paper's volume
    estimator; max of |det M_k - 1| and of ||M_k^T J M_k - J||)."""
    n = setup.scene.ndof
    return Drive(setup, h, z0=nearby_states(setup.start[0], delta, 2 * n + 1), width=width)


def long_envelopes(setup, h, T, bins, delta=1e-4, progress=None):
    """A long run of setup (see long_drive) reduced to at most `bins` bins; returns (dict of
    arrays, failure message): the bins up to a failure, and its message."""
    steps = check_step(h, T)
    drive = long_drive(setup, h, max(1, math.ceil(steps / bins)), delta)
    out = drive.run(steps, progress, strict=False)
    return out or {k: np.empty(0) for k in ("t",) + ENV}, drive.failure

