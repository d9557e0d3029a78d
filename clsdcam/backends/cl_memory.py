"""OpenCL memory on CPU devices: buffers over our own NumPy memory, and host views of device arrays.

CPU devices share the host's memory, so the backend allocates their buffers with USE_HOST_PTR over
128-byte-aligned NumPy memory (PoCL is zero-copy only when aligned): mapping one then costs nothing,
and NumPy's transparent huge pages on large allocations made pocketfft's passes over mapped cubes
20–25 % faster than on the driver's own memory.

That host memory is ours, not the driver's, so it must outlive the work queued on it. A buffer's host
memory is kept when Python lets go of the buffer, until a marker enqueued at that moment has completed:
the in-order queue has then finished everything that could still read or write it (the queue's events,
not reference counts, decide). The allocator itself, when Python lets go of it (the last buffer dropped, a
backend gone) or at exit, first waits for its queue: the memory it still holds goes only when nothing queued
can touch it (a CPU runtime's worker threads otherwise write into freed NumPy memory: Intel's CPU runtime
aborted on a corrupted heap after the parity tests under load).
"""
from __future__ import annotations

import weakref
from collections import deque
from contextlib import contextmanager

import numpy as np
import pyopencl as cl

ALIGNMENT = 128
MAP_FLAGS = {"r": cl.map_flags.READ, "w": cl.map_flags.WRITE_INVALIDATE_REGION,
             "rw": cl.map_flags.READ | cl.map_flags.WRITE}


class HostBuffer(cl.Buffer):
    """A USE_HOST_PTR buffer (a Python subclass, so that its end can be observed)."""


class HostBuffers:
    """The allocator of CPU devices: :class:`HostBuffer` over aligned NumPy memory, each buffer's memory
    retired through a marker event when the buffer is dropped (see the module docstring)."""

    FLAGS = cl.mem_flags.READ_WRITE | cl.mem_flags.USE_HOST_PTR

    def __init__(self, queue):
        self.queue = queue
        self._dropped: deque = deque()     # (marker, memory) of dropped buffers: appended on any thread, by GC
        self._retiring: list[tuple[cl.Event, np.ndarray]] = []
        weakref.finalize(self, _finish_then_release, queue, self._dropped, self._retiring)

    def __call__(self, nbytes: int) -> HostBuffer:
        self.release_finished()
        memory = aligned_bytes(max(nbytes, 1))
        buffer = HostBuffer(self.queue.context, self.FLAGS, hostbuf=memory)
        weakref.finalize(buffer, self._retire, memory).atexit = False    # at exit the queue may be gone
        return buffer

    def _retire(self, memory: np.ndarray):
        """The buffer is gone from Python: keep its memory until the queue has passed this point."""
        self._dropped.append((cl.enqueue_marker(self.queue), memory))

    def release_finished(self):
        """Let go of the memory of dropped buffers whose queued work has completed."""
        while self._dropped:
            self._retiring.append(self._dropped.popleft())
        done = cl.command_execution_status.COMPLETE
        self._retiring[:] = [(event, memory) for event, memory in self._retiring
                             if event.command_execution_status != done]

    def retiring(self) -> int:
        """Dropped buffers whose memory is still kept (for tests)."""
        return len(self._retiring) + len(self._dropped)


def _finish_then_release(queue, dropped: deque, retiring: list):
    """The allocator is gone (or Python exits): wait for everything queued, then let its held memory go."""
    queue.finish()
    dropped.clear()
    retiring.clear()


def aligned_bytes(nbytes: int, alignment: int = ALIGNMENT) -> np.ndarray:
    """``nbytes`` of NumPy memory starting on an ``alignment``-byte boundary."""
    raw = np.empty(nbytes + alignment, np.uint8)
    start = -raw.ctypes.data % alignment
    return raw[start:start + nbytes]


@contextmanager
def mapped(queue, array, mode: str):
    """The host view of a device array for the duration of the block (mapping waits for queued work)."""
    host, _ = cl.enqueue_map_buffer(queue, array.base_data, MAP_FLAGS[mode], array.offset, array.shape, array.dtype)
    try:
        yield host
    finally:
        host.base.release(queue)
