"""The small dense solve of the implicit steps: Cramer's rule for 2 x 2 systems, elimination otherwise."""
import numpy as np
import pytest
from numba import njit

from cosymp.kernels.dispatch import JIT
from cosymp.kernels.linalg import solve


@njit(**{**JIT, "cache": False})  # the kernels' flags: an FMA may form det
def _solved(A, B, k):
    X = B.copy()
    ok = solve(A.copy(), X, A.shape[0], k)
    return ok, X


def solved(A, B):
    """(ok, A^-1 B) by kernels.linalg.solve, on copies; B a vector or columns."""
    return _solved(A, B, 1 if B.ndim == 1 else B.shape[1])


def cases(seed, n, count):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        A = rng.normal(size=(n, n))
        if np.linalg.cond(A) < 1e3:
            yield A, rng.normal(size=n), rng.normal(size=(n, n))


@pytest.mark.parametrize("n", [2, 3])
def test_the_solve_agrees_with_lapack_for_vectors_and_columns(n):
    for A, b, B in cases(n, n, 200):
        for rhs in (b, B):
            ok, X = solved(A, rhs)
            expected = np.linalg.solve(A, rhs)
            scale = np.linalg.cond(A) * np.max(np.abs(expected))
            assert ok and np.max(np.abs(X - expected)) <= 8 * np.finfo(float).eps * scale


def test_a_complex_system_as_the_complex_step_gives_it():
    A = np.array([[1.0 + 1e-50j, -0.05], [0.05, 1.0]])
    for rhs in (np.array([0.3 + 2e-50j, -0.7]), np.array([[0.3 + 2e-50j, 1.0], [-0.7, 1e-50j]])):
        ok, x = solved(A, rhs)
        expected = np.linalg.solve(A, rhs)
        assert ok and np.allclose(x, expected, rtol=1e-15, atol=0)
        assert np.allclose(x.imag, expected.imag, rtol=1e-13, atol=0)


@pytest.mark.parametrize("A", [[[1.0, 2.0], [2.0, 4.0]], [[3.0, 1.0], [1.0, 1.0 / 3.0]]])
def test_a_singular_system_is_refused(A):
    """The second's det is 1 - 3 fl(1/3): 0 by elimination, -5.6e-17 where an FMA forms it."""
    ok, _ = solved(np.array(A), np.array([1.0, 1.0]))
    assert not ok


def test_a_tiny_determinant_is_left_to_elimination():
    """det = 1e-320 is subnormal and its reciprocal overflows; the columns' solve stays exact."""
    A = 1e-160 * np.eye(2)
    ok, X = solved(A, np.eye(2))
    assert ok and np.array_equal(X, 1e160 * np.eye(2))
    ok, x = solved(A, np.array([1e-160, 3e-160]))
    assert ok and np.array_equal(x, [1.0, 3.0])


def test_a_determinant_beyond_floating_point_is_left_to_elimination():
    """det = 2e300 * 3e300 overflows; elimination's pivots do not."""
    A = np.array([[2e300, 1e300], [1.0, 3e300]])
    b = np.array([1e300, 1.0])
    ok, x = solved(A, b)
    assert ok and np.all(np.isfinite(x)) and np.allclose(x, np.linalg.solve(A, b), rtol=1e-14, atol=0)
