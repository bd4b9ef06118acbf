"""Compile-time dispatch from a parameter tuple to the jitted functions behind it.

Time coefficients live in a 2-D table C (one row per time point of a step) and are passed as
(C, j) rather than as a row view: a view or a tuple of arrays unpacked inside a loop with early
exits costs reference-count operations on every step, which numba cannot prune there.

A scene's kernel parameters are an instance of its own namedtuple class, and so is a method
family's data. Numba types each class as a distinct type, so one generic kernel compiled with
``cache=True`` specializes per (scene, family) and its cache entry survives a new process: no
function object ever appears in a cached signature (STYLE.md, "Numba caching").

Each stub below is resolved by the class of its first argument, through the table that
`register` fills: each scene registers its kernel where it is defined (scenes.base.Scene) and
each method family where the families are listed (kernels.registry), so this generic layer
imports neither.
"""
import inspect

from numba.core import codegen, compiler
from numba.core.errors import TypingError
from numba.extending import overload

from . import cachestamp

cachestamp.install()
JIT = {"cache": True, "nogil": True, "fastmath": {"contract"}, "error_model": "numpy"}
# Everything a step calls is inlined by LLVM (alwaysinline): left as calls, a Hessian or a
# small solve costs more than the arithmetic of the step.
INLINE = {**JIT, "forceinline": True}
# Two kinds of function are inlined in numba's IR instead. Those that declare stack scratch, so
# that the stack arrays belong to the compiled loop that uses them (kernels.stack). And those
# whose loops run over a size they receive as an argument (m, n, k): numba optimizes each
# forceinline function on its own before its caller, where such a loop has an unknown trip
# count; LLVM then unrolls it at run time and marks the remainder loop "do not unroll", so once
# inlined with m = 2 it stays a rolled loop through memory (measured: the composition's step
# matrix 133 -> 50 ns, a 2 x 2 solve and products). Inlined in numba's IR, the loop is first
# optimized where its size is a constant. Where that size is the state's (2 ndof), a helper takes
# the scene's parameters instead and reads ndof, a constant, so it can stay INLINE (kernels.loops).
IR_INLINE = {**JIT, "inline": "always"}
# Overload bodies are closures that compile into their caller's cached library; caching them on
# their own would key distinct closures by one qualified name.
_INLINE = {k: v for k, v in INLINE.items() if k != "cache"}
_IR_INLINE = {k: v for k, v in JIT.items() if k != "cache"}


_REGISTERED = {}


def _ndof(numba_type):
    """The degrees of freedom of the scene whose parameter tuple has this numba type (1 for any other
    type: a family's data, an array, a number)."""
    return getattr(_REGISTERED.get(getattr(numba_type, "instance_class", None)), "ndof", 1)


class _WithSLP:
    """A codegen as one library sees it: module pass managers with LLVM's SLP vectorizer on unless
    the caller says otherwise (numba's cheap first pass does: off)."""

    def __init__(self, inner):
        self._codegen = inner

    def __getattr__(self, name):
        return getattr(self._codegen, name)

    def _module_pass_manager(self, **kwargs):
        kwargs.setdefault("slp_vectorize", True)
        return self._codegen._module_pass_manager(**kwargs)


class _VectorizedLibrary(codegen.JITCodeLibrary):
    """numba's code library of one compiled function, whose final module (the function with every
    callee inlined into it) is optimized with the SLP vectorizer. The callees' own libraries, compiled
    and cached on their own, are not."""

    def _optimize_final_module(self):
        shared = self._codegen
        self._codegen = _WithSLP(shared)
        try:
            super()._optimize_final_module()
        finally:
            self._codegen = shared


class Vectorizing(compiler.Compiler):
    """numba's compiler, whose function compiled for a scene of two or more degrees of freedom is
    optimized with LLVM's SLP vectorizer, which numba leaves off (NUMBA_SLP_VECTORIZE = 0): the
    charged particle's step-matrix loop multiplies 4 x 4 matrices in straight-line code that only
    that pass packs into vector instructions, as gcc -O3 does. Only that function's library: numba's
    setting and every other compile, its callees' included, are left as they are. Measured with
    `cosymp bench` (README, "cosymp bench"). Not for one degree of freedom, nor for member steps:
    there the pass made steps slower, and simulate and the fused driver would round differently."""

    def _compile_core(self):
        if self.state.library is None and any(_ndof(a) >= 2 for a in self.state.args):
            self.state.library = _VectorizedLibrary(self.state.targetctx.codegen(),
                                                    self.state.func_id.func_qualname)
            self.state.library.enable_object_caching()  # as numba does for a library it creates
        return super()._compile_core()


def register(cls, table):
    """Make `table` (a scene's SceneKernel, a family's FamilyKernel) what the stubs below resolve
    to for parameter tuples of class `cls`."""
    _REGISTERED[cls] = table


def registered(cls):
    """The table registered for class `cls`."""
    if cls not in _REGISTERED:
        raise TypingError(f"{cls.__name__} is not registered: define its scene or family first")
    return _REGISTERED[cls]


def _target(cls, name, fallback=None):
    fn = getattr(registered(cls), name, None)
    if fn is None and fallback is not None:
        fn = getattr(registered(cls), fallback, None)
    if fn is None:
        raise TypingError(f"{cls.__name__} provides no '{name}'")
    return fn


def _forwarder(fn, arity):
    if arity == 1:
        def impl(k):
            return fn(k)
    elif arity == 2:
        def impl(k, a):
            return fn(k, a)
    elif arity == 3:
        def impl(k, a, b):
            return fn(k, a, b)
    elif arity == 4:
        def impl(k, a, b, c):
            return fn(k, a, b, c)
    elif arity == 5:
        def impl(k, a, b, c, d):
            return fn(k, a, b, c, d)
    else:
        def impl(k, a, b, c, d, e, f, g):
            return fn(k, a, b, c, d, e, f, g)
    return impl


def _dispatched(name, arity, doc, scratch=False, fallback=None):
    """A stub whose call in jitted code becomes a call of the registered implementation (of
    `fallback` where the table gives none for `name`)."""
    params = ("k", "a", "b", "c", "d", "e", "f", "g")[:arity]

    def stub(*args):
        raise NotImplementedError(f"{name} is only callable from jitted code")

    stub.__name__ = stub.__qualname__ = name
    stub.__doc__ = f"{doc} (arguments: {', '.join(params)})."
    stub.__signature__ = inspect.Signature(
        [inspect.Parameter(p, inspect.Parameter.POSITIONAL_OR_KEYWORD) for p in params])

    def _overload(*types):
        return _forwarder(_target(types[0].instance_class, name, fallback), arity)

    _overload.__signature__ = stub.__signature__
    if scratch:
        overload(stub, jit_options=_IR_INLINE, inline="always")(_overload)
    else:
        overload(stub, jit_options=_INLINE)(_overload)
    return stub


def _constant(name, doc):
    """A stub that compiles to a constant attribute of the registered scene."""
    def stub(k):
        raise NotImplementedError(f"{name} is only callable from jitted code")

    stub.__name__ = stub.__qualname__ = name
    stub.__doc__ = doc

    @overload(stub, jit_options=_INLINE)
    def _overload(k):
        value = _target(k.instance_class, name)
        return lambda k: value

    return stub


coef = _dispatched("coef", 4, "Fill row j of C with the time coefficients at t: coef(P, t, C, j)")
energy = _dispatched("energy", 4, "H(z) from coefficient row j: energy(P, C, j, z)")
energy_coef = _dispatched("energy_coef", 4, "Fill what `energy` reads of row j of C at t (all of coef where the "
                          "scene gives no energy_coef): energy_coef(P, t, C, j)", fallback="coef")
grad = _dispatched("grad", 5, "Gradient of H in z = (q, p): grad(P, C, j, z, g)")
hess = _dispatched("hess", 5, "Hessian of H in z: hess(P, C, j, z, Hm)")
dhdt = _dispatched("dhdt", 4, "Partial derivative of H in t: dhdt(P, C, j, z)")
flow = _dispatched("flow", 4, "Exact flow from t0 to t1, in place: flow(P, t0, t1, z)")
vecpot = _dispatched("vecpot", 5, "Vector potential of the run's gauge at q = z[:2]: vecpot(P, C, j, z, A)")
efield = _dispatched("efield", 5, "Electric field at q = z[:2]: efield(P, C, j, z, E)")
bfield = _dispatched("bfield", 3, "Magnetic field (z component): bfield(P, C, j)")
kick = _dispatched("kick", 5, "Exact flow of V(q, t) for a time tau at row j's time (separable scenes): "
                   "kick(P, C, j, tau, z) -> p_t increment")
drift = _dispatched("drift", 4, "Exact flow of T(p, t) + p_t from t0 for a time tau (separable scenes): "
                    "drift(P, t0, tau, z) -> p_t increment")
rotate = _dispatched("rotate", 4, "Exact flow of the integrable part H0 + p_t from t0 for a time tau (near-integrable "
                     "scenes, H = H0 + (H - H0) with H - H0 small): rotate(P, t0, tau, z) -> p_t increment")
nudge = _dispatched("nudge", 5, "Exact flow of the perturbation H - H0 for a time tau at row j's time (near-integrable "
                    "scenes): nudge(P, C, j, tau, z) -> p_t increment")
scaling = _dispatched("scaling", 2, "Scaling exponent e of the step from t (see scenes.base.SceneKernel): "
                      "scaling(P, t) -> e")
shift = _dispatched("shift", 2, "Time shift tau of the scaling exponent e: shift(P, e) -> tau")
step = _dispatched("step", 8, "One step of family D for one member: step(D, P, C, t, h, z, pt, W) -> (status, pt)")
work = _dispatched("work", 3, "Stack work arrays of family D: work(D, P, like)", scratch=True)
lmatrix = _dispatched("lmatrix", 8, "Step matrices of family D on a linear scene: "
                      "lmatrix(D, P, C, t, h, M, Q, W) -> s; M alone where Q has no rows (s may then be 0)")
lwork = _dispatched("lwork", 2, "Stack work arrays of family D's step matrices: lwork(D, P)",
                    scratch=True)
ndof = _constant("ndof", "Degrees of freedom n of the scene (z has 2n entries).")
ncoef = _constant("ncoef", "Length of the scene's time-coefficient vector.")
diagonal = _constant("diagonal", "Whether the scene's H is quadratic with S(t) and dS/dt diagonal (scenes.quadratic).")
is_linear = _constant("linear", "Whether H is quadratic in z, so implicit steps solve linear equations (no Newton "
                      "iteration to convergence).")
interleaved = _constant("interleaved", "Whether family D's step computes each coefficient row where a stage first "
                        "uses it (kernels.families.row), rather than the loop computing every row before the step.")
