"""The whole batch: the missing frames as chunks, in one process or on Dask distributed workers.

Checks. Before anything is written, every frame still to compute is read once and checked
(:meth:`FrameSource.check`): a frame that cannot be read or holds a NaN/Inf stops the batch with
one line naming it and its first bad pixel; so does a truth that does not match the frames
(:class:`~clsdcam.batch.truth.TruthVideo`).

Workers. Where the chunks run, processes × threads, is :func:`clsdcam.batch.workers.plan_workers`'s
choice (never more than the cores), said in the summary.

Distribution. The frames still missing are cut into contiguous chunks (a chunk is one Dask
task, so warm starts hold inside it). The worker writes its chunk into a temporary file and
renames it to its part (:mod:`clsdcam.batch.parts`): a part is whole or absent. A task that
Dask re-runs after its worker died finds the part already there when the dead worker had
finished it, and keeps it: no frame is lost or written twice. Without Dask (``workers=0``)
the chunks run as one stream in this process, warm starts carried across them.

Progress. Each finished frame is reported once (an event per frame from the workers; a
re-run chunk repeats its events and they are counted once).

Ctrl-C. The finished parts are kept; when they hold some frames, the KeyboardInterrupt is a
:class:`~clsdcam.batch.spec.BatchInterrupted` saying how many, and running the same batch
again computes only the others.
"""
from __future__ import annotations

import contextlib
import shutil
import threading
import time
import uuid
from dataclasses import replace
from pathlib import Path

from ..extras import require
from ..io import check_output
from ..provenance import provenance
from .frames import FrameSource
from .parts import assemble, chunks, claim, finished_parts, missing_frames, part_path, parts_dir
from .spec import BatchInterrupted, BatchSpec, BatchSummary
from .stream import Carried, failure_text, frame_calibration, run_stream, solve_chunk
from .truth import TruthVideo
from .workers import chunk_threads, connect, plan_workers


def run_batch(spec: BatchSpec, output, workers: int = 1, scheduler: str | None = None, chunk: int | None = None,
              overwrite: bool = False, progress=None, on_plan=None, truth=None) -> BatchSummary:
    """Reconstruct every frame not yet in ``output``'s parts, then (re)build ``output``.

    ``workers`` = 0 (and no scheduler): one in-process stream (warm starts carried across its
    chunks); otherwise Dask distributed, an embedded LocalCluster (``workers`` processes at most, as
    :func:`plan_workers` chooses) or the cluster at ``scheduler``. ``chunk`` defaults to
    ⌈missing / workers⌉, at most MAX_CHUNK. ``on_plan(n_frames, n_missing, layout)`` is called once
    the missing frames are known, ``progress(k)`` as k more frames are done. With ``truth`` (a video's
    truth.h5) each frame is scored against its true cube (:mod:`clsdcam.batch.truth`). InputError before
    any work, nothing written, if ``output`` (or its parts folder) cannot be written, a frame to
    compute cannot be read or is not finite, ``truth`` does not match the frames, or the video extra is not
    installed (:mod:`clsdcam.extras`).
    """
    require("batch")
    output, spec = check_output(Path(output).resolve()), _resolved(spec)
    source = FrameSource(spec.frames)
    n, parts = len(source), parts_dir(output)
    source.check(range(n) if overwrite else missing_frames(parts, n))
    scored = None if truth is None else TruthVideo(truth, n, frame_calibration(spec, source.read(0)))
    layout = plan_workers(workers, scheduler)
    if overwrite:
        shutil.rmtree(parts, ignore_errors=True)
        output.unlink(missing_ok=True)
    claim(parts, spec, n)
    with _kept_on_interrupt(parts, n):
        missing = missing_frames(parts, n)
        if on_plan is not None:
            on_plan(n, len(missing), layout)
        start = time.perf_counter()
        lost = _compute(spec, parts, missing, (layout, chunk), _Progress(progress))
        summary = assemble(output, n, lost, provenance(_inputs(spec, source, scored), spec.preprocessing),
                           None if scored is None else scored.score)
    summary.computed_frames, summary.seconds, summary.layout = len(missing), time.perf_counter() - start, str(layout)
    return summary


def _inputs(spec: BatchSpec, source: FrameSource, truth: TruthVideo | None) -> dict:
    """The input files whose paths and SHA-256 the output records: the frames, the calibration, the truth."""
    inputs = {"frames": source.paths, "calibration": spec.calibration}
    return inputs if truth is None else {**inputs, "truth": truth.path.resolve()}


def _resolved(spec: BatchSpec) -> BatchSpec:
    """``spec`` with absolute paths, the dark frames' too (workers may run elsewhere)."""
    dark = spec.preprocessing.dark
    if isinstance(dark, tuple):
        spec = replace(spec, preprocessing=replace(spec.preprocessing, dark=tuple(str(Path(p).resolve()) for p in dark)))
    return replace(spec, frames=tuple(str(Path(p).resolve()) for p in spec.frames),
                   calibration=str(Path(spec.calibration).resolve()))


@contextlib.contextmanager
def _kept_on_interrupt(parts: Path, n: int):
    """A KeyboardInterrupt in the block becomes BatchInterrupted when finished parts hold some of the n frames."""
    try:
        yield
    except KeyboardInterrupt:
        kept = n - len(missing_frames(parts, n))
        if kept:
            raise BatchInterrupted(kept, n, parts) from None
        raise


def _compute(spec: BatchSpec, parts: Path, missing: list[int], how, progress) -> dict[int, str]:
    """Compute the missing frames' parts; {frame: reason} for frames lost with their whole chunk.
    On any exception, a parts folder with no part yet is removed (a failed start leaves no trace)."""
    layout, chunk = how
    try:
        if missing and layout.processes == 0 and layout.scheduler is None:
            _run_serial(spec, parts, chunks(missing, chunk, 1), progress)
        elif missing:
            with connect(layout) as client:
                slots = sum(client.nthreads().values()) or max(layout.processes, 1)
                return _run_dask(client, spec, parts, chunks(missing, chunk, slots), progress)
    except BaseException:
        if not finished_parts(parts):  # nothing computed (e.g. no scheduler): leave no trace
            shutil.rmtree(parts, ignore_errors=True)
        raise
    return {}


class _Progress:
    """Counts each frame once (events can repeat when Dask re-runs a chunk) and reports it."""

    def __init__(self, callback):
        self.callback, self.seen, self.lock = callback, set(), threading.Lock()

    def __call__(self, indices):
        with self.lock:
            new = set(indices) - self.seen
            self.seen |= new
        if new and self.callback is not None:
            self.callback(len(new))


def _run_serial(spec, parts, bounds, progress):
    """The chunks in this process, one after another; a chunk that follows on its predecessor continues its stream."""
    carried, last = Carried(), None
    for s, e in bounds:
        _, carried = run_stream(spec, s, e, part_path(parts, s, e), lambda i: progress([i]),
                                carried if s == last else Carried())
        last = e


def _dask_chunk(spec, start, stop, part, topic):
    """solve_chunk on a Dask worker (under :func:`chunk_threads`), announcing each finished frame on the event
    ``topic``."""
    from distributed import get_worker

    worker = get_worker()
    with chunk_threads():
        return solve_chunk(spec, start, stop, part, lambda i: worker.log_event(topic, i))


def _run_dask(client, spec, parts, bounds, progress) -> dict[int, str]:
    """Run the chunks as tasks; {frame: reason} for the frames of chunks that failed as a whole
    (e.g. their worker died more often than Dask's allowed-failures): a re-run retries them."""
    from distributed import as_completed

    topic = f"clsdcam-frames-{uuid.uuid4().hex}"
    client.subscribe_topic(topic, lambda event: progress([event[1]]))
    futures = {client.submit(_dask_chunk, spec, s, e, str(part_path(parts, s, e)), topic, pure=False,
                             key=f"clsdcam-chunk-{s}-{e}-{uuid.uuid4().hex}"): (s, e) for s, e in bounds}
    lost = {}
    try:
        for future in as_completed(futures, loop=client.loop):
            if future.status == "finished":
                progress(r["index"] for r in future.result())
            else:
                lost.update(dict.fromkeys(range(*futures[future]), f"chunk failed: {failure_text(future.exception())}"))
    finally:
        client.unsubscribe_topic(topic)
        client.cancel(list(futures))
    return lost
