"""Compiled (numba) kernels of the fast path.

Each kernel mirrors a numpy reference in the thesis layers and is tested against it.
"""
