"""The numba internals cosymp relies on, checked one by one with a message saying what changed.

pyproject.toml bounds numba and llvmlite to the versions these pass on. A newer numba may move
or rename any of them; this file says which, before a kernel fails in an obscure way.
"""
import importlib.metadata
import inspect
import re

import numpy as np
import pytest
from numba import njit, types
from numba.core import caching, cgutils
from numba.core.errors import NumbaError
from numba.extending import overload
from numba.np import arrayobj
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

from cosymp.kernels import cachestamp
from cosymp.kernels.borrow import borrow
from cosymp.kernels.dispatch import Vectorizing
from cosymp.kernels.stack import stack_array

WHERE = {
    "caching": "cosymp/kernels/cachestamp.py",
    "stack": "cosymp/kernels/stack.py",
    "borrow": "cosymp/kernels/borrow.py",
    "dispatch": "cosymp/kernels/dispatch.py",
    "vectorizing": "cosymp/kernels/dispatch.py (Vectorizing)",
    "entry": "cosymp/integrate.py (_entry)",
}


def changed(what, where):
    return (f"numba {importlib.metadata.version('numba')} changed {what}, which {WHERE[where]} relies on: "
            "install the numba version pyproject.toml names, or update that module")


def test_the_installed_versions_are_within_the_pins():
    reqs = {r.name: r for r in map(Requirement, importlib.metadata.requires("cosymp"))}
    for name in ("numba", "llvmlite"):
        spec = reqs[name].specifier if name in reqs else SpecifierSet()
        assert any(s.operator == "<" for s in spec), f"pyproject.toml must bound {name} from above"
        assert importlib.metadata.version(name) in spec, f"{name} {importlib.metadata.version(name)} is not {spec}"


def test_the_cache_internals_are_where_cachestamp_expects_them():
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    assert impl is not None and isinstance(getattr(impl, "_locator_classes", None), list), \
        changed("the cache implementation's list of locators (CacheImpl._locator_classes)", "caching")
    assert cachestamp.PackageStampLocator in impl._locator_classes, changed("how locators are chosen", "caching")
    index = caching.IndexDataCacheFile(cache_path="/nonexistent", filename_base="probe", source_stamp="s")
    for name in ("_cache_path", "_index_path", "_load_index", "_save_index", "_save_data", "_data_name"):
        assert hasattr(index, name), changed(f"IndexDataCacheFile.{name}", "caching")
    assert list(inspect.signature(caching.IndexDataCacheFile.save).parameters) == ["self", "key", "data"], \
        changed("IndexDataCacheFile.save's signature", "caching")
    assert caching.IndexDataCacheFile.save is cachestamp._save, changed("where a cache entry is saved", "caching")


def test_the_code_generation_helpers_exist():
    for module, name, where in ((cgutils, "alloca_once", "stack"), (cgutils, "get_null_value", "borrow"),
                                (arrayobj, "make_array", "stack"), (arrayobj, "populate_array", "stack")):
        assert callable(getattr(module, name, None)), changed(f"{module.__name__}.{name}", where)
    assert hasattr(types, "IntegerLiteral"), changed("types.IntegerLiteral", "stack")
    assert {"jit_options", "inline", "strict"} <= set(inspect.signature(overload).parameters), \
        changed("overload's options (jit_options, inline, strict)", "dispatch")


@njit
def _stack_and_borrow(x):
    buf = stack_array((3, 2), x)
    for i in range(3):
        for j in range(2):
            buf[i, j] = x[i] * (j + 1)
    y = borrow(x)
    total = 0.0
    for i in range(3):
        total += buf[i, 0] + buf[i, 1] + y[i]
    return total, buf.shape[0], buf.strides[0]


def test_stack_arrays_and_borrowed_arrays_compile_and_hold_their_values():
    try:
        total, rows, stride = _stack_and_borrow(np.array([1.0, 2.0, 3.0]))
    except (NumbaError, TypeError, AttributeError) as e:
        pytest.fail(changed(f"code generation for stack arrays or borrowed arrays ({type(e).__name__}: {e})",
                            "stack"))
    assert (total, rows, stride) == (24.0, 3, 16)


def test_simulate_calls_the_compiled_entry_point_with_the_dispatchers_result():
    from cosymp import integrate
    from cosymp.kernels.loops import propagate_one

    setup = integrate.Setup.make("kapitza", "rk4")
    run = integrate.simulate(setup, 0.01, 0.1)
    entry = integrate._ENTRIES.get((propagate_one, "rk4", type(setup.P)))
    assert entry is not None and entry is not propagate_one, \
        changed("Dispatcher.overloads or CompileResult.entry_point (simulate fell back to the dispatcher)", "entry")
    Z, PT = integrate.initial_states(setup), np.empty(1)
    K = len(run.t)
    rec = (np.empty(K), np.empty((K, 1, 2)), np.empty((K, 1)), np.empty((0, 1, 2)), np.empty((K, 1)))
    assert propagate_one(setup.data, setup.P, 0.0, 0.01, Z, PT, K - 1, 1, *rec, False, True) == (0, K - 1)
    assert np.array_equal(rec[1], run.z) and np.array_equal(rec[2], run.pt) and np.array_equal(rec[4], run.H)
    with pytest.raises(ValueError, match="one trajectory"):
        propagate_one(setup.data, setup.P, 0.0, 0.01, np.repeat(Z, 2, axis=0), np.empty(2), 1, 1, *rec, False, True)


def _run_or_partial(setup, h, T):
    """simulate's run, or the part of it before the step that failed."""
    from cosymp import integrate
    from cosymp.errors import RunError

    try:
        return integrate.simulate(setup, h, T)
    except RunError as err:
        return err.partial


def test_one_trajectorys_loop_only_reads_its_start_so_simulate_shares_it_between_runs_and_threads():
    """simulate passes the setup's own start and one shared p_t to the loop of one trajectory, uncopied
    (0.3 us and 0.26 us of a call's 4): the loop must not write them, also where a step fails, and
    runs of the same setup at once in threads are each the run alone, to the bit."""
    from concurrent.futures import ThreadPoolExecutor

    from cosymp import integrate

    for scene, method, h, T, values in (("kapitza", "midpoint", 0.01, 2.0, {}), ("modulated", "rk8", 0.1, 5.0, {}),
                                        ("kapitza", "midpoint", 0.5, 100.0, {"q0": 3.0, "a": 0.3, "nu": 40.0})):
        setup = integrate.Setup.make(scene, method, values)
        first, shared = setup.first.copy(), integrate.UNREAD_PT.copy()
        alone = _run_or_partial(setup, h, T)
        assert np.array_equal(setup.first, first) and np.array_equal(integrate.UNREAD_PT, shared), (scene, method)
        assert np.array_equal(alone.z[0], setup.start) and alone.pt[0, 0] == -alone.H[0, 0]
        with ThreadPoolExecutor(2) as pool:
            for r in [f.result() for f in [pool.submit(_run_or_partial, setup, h, T) for _ in range(8)]]:
                assert np.array_equal(r.z, alone.z) and np.array_equal(r.pt, alone.pt) and np.array_equal(r.H, alone.H)


def _product_2x2(P, a, b, out):
    """A 2 x 2 matrix product written out, as a step's small matrices are: straight-line code. The
    entries are read before any is written (out might alias a or b, and LLVM then keeps the order
    of loads and stores), as a step reads its state into locals. P: a scene's parameters."""
    a0, a1, a2, a3 = a[0], a[1], a[2], a[3]
    b0, b1, b2, b3 = b[0], b[1], b[2], b[3]
    out[0] = a0 * b0 + a1 * b2
    out[1] = a0 * b1 + a1 * b3
    out[2] = a2 * b0 + a3 * b2
    out[3] = a2 * b1 + a3 * b3


_OPTIONS = {"fastmath": {"contract"}, "error_model": "numpy"}
_product_inlined = njit(forceinline=True, **_OPTIONS)(_product_2x2)


def _through_a_callee(P, a, b, out):
    """The product in a callee inlined by LLVM, as a loop's step is."""
    _product_inlined(P, a, b, out)


def test_cosymps_compiler_vectorizes_one_function_for_a_scene_of_two_degrees_of_freedom():
    """Vectorizing optimizes the function it compiles with LLVM's SLP vectorizer when its arguments
    hold the parameters of a scene of two or more degrees of freedom (charged), not one (modulated),
    and nothing else: the callee first compiled inside it keeps numba's scalar code in its own
    library (other callers link that one), and numba's own compiler vectorizes neither (so the
    check can fail)."""
    from cosymp.integrate import Setup

    ours = njit(pipeline_class=Vectorizing, **_OPTIONS)(_through_a_callee)
    plain = njit(**_OPTIONS)(_through_a_callee)
    a, b = np.array([1.0, 2.0, 3.0, 4.0]), np.array([5.0, 6.0, 7.0, 8.0])
    vector = re.compile(r"<\d+ x double>")
    for scene, vectorized in (("charged", True), ("modulated", False)):
        P = Setup.make(scene, "midpoint").P
        for fn, expected in ((ours, vectorized), (plain, False), (_product_inlined, False)):
            out = np.empty(4)
            fn(P, a, b, out)
            assert np.array_equal(out, (a.reshape(2, 2) @ b.reshape(2, 2)).ravel())
            ir = fn.inspect_llvm(fn.signatures[-1])
            assert bool(vector.search(ir)) == expected, changed(
                f"how a library's final module is optimized (CPUCodeLibrary._optimize_final_module, "
                f"CPUCodegen._module_pass_manager): {scene}, {fn.py_func.__name__}"
                f"{' by Vectorizing' if fn is ours else ''}, vector arithmetic {not expected}", "vectorizing")
