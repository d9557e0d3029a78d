"""A's filtered convolution on the host: bands in cache-sized chunks through pocketfft, pruned transforms.

The operator of ``convolution.py`` (backends return it on the host path):

    forward:   b = Σ_k F_k ⊙ [irfft2(Ĥ · rfft2(v_k))]_{0:H, 0:W}
    adjoint:   (Aᵀr)_k = irfft2(conj(Ĥ) · rfft2(pad₀(F_k ⊙ r)))

computed in chunks of bands whose spectra fit the cache (``CHUNK_BYTES``), each chunk going
through every stage before the next starts, so only the cube itself crosses main memory.
Pruned transforms: the window sits at the FFT origin, so the forward's inverse transform
runs its row pass on the H rows it keeps only, and the adjoint's forward transform its row
pass on the H non-zero rows only (the rest of each row is zero padding, done by ``n=``); the
adjoint's inverse is two passes too, in place (``host_fft``: faster than pocketfft's own irfft2).
Bands no filter sees are skipped: they add nothing to b and get no gradient.

It runs on NumPy arrays: the NumPy backend's own, or an OpenCL CPU device's mapped buffers (zero-copy).
"""
from __future__ import annotations

import numpy as np
import scipy.fft

from .host_fft import irfft2, irfft2_to_window, rfft2_of_window

CHUNK_BYTES = 4 << 20      # spectrum bytes per chunk of bands: measured best at 64×576×800 (2 bands)


def seen_bands(filters: np.ndarray) -> np.ndarray:
    """(K,) bool: bands whose filter is non-zero somewhere (the others add nothing to b and get no gradient)."""
    return np.any(np.asarray(filters) != 0, axis=tuple(range(1, np.ndim(filters))))


def band_chunks(seen: np.ndarray, per_chunk: int) -> list[tuple[int, int]]:
    """Contiguous runs of seen bands, cut into [start, stop) chunks of at most ``per_chunk`` bands."""
    chunks, k, n = [], 0, len(seen)
    while k < n:
        if not seen[k]:
            k += 1
            continue
        stop = k
        while stop < n and seen[stop] and stop - k < per_chunk:
            stop += 1
        chunks.append((k, stop))
        k = stop
    return chunks


class HostConvolution:
    """The filtered convolution for one transfer function and filter set, on host (NumPy) arrays."""

    def __init__(self, transfer: np.ndarray, filters: np.ndarray, field_shape, dtype, workers: int,
                 skip_unseen: bool = True):
        self.dtype = np.dtype(dtype)
        cdtype = np.result_type(self.dtype, np.complex64)
        self.field_shape = tuple(field_shape)
        self.sensor_shape = tuple(filters.shape[-2:])
        self.n_bands = filters.shape[0]
        self.workers = workers
        self.transfer = np.ascontiguousarray(transfer, dtype=cdtype)
        self.conj_transfer = np.conj(self.transfer)
        self.filters = np.ascontiguousarray(filters, dtype=self.dtype)
        self.skip_unseen = skip_unseen
        self.seen = seen_bands(filters) if skip_unseen else np.ones(self.n_bands, bool)
        per_band = self.transfer.nbytes
        self.chunks = band_chunks(self.seen, max(1, CHUNK_BYTES // per_band))

    def forward(self, v: np.ndarray, out: np.ndarray) -> np.ndarray:
        """b = Σ_k F_k ⊙ [irfft2(Ĥ · rfft2(v_k))]_{0:H, 0:W}, chunk by chunk."""
        out[...] = 0
        for k0, k1 in self.chunks:
            spectrum = scipy.fft.rfft2(v[k0:k1], workers=self.workers)
            spectrum *= self.transfer
            window = irfft2_to_window(spectrum, self.field_shape, self.sensor_shape, self.workers, overwrite=True)
            out += np.einsum("khw,khw->hw", self.filters[k0:k1], window)
        return out

    def adjoint(self, r: np.ndarray, out: np.ndarray, y: np.ndarray | None = None, step: float = 1.0) -> np.ndarray:
        """out = Aᵀr, or the gradient step out = y − step·Aᵀr when y is given (out may be y)."""
        for k0, k1 in self.chunks:
            spectrum = rfft2_of_window(self.filters[k0:k1] * r, self.field_shape, self.workers)
            spectrum *= self.conj_transfer
            gradient = irfft2(spectrum, self.field_shape, self.workers, overwrite=True)
            if y is None:
                out[k0:k1] = gradient
            else:
                gradient *= -step
                np.add(gradient, y[k0:k1], out=out[k0:k1])    # z = y − s·Aᵀr
        self._unseen(out, y)
        return out

    def _unseen(self, out, y):
        """Bands no filter sees: Aᵀr = 0 there, so the gradient step leaves y."""
        for k in np.flatnonzero(~self.seen):
            out[k] = 0 if y is None else y[k]

    def with_filters(self, filters: np.ndarray) -> "HostConvolution":
        return HostConvolution(self.transfer, filters, self.field_shape, self.dtype, self.workers, self.skip_unseen)

    def transforms(self) -> int:
        """2-D transforms per forward + adjoint pair (pruned ones counted as whole)."""
        return 4 * int(self.seen.sum())
