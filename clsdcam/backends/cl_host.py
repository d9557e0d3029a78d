"""The host path's code on OpenCL CPU devices: the ``HOST_CODE`` primitives (see ``base.py``) run the
host's BLAS and cache-blocked NumPy code on mapped, zero-copy device buffers, and A runs the host's chunked
pocketfft pipeline on them.

On PoCL these beat the kernels 1.3–25× (BLAS for ``gram``/``bandmix``, cache blocks for ``subspace_tv``,
whose kernels must write and read two band cubes). The device path's counterpart is
``cl_kernel_code.KernelCode``, with the same methods: the backend holds one of the two, chosen once from its
path.
"""
from __future__ import annotations

from .cl_memory import mapped
from .convolution import host_path
from .host_linalg import bandmix as host_bandmix
from .host_linalg import gram as host_gram
from .host_tv import subspace_tv_blocks, tv_norm_blocks


class MappedHostCode:
    """``tv_norm``, ``gram``, ``bandmix``, ``subspace_tv`` and the convolution of one OpenCL backend, on mapped
    buffers."""

    path = "host"

    def __init__(self, backend):
        self.backend = backend

    def convolution(self, transfer, filters, field_shape, skip_unseen: bool = True):
        """The chunked pocketfft pipeline on mapped buffers (``convolution.HostPathConvolution``)."""
        return host_path(self.backend, transfer, filters, field_shape, skip_unseen)

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
