"""A's filtered convolution on CPU OpenCL devices: the host pipeline on mapped device buffers.

PoCL's buffers live in host memory (the backend allocates them with ALLOC_HOST_PTR), so
mapping them costs nothing: the band-chunked, pruned pocketfft pipeline of
:mod:`clsdcam.backends.host_convolution` runs on them in place, and the rest of the
iteration stays in OpenCL kernels. Mapping waits for the queue, so the order of work holds.
"""
from __future__ import annotations

from contextlib import ExitStack

import pyopencl as cl

from .fft import mapped
from .host_convolution import HostConvolution

READ, WRITE, READ_WRITE = cl.map_flags.READ, cl.map_flags.WRITE_INVALIDATE_REGION, cl.map_flags.READ | cl.map_flags.WRITE


class MappedConvolution:
    """:class:`HostConvolution` over device arrays of one queue."""

    def __init__(self, queue, host: HostConvolution):
        self.queue = queue
        self.host = host
        self.n_bands = host.n_bands

    def forward(self, v, out):
        with ExitStack() as stack:
            self.host.forward(stack.enter_context(mapped(self.queue, v, READ)),
                              stack.enter_context(mapped(self.queue, out, WRITE)))
        return out

    def adjoint(self, r, out, y=None, step: float = 1.0):
        """out = Aᵀr, or y − step·Aᵀr given y (out may be y: then mapped once, for reading and writing)."""
        with ExitStack() as stack:
            host_r = stack.enter_context(mapped(self.queue, r, READ))
            if y is None:
                self.host.adjoint(host_r, stack.enter_context(mapped(self.queue, out, WRITE)))
            elif out.base_data == y.base_data:
                host_y = stack.enter_context(mapped(self.queue, y, READ_WRITE))
                self.host.adjoint(host_r, host_y, host_y, step)
            else:
                host_y = stack.enter_context(mapped(self.queue, y, READ))
                self.host.adjoint(host_r, stack.enter_context(mapped(self.queue, out, WRITE)), host_y, step)
        return out

    def with_filters(self, filters) -> "MappedConvolution":
        return MappedConvolution(self.queue, self.host.with_filters(filters))

    def transforms(self) -> int:
        return self.host.transforms()
