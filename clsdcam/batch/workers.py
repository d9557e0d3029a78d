"""Where a batch's chunks run: processes × threads, and the Dask client on them.

An embedded cluster gets min(``workers``, cores) worker processes of max(1, cores // processes)
threads each (:func:`plan_workers`): processes × threads never exceeds the cores, and more
processes than cores would only add cold starts (one per chunk) and memory. Each worker's solver
runs its FFTs (pocketfft) and row blocks on ``CLSDCAM_THREADS`` threads
(:func:`clsdcam.backends.blocks.host_threads`) and pocl its kernels on ``POCL_MAX_PTHREAD_COUNT``
(both set in the worker's environment, :func:`worker_environment`), and a chunk holds BLAS and
OpenMP to as many (:func:`chunk_threads`; Dask starts workers with one BLAS thread). The worker
processes start without Dask's ``MALLOC_TRIM_THRESHOLD_`` (:func:`_spawning_without_malloc_trim`).
In this process (``workers=0``) the solver uses :func:`host_threads`, every core by default; on
an external cluster (``scheduler``) each worker uses its machine's cores, or its ``CLSDCAM_THREADS``.
"""
from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass

from ..backends import THREADS_VARIABLE, available_cores, host_threads
from ..errors import InputError

SPAWN_ENVIRON = "distributed.nanny.pre-spawn-environ"
MALLOC_TRIM = "MALLOC_TRIM_THRESHOLD_"


@dataclass(frozen=True)
class Layout:
    """Where the chunks run: ``processes`` worker processes (0: this process) of ``threads`` threads each on a
    machine of ``cores`` cores, or the cluster at ``scheduler``; ``asked``: the ``--workers`` asked for."""

    processes: int
    threads: int
    cores: int
    asked: int
    scheduler: str | None = None

    def __str__(self) -> str:
        if self.scheduler:
            return f"the workers of {self.scheduler} (each with its machine's cores, or its {THREADS_VARIABLE})"
        if not self.processes:
            return f"this process × {_count(self.threads, 'thread')} on {_count(self.cores, 'core')}"
        capped = f" (--workers {self.asked}: no more processes than cores)" if self.asked > self.processes else ""
        return (f"{_count(self.processes, 'worker')} × {_count(self.threads, 'thread')} on "
                f"{_count(self.cores, 'core')}{capped}")


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def plan_workers(workers: int, scheduler: str | None = None, cores: int | None = None) -> Layout:
    """The :class:`Layout` of a batch on a machine of ``cores`` (default: this process's) cores: ``scheduler``'s
    workers; this process with :func:`host_threads` threads (``workers`` = 0); else min(workers, cores)
    processes × max(1, cores // processes) threads, never more than the cores."""
    cores = cores or available_cores()
    if scheduler:
        return Layout(0, 0, cores, workers, scheduler)
    if workers == 0:
        return Layout(0, host_threads(), cores, 0)
    processes = min(workers, cores)
    return Layout(processes, max(1, cores // processes), cores, workers)


@contextlib.contextmanager
def _spawning_without_malloc_trim():
    """While worker processes start: neither Dask's pre-spawn environment nor this process's (restored after)
    holds ``MALLOC_TRIM_THRESHOLD_``. Set at all, it turns off glibc's adaptive mmap threshold, so every large
    temporary array is mapped and unmapped afresh and its pages faulted in again (about 40 % of the workers' CPU
    time went to the kernel, docs/batch.md)."""
    import dask

    saved = os.environ.pop(MALLOC_TRIM, None)  # an earlier LocalCluster in this process may have left it
    try:
        with dask.config.set({SPAWN_ENVIRON: {k: v for k, v in dask.config.get(SPAWN_ENVIRON, {}).items()
                                              if k != MALLOC_TRIM}}):
            yield
    finally:
        if saved is not None:
            os.environ[MALLOC_TRIM] = saved


def worker_environment(threads: int) -> dict[str, str]:
    """A worker process's environment for ``threads`` threads: its solver's (:func:`host_threads`) and pocl's
    (``POCL_MAX_PTHREAD_COUNT``, read by pocl's pthread device when a worker first builds an OpenCL solver)."""
    return dict.fromkeys((THREADS_VARIABLE, "POCL_MAX_PTHREAD_COUNT"), str(threads))


def chunk_threads():
    """A context holding BLAS and OpenMP to the worker's :func:`host_threads` (Dask starts workers with one BLAS
    thread; a worker given two threads should use them)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=host_threads())


@contextlib.contextmanager
def connect(layout: Layout):
    """A Dask client on the cluster at ``layout.scheduler``, or on an embedded LocalCluster of ``layout.processes``
    one-task processes started by :func:`_spawning_without_malloc_trim` with :func:`worker_environment`; both
    closed on exit."""
    import logging

    from distributed import Client, LocalCluster

    if layout.scheduler:
        try:
            client = Client(layout.scheduler, timeout=30)
        except OSError as exc:
            raise InputError(f"--scheduler {layout.scheduler}: cannot connect ({exc})") from None
        with client:
            yield client
        return
    with _spawning_without_malloc_trim():
        cluster = LocalCluster(n_workers=layout.processes, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=logging.ERROR,
                               env=worker_environment(layout.threads))
    with cluster, Client(cluster) as client:
        yield client
