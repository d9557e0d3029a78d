"""Cache-sized row blocks of (K, H, W) cubes, spread over a few threads.

NumPy releases the GIL inside its loops, so each thread's ufuncs run on their own core.
A block holds every band of a few rows (about ``BLOCK_BYTES`` per array), so the
temporaries of a multi-step computation stay in cache and the cube is read once.
Thread t gets the t-th contiguous span of rows and walks it block by block. While blocks run
on several threads, BLAS (matrix products inside a block) is held to one thread each:
OpenBLAS's own threads on top of ours made the subspace prox 2.5× slower on two cores.
A host backend's threads (its pocketfft ``workers`` and the blocks' threads) are
:func:`host_threads`: ``CLSDCAM_THREADS`` when set (how ``clsdcam batch`` gives each worker process
its share of the cores), else the cores this process may run on.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from functools import lru_cache
from typing import Callable

import numpy as np

from ..errors import InputError

THREADS_VARIABLE = "CLSDCAM_THREADS"
BLOCK_BYTES = 2 << 20     # per array: measured best on a 2-core Zen 3 (512 KiB L2, 32 MiB L3), 64×576×800


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one, else all)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity on this system (macOS, Windows)
        return os.cpu_count() or 1


def host_threads() -> int:
    """Threads of a host backend: ``CLSDCAM_THREADS`` (an integer ≥ 1) when set, else :func:`available_cores`."""
    text = os.environ.get(THREADS_VARIABLE, "").strip()
    if not text:
        return available_cores()
    if not text.isdigit() or int(text) < 1:
        raise InputError(f"{THREADS_VARIABLE}={text!r}: expected an integer ≥ 1 (threads of a host solver)")
    return int(text)


@lru_cache(maxsize=4)
def _pool(workers: int) -> ThreadPoolExecutor:
    """A pool of ``workers`` threads, kept for the few sizes in use (an evicted pool's idle threads exit
    when it is collected)."""
    return ThreadPoolExecutor(workers, thread_name_prefix="clsdcam-blocks")


def rows_per_block(row_bytes: int) -> int:
    return max(1, BLOCK_BYTES // max(row_bytes, 1))


def spans(n_rows: int, parts: int) -> list[tuple[int, int]]:
    """``parts`` contiguous [start, stop) spans covering n_rows (empty ones dropped)."""
    edges = [n_rows * i // parts for i in range(parts + 1)]
    return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def map_blocks(work: Callable[[int, int, dict], object], n_rows: int, row_bytes: int, workers: int) -> list:
    """``work(y0, y1, scratch)`` over row blocks covering [0, n_rows); its results in row order.

    ``scratch`` is a dict private to the calling thread, for buffers reused across its blocks. A Ctrl-C while the
    threads work is raised once they have finished, so the caller's handler (the driver's: the best iterate back into
    the algorithm's arrays) runs with no thread still writing.
    """
    block = rows_per_block(row_bytes)

    def walk(span):
        scratch: dict = {}
        return [work(y0, min(y0 + block, span[1]), scratch) for y0 in range(span[0], span[1], block)]

    parts = spans(n_rows, max(1, min(workers, -(-n_rows // block))))
    if len(parts) == 1:
        return walk(parts[0])
    walks = _Walks()
    with single_threaded_blas():
        try:                           # a Ctrl-C may come while the spans are still being submitted
            futures = [_pool(len(parts)).submit(walks.run, walk, part) for part in parts]
            return [r for future in futures for r in future.result()]
        except KeyboardInterrupt:      # no span starts after a Ctrl-C is seen, and those running finish first
            walks.stop()
            raise


class _Walks:
    """The spans' walks on the pool: after :meth:`stop` none starts, and it returns once none is running."""

    def __init__(self):
        self._changed = threading.Condition()
        self._running, self._stopped = 0, False

    def run(self, walk, span) -> list:
        with self._changed:
            if self._stopped:
                return []
            self._running += 1
        try:
            return walk(span)
        finally:
            with self._changed:
                self._running -= 1
                self._changed.notify_all()

    def stop(self) -> None:
        with self._changed:
            self._stopped = True
            self._changed.wait_for(lambda: self._running == 0)


@lru_cache(maxsize=1)
def _blas_controller():
    """threadpoolctl's view of the loaded BLAS libraries (made on first use)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def single_threaded_blas():
    """A context holding BLAS libraries to one thread (threadpoolctl), or nothing when none is loaded."""
    controller = _blas_controller()
    return controller.limit(limits=1, user_api="blas") if controller.select(user_api="blas").lib_controllers \
        else nullcontext()


def scratch_buffer(scratch: dict, name: str, shape, dtype) -> np.ndarray:
    """A ``shape`` array from the thread's ``scratch`` (kept and reused across its blocks; contents undefined)."""
    size = int(np.prod(shape))
    held = scratch.get(name)
    if held is None or held.size < size or held.dtype != np.dtype(dtype):
        held = scratch[name] = np.empty(size, dtype)
    return held[:size].reshape(shape)
