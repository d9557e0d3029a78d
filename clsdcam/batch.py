"""Many frames: warm-started streams, spread over Dask distributed workers.

The frames are cut into contiguous chunks; a chunk is one task. A worker builds its solver
(model, PSF transfer function, FFT plans, device buffers, Lipschitz constant) once per
process and reuses it for every frame of every chunk it gets; inside a chunk each frame
starts from the previous frame's cube (warm start) and stops by the solver's rule, while a
reader thread fetches the next frame. Each chunk is written by its worker to its own part
file ``OUT.h5.parts/chunk-START-STOP.h5``, atomically, so a chunk is either complete or
absent: re-running the same command computes only the missing chunks, and a chunk that Dask
re-runs after a worker died replaces its part file whole (no frame is written twice).
``OUT.h5`` presents ``cubes`` (N,K,H,W) as an HDF5 virtual dataset over the parts, with
``wavelengths`` and per-frame ``iterations``, ``stop_reason``, ``seconds`` and ``error``.
"""
from __future__ import annotations

import math
import pickle
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .calibration import Calibration, Preprocessing, preprocess
from .errors import InputError
from .frames import FrameSource
from .io import atomic_output
from .solver import Settings, Solver

_SOLVERS: dict = {}   # per process: spec key -> (solver, calibration after preprocessing)


@dataclass(frozen=True)
class BatchSpec:
    """Everything a worker needs to reconstruct any chunk (picklable)."""

    frames: tuple[str, ...]
    calibration: str
    preprocessing: Preprocessing = Preprocessing()
    settings: Settings = Settings()
    backend: str = "numpy"
    device: str | None = None
    fft: str = "auto"
    warm_start: bool = True


@dataclass
class BatchSummary:
    n_frames: int
    computed_frames: int
    failed: list[tuple[int, str]] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0


# ---- one chunk on one worker ---------------------------------------------------------------
def solve_chunk(spec: BatchSpec, start: int, stop: int, part: str) -> list[dict]:
    """Reconstruct frames [start, stop) as one warm-started stream and write the part file."""
    source = FrameSource(spec.frames)
    records, cubes, x0 = [], None, None
    with ThreadPoolExecutor(max_workers=1) as reader:
        upcoming = reader.submit(_read, source, start)
        for i in range(start, stop):
            frame, error = upcoming.result()
            if i + 1 < stop:
                upcoming = reader.submit(_read, source, i + 1)  # read ahead while this frame is solved
            record = {"index": i, "iterations": 0, "stop_reason": "failed", "seconds": 0.0, "error": error or ""}
            if error is None:
                try:
                    cube, record = _solve_frame(spec, frame, x0, record)
                    cubes = _store(cubes, stop - start, i - start, cube)
                    x0 = cube if spec.warm_start else None
                except InputError as exc:
                    record["error"], x0 = str(exc), None
            records.append(record)
    _write_part(Path(part), records, cubes, stop - start)
    return records


def _read(source: FrameSource, i: int):
    try:
        return source.read(i), None
    except InputError as exc:
        return None, str(exc)


def _solve_frame(spec: BatchSpec, frame, x0, record: dict):
    solver, calibration = _cached_solver(spec, frame)
    b = _measurement(spec.preprocessing, calibration["raw"], frame)
    start = time.perf_counter()
    result = solver.solve(b, x0=x0)
    record.update(iterations=result.iterations, stop_reason=result.stop_reason, seconds=time.perf_counter() - start)
    return result.cube, record


def _measurement(options: Preprocessing, raw: Calibration, frame):
    """The frame after the crop / defect / dead-pixel steps (the calibration's steps are done once)."""
    if options.crop is None and not options.zero_defect and options.dead_pixels is None:
        return frame
    return preprocess(raw, frame, options)[1]


def _cached_solver(spec: BatchSpec, frame):
    """The process's solver for this spec, built on first use (once per worker, not per frame)."""
    key = pickle.dumps((spec.calibration, spec.preprocessing, spec.settings, spec.backend, spec.device, spec.fft))
    if key not in _SOLVERS:
        raw = Calibration.load(spec.calibration)
        calibration, _ = preprocess(raw, frame, spec.preprocessing)
        solver = Solver(calibration, backend=spec.backend, device=spec.device, settings=spec.settings, fft=spec.fft)
        _SOLVERS[key] = (solver, {"raw": raw, "wavelengths": calibration.wavelengths})
    return _SOLVERS[key]


def _store(cubes, n, j, cube):
    if cubes is None:
        cubes = np.full((n,) + cube.shape, np.nan, np.float32)
    cubes[j] = cube
    return cubes


def _write_part(part: Path, records: list[dict], cubes, n: int):
    import h5py

    with atomic_output(part) as tmp, h5py.File(tmp, "w") as f:
        if cubes is not None:
            f["cubes"] = cubes
        for key in ("index", "iterations", "seconds"):
            f[key] = np.array([r[key] for r in records])
        for key in ("stop_reason", "error"):
            f[key] = np.array([r[key] for r in records], dtype=h5py.string_dtype())


# ---- the whole batch ------------------------------------------------------------------------
def chunk_bounds(n_frames: int, chunk: int) -> list[tuple[int, int]]:
    return [(s, min(s + chunk, n_frames)) for s in range(0, n_frames, chunk)]


def parts_dir(output: Path) -> Path:
    return output.with_name(output.name + ".parts")


def run_batch(spec: BatchSpec, output, workers: int = 1, scheduler: str | None = None, chunk: int | None = None,
              overwrite: bool = False, progress=None) -> BatchSummary:
    """Reconstruct every frame into ``output``; only chunks without a part file are computed.

    ``workers`` = 0 (and no scheduler): one in-process stream; otherwise Dask distributed, an
    embedded LocalCluster of ``workers`` processes or the cluster at ``scheduler``.
    ``progress(n)`` is called with the number of frames each finished chunk adds.
    """
    output = Path(output)
    n = len(FrameSource(spec.frames))
    if overwrite:
        shutil.rmtree(parts_dir(output), ignore_errors=True)
        output.unlink(missing_ok=True)
    chunk = chunk or max(1, math.ceil(n / max(2 * workers, 1)))
    bounds = chunk_bounds(n, chunk)
    todo = [(s, e) for s, e in bounds if not _part_path(output, s, e).exists()]
    parts_dir(output).mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    if todo:
        runner = _run_serial if workers == 0 and scheduler is None else _run_dask
        runner(spec, output, todo, workers, scheduler, progress or (lambda k: None))
    summary = _assemble(spec, output, bounds, n)
    summary.computed_frames = sum(e - s for s, e in todo)
    summary.seconds = time.perf_counter() - start
    return summary


def _part_path(output: Path, start: int, stop: int) -> Path:
    return parts_dir(output) / f"chunk-{start:06d}-{stop:06d}.h5"


def _run_serial(spec, output, todo, workers, scheduler, progress):
    for s, e in todo:
        progress(len(solve_chunk(spec, s, e, str(_part_path(output, s, e)))))


def _run_dask(spec, output, todo, workers, scheduler, progress):
    from dask.distributed import as_completed

    with _client(workers, scheduler) as client:
        futures = [client.submit(solve_chunk, spec, s, e, str(_part_path(output, s, e)), pure=False,
                                 key=f"clsdcam-chunk-{s}-{e}-{time.time_ns()}") for s, e in todo]
        for future in as_completed(futures):
            progress(len(future.result()))


class _client:
    """A Dask client on an embedded LocalCluster (``workers`` processes) or on ``scheduler``."""

    def __init__(self, workers: int, scheduler: str | None):
        self.workers, self.scheduler, self.cluster = workers, scheduler, None

    def __enter__(self):
        import logging

        from dask.distributed import Client, LocalCluster

        if self.scheduler:
            self.client = Client(self.scheduler, timeout=30)
        else:
            self.cluster = LocalCluster(n_workers=max(self.workers, 1), threads_per_worker=1, processes=True,
                                        dashboard_address=None, silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
        return self.client

    def __exit__(self, *exc):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def _assemble(spec: BatchSpec, output: Path, bounds, n: int) -> BatchSummary:
    """OUT.h5: a virtual ``cubes`` over the parts (NaN where a frame failed) and per-frame records."""
    import h5py

    per_frame = {"iterations": np.zeros(n, np.int64), "seconds": np.zeros(n), "stop_reason": [""] * n, "error": [""] * n}
    sources, shape = [], None
    for s, e in bounds:
        with h5py.File(_part_path(output, s, e), "r") as part:
            for key in per_frame:
                values = part[key].asstr()[...] if key in ("stop_reason", "error") else part[key][...]
                for j, value in enumerate(values):
                    per_frame[key][s + j] = value
            if "cubes" in part:
                shape = part["cubes"].shape[1:]
                sources.append((s, e, h5py.VirtualSource(f"{parts_dir(output).name}/{_part_path(output, s, e).name}",
                                                         "cubes", shape=part["cubes"].shape)))
    failed = [(i, per_frame["error"][i]) for i in range(n) if per_frame["error"][i]]
    if shape is None:
        raise InputError(f"no frame of {n} could be reconstructed; first error: {failed[0][1]}")
    layout = h5py.VirtualLayout(shape=(n,) + shape, dtype=np.float32)
    for s, e, source in sources:
        layout[s:e] = source
    with atomic_output(output) as tmp, h5py.File(tmp, "w") as f:
        f.create_virtual_dataset("cubes", layout, fillvalue=np.nan)
        f["wavelengths"] = _cached_wavelengths(spec)
        for key, values in per_frame.items():
            f[key] = np.array(values, dtype=h5py.string_dtype()) if key in ("stop_reason", "error") else values
        f.attrs["calibration"] = spec.calibration
        f.attrs["warm_start"] = spec.warm_start
    return BatchSummary(n_frames=n, computed_frames=0, failed=failed)


def _cached_wavelengths(spec: BatchSpec) -> np.ndarray:
    wavelengths = Calibration.load(spec.calibration).wavelengths
    return wavelengths[:-1] if spec.preprocessing.drop_last_band else wavelengths
