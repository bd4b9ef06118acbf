"""Diagnostics (PHYSICS.md section 4): the paper's estimators, as printed, and rigorous companions.

Paper's estimators (labelled as such wherever shown): omega(X1, X2) and det[X1 X2 X3] of the
one-step increments X = z_(k+1) - z_k of nearby trajectories. Rigorous companions: the one-step
tangent map M_k on the time slice with |det M_k - 1| and ||M_k^T J M_k - J||_max, omega of the
separation vectors of nearby trajectories, and the action (area) of a carried loop.
"""
import math

import numpy as np

from . import warm
from .errors import RunError
from .integrate import failure_message
from .kernels.families import OK
from .kernels.loops import tangent


def J(n):
    """The canonical matrix in z = (q, p)."""
    return np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])


def norm(v, axis=-1):
    """The 2-norm over an axis without overflow or underflow for huge or tiny finite entries
    (the damped scene's state reaches 1e300 while staying finite)."""
    v = np.asarray(v, dtype=float)
    scale = np.max(np.abs(v), axis=axis, keepdims=True)
    ok = (scale > 0) & np.isfinite(scale)
    unit = np.divide(v, scale, out=np.zeros_like(v), where=ok)
    out = np.where(ok, scale, 1.0) * np.linalg.norm(unit, axis=axis, keepdims=True)
    return np.squeeze(np.where(ok, out, scale), axis=axis)


def distance(a, b, axis=-1):
    """norm(a - b) without overflow in the difference itself (a and b near 1e308, opposite signs)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    with np.errstate(over="ignore"):  # a distance beyond 1.8e308 is inf, as it should be
        return 2.0 * norm(0.5 * a - 0.5 * b, axis=axis)


def relative_error(z, z_ref):
    """(|z - z_ref| / |z_ref|, |z - z_ref|) over all entries, without overflow."""
    err = float(distance(np.ravel(z), np.ravel(z_ref)))
    return err / reference_size(z_ref), err


def reference_size(z_ref):
    """|z_ref| over all entries, what relative errors divide by (the smallest float where it is 0)."""
    return max(float(norm(np.ravel(z_ref))), np.finfo(float).tiny)


ORBIT_ERROR = "|z − z_ref| / max |z_ref| up to t"  # errors_over_time's second, as plots label it


def errors_over_time(z, z_ref):
    """Two relative errors of records z against z_ref (rows: records): |z - z_ref| / |z_ref|, and
    |z - z_ref| / max |z_ref| over the records so far, relative to the orbit's size. The first spikes
    where z_ref passes near 0: the damped oscillator's q crosses 0 at an amplitude growing like
    e^(gamma t / 2) while its p is e^(-gamma t) smaller (the paper's values, midpoint rule: 4.9 at
    t = 40.2, where |z_ref| is 0.5 on an orbit of size 64; 0.039 relative to that size)."""
    return relative_over_time(distance(z, z_ref), z_ref)


def relative_over_time(d, z_ref):
    """Distances d from the records z_ref, relative as errors_over_time gives its two."""
    size = norm(z_ref)
    tiny = np.finfo(float).tiny
    return d / np.maximum(size, tiny), d / np.maximum(np.fmax.accumulate(size), tiny)


def omega(X, Y):
    """Canonical 2-form sum_i X_qi Y_pi - X_pi Y_qi over the last axis (q then p)."""
    n = X.shape[-1] // 2
    return np.sum(X[..., :n] * Y[..., n:] - X[..., n:] * Y[..., :n], axis=-1)


def tangent_maps(traj, member=0, last=False):
    """One-step tangent maps M_k at the recorded states of one member: (K - 1, 2n, 2n).

    M_k is the Jacobian of the step taken from record k (exact for linear scenes, complex step
    otherwise). `last` adds the map of one more step from the final record.
    """
    s = traj.setup
    warm.ensure(s)
    z = np.ascontiguousarray(traj.z[:, member])
    pt = np.ascontiguousarray(traj.pt[:, member])
    t = np.ascontiguousarray(traj.t)
    if not last:
        z, pt, t = z[:-1], pt[:-1], t[:-1]
    M = np.empty((len(t), z.shape[1], z.shape[1]))
    status, k = tangent(s)(s.data, s.P, float(traj.h), t, z, pt, M)
    if status != OK:
        msg = failure_message(status, k * traj.stride, t[k], traj.h, at=(s, z[k]))
        raise RunError(f"tangent map: {msg}", t[k], k * traj.stride)
    return M


class MapGrowth:
    """The largest finite-time growth exponent of a method's map along a run:
    ln(sigma_max(M_(K-1) ... M_0)) / t over the one-step tangent maps of every step (the largest
    singular value of the run's linearised map: a finite-time Lyapunov exponent). The fused
    driver (cosymp.drive) multiplies the maps into A as it steps, taking out an exact power of
    two whenever A's entries leave [2^-64, 2^64], so any horizon fits in floating point; scaled
    steps (the damped scene) are undone exactly. state: (log of the scale taken out, the scaling exponent A is kept in, 1.0 while
    the product stayed finite and not zero)."""

    def __init__(self, m):
        self.A = np.eye(m)
        self.state = np.array([0.0, 0.0, 1.0])

    @property
    def finite(self):
        return self.state[2] == 1.0

    def log_norm(self):
        """ln sigma_max of the product so far (NaN if a map was not finite or was singular)."""
        return float(log_norms(self.A[None], self.state[None])[0])


def log_norms(A, state):
    """ln sigma_max of products kept as MapGrowth keeps them: A (B, m, m), state (B, 3)."""
    e = state[:, 1].astype(int)
    n = A.shape[1] // 2
    A = A.copy()
    A[:, :n] = np.ldexp(A[:, :n], (e - abs(e))[:, None, None])
    A[:, n:] = np.ldexp(A[:, n:], (-e - abs(e))[:, None, None])
    finite = state[:, 2] == 1.0
    sigma = np.ones(len(A))
    sigma[finite] = np.linalg.svd(A[finite], compute_uv=False)[:, 0]
    return np.where(finite, state[:, 0] + abs(e) * math.log(2.0) + np.log(sigma), math.nan)


def det_deviation(M):
    """|det M - 1| per map."""
    return np.abs(np.linalg.det(M) - 1.0)


def symplecticity_defect(M, relative=False):
    """||M^T J M - J||_max per map; relative: divided by the largest sum of |terms| making up an
    entry of M^T J M (scale-free: round-off level for a symplectic map of any size)."""
    n = M.shape[-1] // 2
    Jn = J(n)
    D = np.max(np.abs(np.swapaxes(M, 1, 2) @ (Jn @ M) - Jn), axis=(1, 2))
    if not relative:
        return D
    A = np.abs(M)
    Aq, Ap = A[:, :n], A[:, n:]
    S = np.swapaxes(Aq, 1, 2) @ Ap + np.swapaxes(Ap, 1, 2) @ Aq
    return D / np.max(S, axis=(1, 2))


def nearby_states(z0, delta, count):
    """z0 and `count` perturbations of size delta: along each coordinate, then -delta * sum."""
    z0 = np.asarray(z0, float)
    m = z0.size
    dirs = [np.eye(m)[i % m] * (1 if i < m else -1) for i in range(count)]
    if count > m:
        dirs[m] = -np.ones(m) / np.sqrt(m)
    return np.array([z0] + [z0 + delta * d for d in dirs])


def paper_symplectic_form(traj, i=1, j=2):
    """The paper's estimator: omega(X^i, X^j) of the one-step increments of members i and j."""
    dZ = traj.increments
    return omega(dZ[1:, i], dZ[1:, j])


def paper_volume_form(traj, members=None):
    """The paper's estimator: det[X^1 ... X^(2n+1)] of increments X^i = (dq^i, h, dp^i) of nearby
    members. Taken as the fused loop takes it (kernels.survey._volume): X^i - X^1 for i >= 2 has 0
    under t, so the determinant is (-1)^n h det[X^i - X^1 in (q, p)]. The increments of nearby
    members are nearly parallel, and their differences first (exact where two are within a factor
    of 2) leave the determinant's round-off at that of the differences: against the exact
    determinant of the same increments, 3e-15 relative where the LU of the raw rows gave 1e-12
    (damped, modulated), and 4e-7 where it gave 1e-2 (charged, two degrees of freedom)."""
    dZ = traj.increments[1:]
    n = traj.q.shape[-1]
    members = list(range(1, 2 * n + 2)) if members is None else list(members)
    X = dZ[:, members]
    return (-1) ** n * traj.h * np.linalg.det(X[:, 1:] - X[:, :1])


def separation_omega(traj, i=1, j=None):
    """omega(delta^i, delta^j) of separations from member 0: constant for a symplectic map. By
    default the members perturbed along q_1 and along p_1 (`nearby_states`: member k along
    coordinate k - 1), a conjugate pair, so that it starts at delta^2 in any dimension (q_1 and
    q_2, the second and third members in two degrees of freedom, give 0 throughout)."""
    z = traj.z
    j = 1 + traj.q.shape[-1] if j is None else j
    return omega(z[:, i] - z[:, 0], z[:, j] - z[:, 0])


def ring_states(z0, radius, count):
    """A closed loop of initial states: a circle in the (q_1, p_1) plane around z0."""
    z0 = np.asarray(z0, float)
    n = z0.size // 2
    a = 2 * np.pi * np.arange(count) / count
    Z = np.repeat(z0[None], count, axis=0)
    Z[:, 0] += radius * np.cos(a)
    Z[:, n] += radius * np.sin(a)
    return Z


def loop_action(traj):
    """-sum_i closed-integral p_i dq_i of the carried loop (trapezoid rule, members in order):
    the enclosed area of a counter-clockwise loop in one degree of freedom; invariant under
    symplectic maps (exactly so for linear ones, whose image of a polygon is a polygon)."""
    q, p = traj.q, traj.p
    dq = np.roll(q, -1, axis=1) - q
    pm = 0.5 * (np.roll(p, -1, axis=1) + p)
    return -np.sum(pm * dq, axis=(1, 2))
