"""One chunk of frames as a warm-started stream, on this process's cached solver.

Stream. Frames [s, e) are one stream on one solver. The first frame (and any frame after a failed
one) is a cold start with the cold budget (``BatchSpec.budget``); every later frame is warm: it starts
from the previous frame's solver state (:mod:`clsdcam.solve.state`: the whole field, the spectral basis and
rank if it ended in a subspace, the step, the prior weights: no band-space warm-up, no new weight estimate), its field moved by
the drift seen between x̂_{i−2} and x̂_{i−1} (:func:`clsdcam.batch.motion.predict_state`), and runs
``settings.iters`` iterations. Frame i+1 is read by a reader thread and cube i−1 written by a writer
thread while frame i is solved, so only about three frames are in memory whatever the stream's length.
A frame's failure is recorded in its part (:mod:`clsdcam.batch.parts`) and the stream goes on cold; a
Ctrl-C, even one the solver turned into its stop reason "interrupted", stops the stream (that frame is
not recorded). Without ``warm_start`` every frame is a cold solve of ``settings.iters`` iterations.

Solver cache. A process builds its solver (model, PSF transfer function, FFT plans, device
buffers, Lipschitz constant) once per (calibration, preprocessing, settings, backend, device,
fft, path, frame shape) and keeps the two last used (:func:`cached_solver`, an LRU cache) for every
later chunk: one build per Dask worker, not per frame. The calibration's preprocessing needs
only the frame's shape (crop and size checks), so it runs on a zero frame of that shape (the
one step that reads a frame's values, ``saturation``, is refused by :class:`BatchSpec`);
each frame first gets its raw steps (:func:`clsdcam.calibrate.measurement.raw_steps`: the calibration's recorded
ones for a frame of its raw size, else ``--dark`` and ``--bin``), then the measurement's steps (crop,
defect block, dead pixels).
"""
from __future__ import annotations

import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..calibrate.measurement import raw_steps
from ..camera.calibration import Calibration, Preprocessing, preprocess
from ..errors import InputError
from ..io import atomic_output
from ..solve.solver import Settings, Solver
from .frames import FrameSource
from .motion import predict_state
from .parts import read_records, write_columns, write_cube
from .spec import BatchSpec

SOLVERS_KEPT = 2  # solvers a process keeps: enough for a worker alternating between two batches
FIT_MARGIN = 1.0  # a warm frame stops once its fit is this close to the previous frame's


@dataclass
class Carried:
    """What a stream carries to its next frame: the cubes x̂_{i−2}, x̂_{i−1} (the drift) and frame i−1's solver
    state; all None after a failed frame or at a cold start."""

    before: Any = None
    previous: Any = None
    state: Any = None

    def after(self, result) -> "Carried":
        """What frame i leaves to frame i+1 (a failed frame, ``result`` None, leaves nothing)."""
        if result is None:
            return Carried()
        return Carried(self.previous, result.cube, result.state)


def solve_chunk(spec: BatchSpec, start: int, stop: int, part: str, report=None) -> list[dict]:
    """Reconstruct frames [start, stop) into the part file; per-frame records."""
    return run_stream(spec, start, stop, Path(part), report)[0]


def run_stream(spec: BatchSpec, start: int, stop: int, part: Path, report=None, carried: Carried = Carried()):
    """(records, what frame stop − 1 leaves): the chunk as one stream into ``part``, from what frame
    start − 1 left (``carried``; a cold start by default); ``report(i)`` after each frame."""
    import h5py

    if part.exists():  # written by a worker that died before Dask heard of it: keep it
        return read_records(part), Carried()
    source = FrameSource(spec.frames)
    with atomic_output(part) as tmp, h5py.File(tmp, "w") as out, \
            ThreadPoolExecutor(1) as reader, ThreadPoolExecutor(1) as writer:
        out.attrs["writer"] = f"{os.uname().nodename}:{os.getpid()}"
        records, carried = _solve_frames(spec, source, range(start, stop), out, (reader, writer), report, carried)
        write_columns(out, {key: [r[key] for r in records] for key in records[0]})
    return records, carried


def _solve_frames(spec: BatchSpec, source: FrameSource, indices: range, out, threads, report, carried: Carried):
    """Solve the frames in order, frame i+1 read ahead and cube i−1 written behind; (records, carried)."""
    reader, writer = threads
    records, pending = [], None
    upcoming = reader.submit(_read, source, indices.start)
    for i in indices:
        frame, error = upcoming.result()
        if i + 1 < indices.stop:
            upcoming = reader.submit(_read, source, i + 1)
        record, result, wavelengths = _solve_frame(spec, i, frame, error, carried if spec.warm_start else Carried())
        carried = carried.after(result)
        if pending is not None:
            pending.result()
        if result is not None:
            pending = writer.submit(write_cube, out, i - indices.start, len(indices), result.cube, wavelengths)
        records.append(record)
        if report is not None:
            report(i)
    if pending is not None:
        pending.result()
    return records, carried


def _read(source: FrameSource, i: int):
    """(frame, None), or (None, why) when frame i cannot be read."""
    try:
        return source.read(i), None
    except Exception as exc:  # noqa: BLE001 - loaders raise many types on damaged files
        return None, failure_text(exc)


def failure_text(exc: BaseException) -> str:
    """An InputError's message as it is; any other exception prefixed by its type."""
    return str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"


def _solve_frame(spec: BatchSpec, i: int, frame, error: str | None, carried: Carried):
    """(record, result, wavelengths) of frame i, warm-started from ``carried`` when it holds a state; result None
    when the frame failed (recorded, not raised)."""
    record = {"index": i, "iterations": 0, "stop_reason": "failed", "seconds": 0.0, "error": error or "",
              "warm": carried.state is not None}
    if error is not None:
        return record, None, None
    try:
        raw = cached_calibration(spec.calibration)
        frame, _ = raw_steps(raw, frame, spec.preprocessing)
        solver, wavelengths = cached_solver(spec.calibration, spec.preprocessing, spec.settings, spec.backend,
                                            spec.device, spec.fft, spec.path, frame.shape)
        b = _measurement(spec.preprocessing, raw, frame)
        start = time.perf_counter()
        result = next_solve(solver, b, carried, (spec.budget(warm=False), spec.budget(warm=True)))
    except Exception as exc:  # noqa: BLE001 - a frame's failure is recorded, the stream goes on
        record["error"] = failure_text(exc)
        return record, None, None
    if result.stop_reason == "interrupted":  # the solver stopped on Ctrl-C: the batch stops, the frame is not done
        raise KeyboardInterrupt
    record.update(iterations=result.iterations, stop_reason=result.stop_reason, seconds=time.perf_counter() - start)
    return record, result, wavelengths


def next_solve(solver: Solver, b, carried: Carried, budgets: tuple[int, int]):
    """Frame i's solve on ``solver``: cold (``budgets[0]`` iterations) when nothing is carried, else warm
    (``budgets[1]``) from frame i−1's state with its field moved by the drift (:func:`predict_state`),
    stopping once ‖Ay − b‖/‖b‖ reaches FIT_MARGIN times frame i−1's fit (a frame that changed little
    stops early; one that changed more uses its budget)."""
    if carried.state is None:
        return solver.solve(b, iters=budgets[0])
    state = predict_state(carried.before, carried.previous, carried.state, solver.backend)
    return solver.solve(b, state=state, iters=budgets[1], stop_at_fit=FIT_MARGIN * carried.state.fit)


def _measurement(options: Preprocessing, raw: Calibration, frame):
    """The frame after the crop / defect / dead-pixel steps (the calibration's steps are done once)."""
    if options.crop is None and not options.zero_defect and options.dead_pixels is None:
        return frame
    return preprocess(raw, frame, options)[1]


@functools.lru_cache(maxsize=SOLVERS_KEPT)
def cached_calibration(calibration: str) -> Calibration:
    """The calibration file as it is (its raw steps and preprocessing still to apply), read once per process."""
    return Calibration.load(calibration)


def frame_calibration(spec: BatchSpec, frame) -> Calibration:
    """The calibration that frames like ``frame`` (as read) are reconstructed with: their cubes are
    (K,) + its shape, at its wavelengths."""
    frame, _ = raw_steps(cached_calibration(spec.calibration), frame, spec.preprocessing)
    return prepared_calibration(spec.calibration, spec.preprocessing, frame.shape)


def prepared_calibration(calibration: str, preprocessing: Preprocessing, frame_shape: tuple[int, ...]) -> Calibration:
    """The calibration file preprocessed for frames of ``frame_shape`` (after their raw steps)."""
    return preprocess(cached_calibration(calibration), np.zeros(frame_shape), preprocessing)[0]


@functools.lru_cache(maxsize=SOLVERS_KEPT)
def cached_solver(calibration: str, preprocessing: Preprocessing, settings: Settings, backend: str,
                  device: str | None, fft: str, path: str, frame_shape: tuple[int, ...]):
    """(solver, wavelengths) for frames of ``frame_shape`` (after their raw steps), built on first use in this
    process."""
    prepared = prepared_calibration(calibration, preprocessing, frame_shape)
    solver = Solver(prepared, backend=backend, device=_worker_device(backend, device), settings=settings, fft=fft,
                    path=path)
    return solver, np.asarray(prepared.wavelengths)


def _worker_device(backend: str, device: str | None):
    """``--device`` if given, else PYOPENCL_CTX if set (the way to pin one device per worker), else,
    for ``opencl`` or ``auto`` on a worker named by an integer n (LocalCluster's are 0…N−1), GPU number
    n mod the GPU count (none: the backend chooses, ``auto`` NumPy)."""
    if device or backend == "numpy" or os.environ.get("PYOPENCL_CTX"):
        return device
    try:
        from distributed import get_worker

        n = int(get_worker().name)
    except (ImportError, ValueError, TypeError):
        return None
    from ..backends import all_devices, import_pyopencl

    try:
        gpus = [d for _, d in all_devices() if d.type & import_pyopencl().device_type.GPU]
    except InputError:  # no OpenCL here: ``auto`` becomes NumPy, ``opencl`` says why when its backend is built
        return None
    return gpus[n % len(gpus)] if gpus else None
