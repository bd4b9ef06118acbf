"""The method families, each registered once with everything the rest of cosymp needs of it:
the member step (any scene) and its stack work, the step as a matrix for linear scenes
(kernels.linear), its vector-field evaluations per step (work-precision's cost measure), and its
entry point in the C mirror benchmarks/bench_ref.c (the bench). A new family is one entry here."""
import math
from collections import namedtuple

import numpy as np

from . import families as f
from . import linear as lin
from .dispatch import register

FamilyKernel = namedtuple("FamilyKernel", "step work lmatrix lwork evaluations mirror interleaved")
FamilyKernel.__doc__ = """evaluations(D, linear): gradients of H per step of family data D (NaN where a
Newton iteration makes it run-dependent: implicit steps on a nonlinear scene, or no vector field at
all: the exact flow). mirror(D): (C function, its arguments after the offsets) in bench_ref.c, or
None where the C mirror has no such family. interleaved: whether the step computes each
coefficient row where a stage first uses it, calling kernels.families.row before it reads one (a
splitting's kicks: the row's transcendentals then overlap the previous kicks' dependency chain;
measured on kapitza, Blanes & Moan's SRKN11b: 425 -> 273 ns a step in a plain numba loop), instead
of the loop computing every row before the step (an implicit step uses every row in each Newton
iteration). Not the Runge-Kutta tableaus: on kapitza, rows computed before the step took rk4 107 ->
92 ns a step (1.18 -> 1.01x a plain numba loop, benchmarks/plain.py) and left euler and rk8 as they
were (within 2 %)."""


def _f64(values):
    return np.array(values, dtype=np.float64).ravel()


def _implicit(count):
    """Evaluations of an implicit family on a linear scene: its `count` stages' time coefficients, once a
    step (Gauss's second, refining correction evaluates no new ones)."""
    return lambda D, linear: float(count(D)) if linear else math.nan


FAMILIES = {
    f.Explicit: FamilyKernel(f.explicit_step, f.explicit_work, lin.explicit_lmatrix, lin.explicit_lwork,
                             lambda D, linear: float(len(D.b)),
                             lambda D: ("run_explicit", (_f64(D.A), _f64(D.b), np.array(D.stage, dtype=np.int64),
                                                         len(D.b))), False),
    f.Theta: FamilyKernel(f.theta_step, f.theta_work, lin.theta_lmatrix, lin.theta_lwork,
                          _implicit(lambda D: 1),
                          lambda D: ("run_theta", (float(D.wq0), float(D.wq1), float(D.wp0), float(D.wp1))), False),
    f.Gauss: FamilyKernel(f.gauss_step, f.gauss_work, lin.gauss_lmatrix, lin.gauss_lwork,
                          _implicit(lambda D: len(D.b)),
                          lambda D: ("run_gauss", (_f64(D.A), _f64(D.b), len(D.b))), False),
    f.Composition: FamilyKernel(f.composition_step, f.theta_work, lin.composition_lmatrix,
                                lin.composition_lwork, _implicit(lambda D: len(D.gammas)),
                                lambda D: ("run_composition", (_f64(D.gammas), len(D.gammas))), False),
    f.Boris: FamilyKernel(f.boris_step, f.boris_work, lin.boris_lmatrix, lin.boris_lwork,
                          lambda D, linear: 1.0, lambda D: ("run_boris", ()), False),
    f.Exact: FamilyKernel(f.exact_step, f.exact_work, lin.exact_lmatrix, lin.exact_lwork,
                          lambda D, linear: math.nan, lambda D: ("run_exact", ()), False),
    f.Splitting: FamilyKernel(f.splitting_step, f.splitting_work, lin.splitting_lmatrix, lin.splitting_lwork,
                              lambda D, linear: float(np.count_nonzero(D.b)),  # one force (grad V) per kick
                              lambda D: None, True),
    f.Perturbed: FamilyKernel(f.perturbed_step, f.splitting_work, lin.splitting_lmatrix, lin.splitting_lwork,
                              lambda D, linear: float(np.count_nonzero(D.b)),  # one force of H - H0 per kick
                              lambda D: None, True),
}
for _cls, _kernel in FAMILIES.items():
    register(_cls, _kernel)


def family(D):
    """The registered FamilyKernel of family data D."""
    return FAMILIES[type(D)]
