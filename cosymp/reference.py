"""Reference solutions: the exact flow where a scene has one, else a fine fixed-step RK8 run."""
import math

import numpy as np

from .integrate import Setup, check_step, initial_states, simulate
from .kernels.loops import vector_field

REFERENCE_FRACTION = 0.02


def reference_final(setup, h, T, z0=None):
    """(z at the run's final time steps*h, uncertainty) for a run of setup with step h to T.

    Exact flow: one exact step over the whole horizon (uncertainty 0). Otherwise rk8 with a
    step h/k no larger than 2% of the scene's time scale, compared with rk8 at twice that step
    for the uncertainty.
    """
    steps = check_step(h, T)
    t_final = steps * h
    if setup.scene.has_flow:
        ref = simulate(Setup.make(setup.scene, "exact", setup.values), t_final, t_final, z0=z0)
        return ref.z[-1], np.zeros(ref.z.shape[1])
    k = max(1, math.ceil(h / (REFERENCE_FRACTION * setup.scene.time_scale)))
    fine = Setup.make(setup.scene, "rk8", setup.values)
    a = simulate(fine, h / k, t_final, z0=z0, stride=steps * k)
    if steps * k % 2 == 0:
        b = simulate(fine, 2 * h / k, t_final, z0=z0, stride=steps * k // 2)
        spread = np.linalg.norm(a.z[-1] - b.z[-1], axis=-1)
    else:
        spread = np.full(a.z.shape[1], np.nan)
    return a.z[-1], spread


def scipy_reference(setup, T, z0=None, rtol=1e-13, atol=1e-13, t_eval=None):
    """scipy's DOP853 on the extended ODE at tight tolerance: an independent check."""
    from scipy.integrate import solve_ivp

    Z = initial_states(setup, z0)
    P = setup.P
    m = Z.shape[1]

    def f(t, y):
        out = np.empty(m + 1)
        vector_field(P, t, y[:m].copy(), out)
        return out

    y0 = np.concatenate([Z[0], [0.0]])
    return solve_ivp(f, (0.0, T), y0, method="DOP853", rtol=rtol, atol=atol, t_eval=t_eval)
