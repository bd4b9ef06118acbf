"""Each scene's gradient, Hessian and dH/dt against its energy, at random states and times.

The convergence tests cannot see a wrong gradient: their references (scipy's DOP853, the rk8
reference) use the same vector field. Here grad and hess are compared with complex-step
derivatives of the energy (exact to round-off), and dhdt with a sixth-order central difference
of the energy in t. Every registered scene is checked, under each of its choices (the gauges).
"""
import itertools

import numpy as np
import pytest
from numba import njit

from cosymp.kernels.dispatch import coef, dhdt, energy, energy_coef, grad, hess, ncoef
from cosymp.scenes import SCENES

STEP = 1e-30
SAMPLES = 6
TEXT = {"charged": {"beta": "0.05*(1 + tanh(t)) + 0.1*sin(3*t)^2"}}
"""Text parameters checked with a value besides their default: beta(t) as an expression (whose
derivatives the expression compiler derives)."""


@njit
def _at(P, t, z, zc, out, g, gc, Hm):
    """out = (H, dH/dt) at (z, t); g = grad H; Hm = hess H; and through the complex z, zc,
    out[2] = Im H(zc) and gc = grad H(zc)."""
    C = np.empty((1, ncoef(P)))
    coef(P, t, C, 0)
    out[0] = energy(P, C, 0, z)
    out[1] = dhdt(P, C, 0, z)
    grad(P, C, 0, z, g)
    hess(P, C, 0, z, Hm)
    out[2] = energy(P, C, 0, zc).imag
    grad(P, C, 0, zc, gc)


def evaluate(P, t, z, direction):
    m = len(z)
    out, g, Hm = np.empty(3), np.empty(m), np.empty((m, m))
    gc = np.empty(m, dtype=complex)
    zc = z + 1j * STEP * direction
    _at(P, t, z, zc, out, g, gc, Hm)
    return out, g, Hm, gc.imag / STEP


def variants(scene):
    """The scene's default values under every combination of its choices (e.g. the gauges), and
    again with its TEXT values."""
    choices = [p for p in scene.params if p.choices]
    for text in ({}, *([TEXT[scene.name]] if scene.name in TEXT else [])):
        for combo in itertools.product(*[p.choices for p in choices]):
            yield scene.values({**text, **dict(zip([p.name for p in choices], combo))})


CASES = [pytest.param(s, v, id=s.name + "".join(f"-{v[p.name]}" for p in s.params if p.choices)
                      + ("-text" if any(v[k] != s.values()[k] for k in TEXT.get(s.name, {})) else ""))
         for s in SCENES.values() for v in variants(s)]


@pytest.mark.parametrize("scene,values", CASES)
def test_grad_hess_and_dhdt_are_the_derivatives_of_the_energy(scene, values, rng):
    P = scene.pack(values)
    m = 2 * scene.ndof
    for _ in range(SAMPLES):
        t = rng.uniform(0.0, 5.0 * scene.time_scale)
        z = rng.uniform(-1.5, 1.5, m)
        g = evaluate(P, t, z, np.zeros(m))[1]
        scale = max(1.0, np.max(np.abs(g)))
        for j in range(m):
            e = np.eye(m)[j]
            (_, _, im), _, Hm, column = evaluate(P, t, z, e)
            assert im / STEP == pytest.approx(g[j], abs=1e-12 * scale), f"dH/dz_{j} at t = {t}, z = {z}"
            assert np.allclose(Hm[:, j], column, rtol=1e-12, atol=1e-12 * scale), f"column {j} of the Hessian"
        d = 1e-3 * scene.time_scale
        H = [evaluate(P, t + k * d, z, np.zeros(m))[0][0] for k in (-3, -2, -1, 1, 2, 3)]
        fd = (-H[0] + 9 * H[1] - 45 * H[2] + 45 * H[3] - 9 * H[4] + H[5]) / (60 * d)
        Ht = evaluate(P, t, z, np.zeros(m))[0][1]
        assert Ht == pytest.approx(fd, abs=1e-7 * max(1.0, abs(fd))), f"dH/dt at t = {t}, z = {z}"


@njit
def _rows(P, t, z, C, out):
    """C[0] = coef's row at t, C[1] = energy_coef's (over whatever C[1] held); out = H(z) from each."""
    coef(P, t, C, 0)
    energy_coef(P, t, C, 1)
    out[0] = energy(P, C, 0, z)
    out[1] = energy(P, C, 1, z)


@pytest.mark.parametrize("scene,values", CASES)
def test_the_energy_row_gives_the_energy_of_the_whole_row(scene, values, rng):
    """energy_coef (what H reads of a row, where it costs less than coef: H after every step) gives
    H bit for bit as coef's row does, from a row that held NaN before: it writes all that energy
    reads. And a scene that declares its S(t) and dS/dt diagonal (its forms skip the couplings:
    scenes.quadratic) has them so: every coupling of the row exactly 0."""
    P = scene.pack(values)
    m = 2 * scene.ndof
    for _ in range(SAMPLES):
        t = rng.uniform(-5.0 * scene.time_scale, 5.0 * scene.time_scale)
        z = rng.uniform(-1.5, 1.5, m)
        C, out = np.full((2, scene.kernel.ncoef), np.nan), np.empty(2)
        _rows(P, t, z, C, out)
        assert np.isfinite(out[0]) and out[1] == out[0], f"H at t = {t}, z = {z}"
        if scene.kernel.diagonal:
            S, dS = C[0, :m * m].reshape(m, m), C[0, m * m:2 * m * m].reshape(m, m)
            off = ~np.eye(m, dtype=bool)
            assert np.all(S[off] == 0.0) and np.all(dS[off] == 0.0), f"couplings at t = {t}"
