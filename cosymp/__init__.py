"""cosymp: structure-preserving integrators for time-dependent Hamiltonian systems.

    from cosymp import Setup, simulate
    run = simulate(Setup.make("damped", "midpoint"), h=0.1, T=50.0)
    run.t, run.q, run.p, run.pt, run.H_ext
"""
from .errors import CosympError, InputError, RunError
from .integrate import MAX_STEPS, Setup, Trajectory, simulate
from .methods import METHODS
from .scenes import SCENES

__all__ = [
           "MAX_STEPS",
           "METHODS",
           "SCENES",
           "CosympError",
           "InputError",
           "RunError",
           "Setup",
           "Trajectory",
           "simulate",
]
