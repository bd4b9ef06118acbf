"""Family data class -> its compiled pieces: the member step (any scene) and, for linear scenes,
the step as a matrix (kernels.linear)."""
from collections import namedtuple

from . import families as f
from . import linear as lin

FamilyKernel = namedtuple("FamilyKernel", "step work lmatrix lwork")
FAMILIES = {
    f.Explicit: FamilyKernel(f.explicit_step, f.explicit_work, lin.explicit_lmatrix, lin.explicit_lwork),
    f.Theta: FamilyKernel(f.theta_step, f.theta_work, lin.theta_lmatrix, lin.theta_lwork),
    f.Gauss: FamilyKernel(f.gauss_step, f.gauss_work, lin.gauss_lmatrix, lin.gauss_lwork),
    f.Composition: FamilyKernel(f.composition_step, f.theta_work, lin.composition_lmatrix,
                                lin.composition_lwork),
    f.Boris: FamilyKernel(f.boris_step, f.boris_work, lin.boris_lmatrix, lin.boris_lwork),
    f.Exact: FamilyKernel(f.exact_step, f.exact_work, lin.exact_lmatrix, lin.exact_lwork),
    f.Splitting: FamilyKernel(f.splitting_step, f.splitting_work, lin.splitting_lmatrix, lin.splitting_lwork),
}
