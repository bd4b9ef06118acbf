"""Whole-run figures (maxima over every step), computed chunk by chunk in bounded memory."""
import dataclasses
import math
import time

import numpy as np

from .diagnostics import (
    det_deviation,
    distance,
    nearby_states,
    norm,
    paper_volume_form,
    symplecticity_defect,
    tangent_maps,
)
from .errors import RunError
from .integrate import Setup, check_step, simulate
from .kernels.loops import energies
from .reference import reference_final
from .scenes import charged

CHUNK = 1 << 18
LONG_CHUNK_BYTES = 40_000_000
ENVELOPES = ("H_min", "H_max", "vol_min", "vol_max", "det", "symp")


def transport(traj, target):
    """Map a charged-scene trajectory into the gauge of setup `target` by G_chi at each time.

    G_(t_(k+1)) o Phi o G_(t_k)^-1 telescopes, so the transported run is G applied to every
    state of the run in the source gauge; H is re-evaluated in the target gauge.
    """
    src = traj.setup
    t = traj.t
    q, p, pt = charged.gauge_map(src.P, t, traj.q, traj.p, traj.pt, inverse=True)
    q, p, pt = charged.gauge_map(target.P, t, q, p, pt)
    z = np.ascontiguousarray(np.concatenate([q, p], axis=-1))
    H = np.empty(pt.shape)
    energies(target.P, np.ascontiguousarray(t), z, H)
    return dataclasses.replace(traj, setup=target, z=z, pt=pt, H=H)


def transported_maps(M, src, target, t, h):
    """Tangent maps of the transported step: DG(t + h) M DG(t)^-1, DG = [[I, 0], [e beta dC, I]]."""
    beta = charged.betas(src.P, t)[0]
    beta1 = charged.betas(src.P, t + h)[0]
    dC = charged.gauge_matrix(target.P) - charged.gauge_matrix(src.P)
    e = src.P.e

    def DG(b, sign):
        G = np.tile(np.eye(4), (len(b), 1, 1))
        G[:, 2:, :2] = sign * e * b[:, None, None] * dC
        return G

    return DG(beta1, 1.0) @ M @ DG(beta, -1.0)


def run_summary(setup, h, T, transport_from=None, with_error=True, progress=None):
    """The CLI's figures for one run: finals, max |H + p_t|, max |det M - 1|, max symplecticity
    defect over every step, the error at T against the exact flow or the reference, wall time."""
    steps = check_step(h, T)
    source = setup.with_values(gauge=transport_from) if transport_from else setup
    z0 = None
    pt0 = None
    done = 0
    wall = 0.0
    H_max = det_max = symp_max = 0.0
    start = time.perf_counter()
    while done < steps:
        n = min(CHUNK, steps - done)
        tr = simulate(source, h, n * h, z0=z0, stride=1, t0=done * h, pt0=pt0)
        wall += tr.wall_s
        M = tangent_maps(tr)
        if transport_from:
            M = transported_maps(M, source, setup, tr.t[:-1], h)
            shown = transport(tr, setup)
        else:
            shown = tr
        H_max = max(H_max, float(np.max(np.abs(shown.H_ext))))
        det_max = max(det_max, float(np.max(det_deviation(M))))
        symp_max = max(symp_max, float(np.max(symplecticity_defect(M))))
        z0, pt0 = tr.z[-1], tr.pt[-1]
        done += n
        if progress:
            progress(done, steps)
    final = shown
    out = {
        "scene": setup.scene.name,
        "method": setup.method.name,
        "theta": setup.theta,
        "gauge": setup.values.get("gauge"),
        "transport_from": transport_from,
        "h": h,
        "T": T,
        "steps": steps,
        "t_final": float(final.t[-1]),
        "q_final": final.q[-1, 0].tolist(),
        "p_final": final.p[-1, 0].tolist(),
        "pt_final": float(final.pt[-1, 0]),
        "H_ext_final": float(final.H_ext[-1, 0]),
        "H_ext_max_abs": H_max,
        "det_max_dev": det_max,
        "symp_max_dev": symp_max,
        "error_final": None,
        "reference": None,
        "wall_s": wall,
    }
    if setup.scene.name == "charged":
        Pi = charged.mechanical(setup.P, final.t[-1:], final.q[-1:, 0], final.p[-1:, 0])
        out["Pi_final"] = Pi[0].tolist()
    if with_error:
        zr, spread = reference_final(setup, h, T)
        scale = max(float(norm(zr[0])), np.finfo(float).tiny)  # relative, as the app, reports and sweeps give it
        out["error_final"] = float(distance(final.z[-1, 0], zr[0])) / scale
        out["reference"] = "exact flow" if setup.scene.has_flow else "rk8 (fine fixed step)"
        out["reference_uncertainty"] = float(spread[0]) / scale
    out["wall_total_s"] = time.perf_counter() - start
    return out


def bin_reduce(values, width, op):
    """op (np.minimum or np.maximum) over consecutive bins of `width` values."""
    return op.reduceat(values, np.arange(0, len(values), width))


def long_chunk(setup, h, steps, Z, PT, start, width):
    """Advance the ensemble Z (member 0 the trajectory, 1.. the nearby states) by `steps` steps
    from step `start`; returns (per-bin reductions or None, Z, PT, failure message). The
    reductions over bins of `width` steps: t (bin starts), min and max of H + p_t and of the
    paper's volume estimator, max of |det M_k - 1| and of ||M_k^T J M_k - J||."""
    failure = ""
    try:
        tr = simulate(setup, h, steps * h, z0=Z, stride=1, increments=True, t0=start * h, pt0=PT)
    except RunError as err:
        tr, failure = err.partial, str(err)
    if len(tr.t) < 2:
        return None, Z, PT, failure
    try:
        M = tangent_maps(tr)
    except RunError as err:
        return None, Z, PT, failure or str(err)
    H = tr.H_ext[1:, 0]
    vol = paper_volume_form(tr)
    out = {
        "t": tr.t[1:][::width],
        "H_min": bin_reduce(H, width, np.minimum),
        "H_max": bin_reduce(H, width, np.maximum),
        "vol_min": bin_reduce(vol, width, np.minimum),
        "vol_max": bin_reduce(vol, width, np.maximum),
        "det": bin_reduce(det_deviation(M), width, np.maximum),
        "symp": bin_reduce(symplecticity_defect(M), width, np.maximum),
    }
    return out, np.ascontiguousarray(tr.z[-1]), np.ascontiguousarray(tr.pt[-1]), failure


def max_chunk(setup):
    """Steps per chunk that keep one chunk's records and tangent maps under LONG_CHUNK_BYTES."""
    m = 2 * setup.scene.ndof
    members = m + 2
    return max(1, LONG_CHUNK_BYTES // (members * (m + 1) * 3 * 8 + m * m * 8))


def long_envelopes(setup, h, T, bins, delta=1e-4, progress=None):
    """A long run of setup (with the 2n+1 nearby states of the paper's estimators) reduced to
    at most `bins` bins (see long_chunk); returns (dict of arrays, failure message)."""
    steps = check_step(h, T)
    width = max(1, math.ceil(steps / bins))
    chunk = width * max(1, max_chunk(setup) // width)
    n = setup.scene.ndof
    Z, PT = nearby_states(setup.start[0], delta, 2 * n + 1), None
    parts = []
    done = 0
    failure = ""
    while done < steps and not failure:
        k = min(chunk, steps - done)
        red, Z, PT, failure = long_chunk(setup, h, k, Z, PT, done, width)
        if red is not None:
            parts.append(red)
        done += k
        if progress:
            progress(done, steps)
    keys = ("t",) + ENVELOPES
    return {k: np.concatenate([p[k] for p in parts]) if parts else np.empty(0) for k in keys}, failure


def paper_volume_run(h=0.1, T=5e5, gamma=2e-4, methods=("midpoint", "rk4"), delta=1e-4):
    """The paper's longest run: damped, each method with the 3 extra trajectories of its
    volume form, advanced together; returns the wall time per method."""
    walls = {}
    for name in methods:
        s = Setup.make("damped", name, {"gamma": gamma})
        z0 = nearby_states(np.array([s.values["q0"], s.values["p0"]]), delta, 3)
        tr = simulate(s, h, T, z0=z0, stride=1000, increments=True)
        walls[name] = tr.wall_s
    return walls
