"""The device path's code on OpenCL: the ``HOST_CODE`` primitives (see ``base.py``) as kernels, and A from the
backend's primitives.

The host path's counterpart is ``cl_host.MappedHostCode``, with the same methods: the backend holds one of the
two, chosen once from its path, and its ``tv_norm``, ``gram``, ``bandmix``, ``subspace_tv`` and
``convolution`` call it.
"""
from __future__ import annotations

import hashlib

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .base import ints, total
from .convolution import device_path

GRAM_PIXELS = 64      # pixels per gram work item (at least)
GRAM_GROUPS = 4       # gram work-groups per compute unit (at most), each for every (i, j)
BANDMIX_ROWS = 8      # output bands per bandmix work item (as in bandmix.cl)
BANDMIX_TILE = 32     # pixels per bandmix work-group (as in bandmix.cl)
BANDMIX_GROUP = 256   # bandmix work items per group (at most): 8 row blocks, every band of 64
MATRICES = 8          # bandmix matrices kept on the device (a basis, its transpose, the last moves' mappings)


class KernelCode:
    """``tv_norm``, ``gram``, ``bandmix``, ``subspace_tv`` and the convolution of one OpenCL backend, as kernels."""

    path = "device"

    def __init__(self, backend):
        self.backend = backend
        self._band_cubes = None            # (shape, expanded, stepped) of subspace_tv
        self._matrices: dict = {}          # (shape, digest) -> device copy, least recently used first

    def convolution(self, transfer, filters, field_shape, skip_unseen: bool = True):
        """fft2 → cmul → ifft2 → mask_sum on whole cubes (``convolution.PrimitiveConvolution``)."""
        return device_path(self.backend, transfer, filters, field_shape, skip_unseen)

    def tv_norm(self, x, weights) -> float:
        """Partial sums in ACC, an element's forward differences a term (reduce.cl's tv_norm)."""
        be = self.backend
        acc = be.kernels.acc.type
        w = [acc(wd if wd > 0 else 0.0) for wd in weights]
        return be.drained(total(be.kernels.reduce("tv_norm", x.size, x, *ints(*x.shape), *w)))

    def gram(self, x) -> np.ndarray:
        """Work item (t, i, j) sums x_i·x_j over pixels t, t + T, … (j ≥ i) in ACC, its group adds them; the host adds
        the groups' partials."""
        be, kernels = self.backend, self.backend.kernels
        k, pixels = x.shape[0], x.size // x.shape[0]
        local = kernels.local_1d
        groups = max(1, min(-(-pixels // (GRAM_PIXELS * local)), GRAM_GROUPS * be.device.max_compute_units))
        partial = cla.empty(be.queue, (groups, k, k), kernels.acc)
        partial.fill(0, queue=be.queue)
        scratch = cl.LocalMemory(local * kernels.acc.itemsize)
        kernels.launch("gram", (groups * local, k, k), (local, 1, 1), partial, scratch, x, np.int32(k),
                       np.int64(pixels))
        upper = np.triu(be.to_host(partial).sum(axis=0, dtype=np.float64))
        return upper + np.triu(upper, 1).T

    def bandmix(self, x, matrix, out=None):
        """One work item per pixel and BANDMIX_ROWS output bands; a group of BANDMIX_TILE pixels and as many row
        blocks as BANDMIX_GROUP, the device and the kernel allow reads its pixels' x once for them all."""
        be = self.backend
        rows, cols = np.shape(matrix)
        target = be.target(out, (rows,) + x.shape[1:], x)
        pixels = x.size // x.shape[0]
        blocks = -(-rows // BANDMIX_ROWS)
        per_group = max(1, min(blocks, min(BANDMIX_GROUP, be.kernels.group_limit("bandmix")) // BANDMIX_TILE))
        grid = (-(-pixels // BANDMIX_TILE) * BANDMIX_TILE, -(-blocks // per_group) * per_group)
        be.kernels.launch("bandmix", grid, (BANDMIX_TILE, per_group), target, x, self._matrix(matrix),
                          np.int32(rows), np.int32(cols), np.int64(pixels))
        return be.deliver(target, out)

    def _matrix(self, matrix):
        """The device copy of a small bandmix matrix, uploaded the first time it is seen (a subspace mixes by its
        basis and its transpose every iteration: a blocking upload each time would stall the queue twice an
        iteration), the MATRICES last used kept."""
        be = self.backend
        host = np.ascontiguousarray(matrix, dtype=be.dtype)
        key = (host.shape, hashlib.blake2b(host.tobytes(), digest_size=16).digest())
        device = self._matrices.pop(key, None)
        if device is None:
            if len(self._matrices) >= MATRICES:
                del self._matrices[next(iter(self._matrices))]          # the least recently used
            device = cla.to_device(be.queue, host, allocator=be.allocator)
        self._matrices[key] = device                                    # now the most recently used
        return device

    def subspace_tv(self, c, basis, tau, weights, out=None):
        """Expand, the fused haar_tv with max(·, 0), project, through two band cubes kept for the last shape."""
        shape = (basis.shape[0],) + tuple(c.shape[1:])
        if self._band_cubes is None or self._band_cubes[0] != shape:
            self._band_cubes = (shape, self.backend.empty(shape), self.backend.empty(shape))
        _, expanded, stepped = self._band_cubes
        self.bandmix(c, basis, out=expanded)
        self.backend.haar_tv(expanded, tau, weights, out=stepped, nonneg=True)
        return self.bandmix(stepped, np.transpose(basis), out=out)
