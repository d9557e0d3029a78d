"""Linear algebra along the band axis of host cubes, through BLAS: the NumPy backend's, and the OpenCL
backend's on CPU devices (on mapped buffers, where BLAS beats PoCL's kernels ~10×)."""
from __future__ import annotations

import numpy as np

GRAM_CHUNK = 8192  # pixels per partial Gram matrix


def gram(x: np.ndarray) -> np.ndarray:
    """G = X Xᵀ (K×K, float64) of the bands×pixels unfolding X of x: products summed over chunks of
    GRAM_CHUNK pixels in x's dtype (BLAS), the chunks added in float64, without a float64 copy of the cube."""
    flat = x.reshape(x.shape[0], -1)
    total = np.zeros((flat.shape[0], flat.shape[0]))
    for start in range(0, flat.shape[1], GRAM_CHUNK):
        chunk = flat[:, start:start + GRAM_CHUNK]
        total += chunk @ chunk.T
    return total


def bandmix(x: np.ndarray, matrix, out: np.ndarray | None = None) -> np.ndarray:
    """out_k = Σ_j M_kj x_j: a K×J matrix applied along the band axis of x (J bands); ``out`` must not
    share memory with x."""
    flat = x.reshape(x.shape[0], -1)
    shape = (np.shape(matrix)[0],) + x.shape[1:]
    target = np.empty(shape, x.dtype) if out is None else out
    np.dot(np.asarray(matrix, dtype=x.dtype), flat, out=target.reshape(shape[0], -1))
    return target
