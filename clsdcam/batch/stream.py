"""One chunk of frames as a warm-started stream, on this process's cached solver.

Stream. Frames [s, e) are one stream on one solver: frame i starts from the previous frame's
cube x̂_{i−1} moved by the drift seen between x̂_{i−2} and x̂_{i−1} (the *warm start*, see
:func:`clsdcam.batch.motion.predict`; none with ``warm_start=False`` or after a failed frame)
and stops by the solver's rule (``Settings.iters`` / ``Settings.tol``). Frame i+1 is read by a
reader thread and cube i−1 written by a writer thread while frame i is solved, so only about
three frames are in memory whatever the stream's length. A frame's failure is recorded in its
part (:mod:`clsdcam.batch.parts`) and the stream goes on; a Ctrl-C, even one the solver turned
into its stop reason "interrupted", stops the stream (that frame is not recorded).

Solver cache. A process builds its solver (model, PSF transfer function, FFT plans, device
buffers, Lipschitz constant) once per (calibration, preprocessing, settings, backend, device,
fft, path, frame shape) and keeps the two last used (:func:`cached_solver`, an LRU cache) for every
later chunk: one build per Dask worker, not per frame. The calibration's preprocessing needs
only the frame's shape (crop and size checks), so it runs on a zero frame of that shape (the
one step that reads a frame's values, ``saturation``, is refused by :class:`BatchSpec`);
the measurement's steps (crop, defect block, dead pixels) are applied to each frame.
"""
from __future__ import annotations

import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..calibration import Calibration, Preprocessing, preprocess
from ..errors import InputError
from ..io import atomic_output
from ..solver import Settings, Solver
from .frames import FrameSource
from .motion import predict
from .parts import read_records, write_columns, write_cube
from .spec import BatchSpec

SOLVERS_KEPT = 2  # solvers a process keeps: enough for a worker alternating between two batches


def solve_chunk(spec: BatchSpec, start: int, stop: int, part: str, report=None) -> list[dict]:
    """Reconstruct frames [start, stop) into the part file; per-frame records."""
    return run_stream(spec, start, stop, Path(part), report)[0]


def run_stream(spec: BatchSpec, start: int, stop: int, part: Path, report=None, past=(None, None)):
    """(records, (x̂_{stop−2}, x̂_{stop−1})): the chunk as one stream into ``part``; ``past`` = the two
    cubes before ``start`` (None: unknown or failed); ``report(i)`` after each frame."""
    import h5py

    if part.exists():  # written by a worker that died before Dask heard of it: keep it
        return read_records(part), (None, None)
    source = FrameSource(spec.frames)
    with atomic_output(part) as tmp, h5py.File(tmp, "w") as out, \
            ThreadPoolExecutor(1) as reader, ThreadPoolExecutor(1) as writer:
        out.attrs["writer"] = f"{os.uname().nodename}:{os.getpid()}"
        records, past = _solve_frames(spec, source, range(start, stop), out, (reader, writer), report, past)
        write_columns(out, {key: [r[key] for r in records] for key in records[0]})
    return records, past


def _solve_frames(spec: BatchSpec, source: FrameSource, indices: range, out, threads, report, past):
    """Solve the frames in order, frame i+1 read ahead and cube i−1 written behind; (records, past)."""
    reader, writer = threads
    records, pending = [], None
    upcoming = reader.submit(_read, source, indices.start)
    for i in indices:
        frame, error = upcoming.result()
        if i + 1 < indices.stop:
            upcoming = reader.submit(_read, source, i + 1)
        record, cube, wavelengths = _solve_frame(spec, i, frame, error, predict(*past) if spec.warm_start else None)
        past = (past[1], cube)
        if pending is not None:
            pending.result()
        if cube is not None:
            pending = writer.submit(write_cube, out, i - indices.start, len(indices), cube, wavelengths)
        records.append(record)
        if report is not None:
            report(i)
    if pending is not None:
        pending.result()
    return records, past


def _read(source: FrameSource, i: int):
    """(frame, None), or (None, why) when frame i cannot be read."""
    try:
        return source.read(i), None
    except Exception as exc:  # noqa: BLE001 - loaders raise many types on damaged files
        return None, failure_text(exc)


def failure_text(exc: BaseException) -> str:
    """An InputError's message as it is; any other exception prefixed by its type."""
    return str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"


def _solve_frame(spec: BatchSpec, i: int, frame, error: str | None, x0):
    """(record, cube, wavelengths) of frame i started from ``x0``; cube None when it failed (recorded, not raised)."""
    record = {"index": i, "iterations": 0, "stop_reason": "failed", "seconds": 0.0, "error": error or ""}
    if error is not None:
        return record, None, None
    try:
        solver, raw, wavelengths = cached_solver(spec.calibration, spec.preprocessing, spec.settings, spec.backend,
                                                 spec.device, spec.fft, spec.path, frame.shape)
        b = _measurement(spec.preprocessing, raw, frame)
        start = time.perf_counter()
        result = solver.solve(b, x0=x0)
    except Exception as exc:  # noqa: BLE001 - a frame's failure is recorded, the stream goes on
        record["error"] = failure_text(exc)
        return record, None, None
    if result.stop_reason == "interrupted":  # the solver stopped on Ctrl-C: the batch stops, the frame is not done
        raise KeyboardInterrupt
    record.update(iterations=result.iterations, stop_reason=result.stop_reason, seconds=time.perf_counter() - start)
    return record, result.cube, wavelengths


def _measurement(options: Preprocessing, raw: Calibration, frame):
    """The frame after the crop / defect / dead-pixel steps (the calibration's steps are done once)."""
    if options.crop is None and not options.zero_defect and options.dead_pixels is None:
        return frame
    return preprocess(raw, frame, options)[1]


@functools.lru_cache(maxsize=SOLVERS_KEPT)
def cached_solver(calibration: str, preprocessing: Preprocessing, settings: Settings, backend: str,
                  device: str | None, fft: str, path: str, frame_shape: tuple[int, ...]):
    """(solver, raw calibration, wavelengths) for frames of ``frame_shape``, built on first use in this process."""
    raw = Calibration.load(calibration)
    prepared, _ = preprocess(raw, np.zeros(frame_shape), preprocessing)
    solver = Solver(prepared, backend=backend, device=_worker_device(backend, device), settings=settings, fft=fft,
                    path=path)
    return solver, raw, np.asarray(prepared.wavelengths)


def _worker_device(backend: str, device: str | None):
    """``--device`` if given, else PYOPENCL_CTX if set (the way to pin one device per worker), else,
    on a worker named by an integer n (LocalCluster's are 0…N−1), GPU number n mod the GPU count."""
    if device or backend != "opencl" or os.environ.get("PYOPENCL_CTX"):
        return device
    try:
        from distributed import get_worker

        n = int(get_worker().name)
    except (ImportError, ValueError, TypeError):
        return None
    from ..backends.cl_devices import _all_devices, import_pyopencl

    gpus = [d for _, d in _all_devices() if d.type & import_pyopencl().device_type.GPU]
    return gpus[n % len(gpus)] if gpus else None
