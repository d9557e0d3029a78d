"""The host path's code on OpenCL CPU devices: the ``HOST_CODE`` primitives (see ``base.py``) run the
host's BLAS and cache-blocked NumPy code on mapped, zero-copy device buffers.

On PoCL these beat the kernels 1.3–25× (BLAS for ``gram``/``bandmix``, cache blocks for ``subspace_tv``,
whose kernels must write and read two band cubes). Same signatures as the backend's kernel versions;
the OpenCL backend binds these in their place on the host path.
"""
from __future__ import annotations

from .cl_memory import mapped
from .host_linalg import bandmix as host_bandmix
from .host_linalg import gram as host_gram
from .host_tv import subspace_tv_blocks, tv_norm_blocks


class MappedHostCode:
    """``tv_norm``, ``gram``, ``bandmix`` and ``subspace_tv`` of one OpenCL backend, on mapped buffers."""

    def __init__(self, backend):
        self.backend = backend

    def tv_norm(self, x, weights) -> float:
        with mapped(self.backend.queue, x, "r") as host_x:
            return tv_norm_blocks(host_x, weights, self.backend.workers)

    def gram(self, x):
        with mapped(self.backend.queue, x, "r") as host_x:
            return host_gram(host_x)

    def bandmix(self, x, matrix, out=None):
        be = self.backend
        target = be.target(out, (len(matrix),) + x.shape[1:], x)
        with mapped(be.queue, x, "r") as host_x, mapped(be.queue, target, "w") as host_out:
            host_bandmix(host_x, matrix, out=host_out)
        return be.deliver(target, out)

    def subspace_tv(self, c, basis, tau, weights, out=None):
        be = self.backend
        target = be.target(out, c.shape, c)
        with mapped(be.queue, c, "r") as host_c, mapped(be.queue, target, "w") as host_out:
            subspace_tv_blocks(host_c, basis, tau, weights, host_out, be.workers)
        return be.deliver(target, out)
