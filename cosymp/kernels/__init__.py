"""Numba kernels: generic loops specialized at compile time per scene and method family."""
