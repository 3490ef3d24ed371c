"""Compiled (numba) kernels: pure functions on float64 arrays and ints."""
