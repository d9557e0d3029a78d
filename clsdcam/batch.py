"""Many frames: warm-started streams, spread over Dask distributed workers.

Stream. Frames [s, e) are one stream on one solver: frame i starts from the previous frame's
cube x̂_{i−1} moved by the drift seen between x̂_{i−2} and x̂_{i−1} (the *warm start*, see
:func:`predict`; none with ``warm_start=False`` or after a failed frame) and stops by the
solver's rule (``Settings.iters`` / ``Settings.tol``). Frame i+1 is
read by a reader thread and cube i−1 written by a writer thread while frame i is solved, so
only about three frames are in memory whatever the stream's length.

Solver cache. A process builds its solver (model, PSF transfer function, FFT plans, device
buffers, Lipschitz constant) once per (calibration, preprocessing, settings, backend) and
keeps it in ``_SOLVERS`` for every later chunk: one build per Dask worker, not per frame.

Distribution. The frames still missing are cut into contiguous chunks (a chunk is one Dask
task, so warm starts hold inside it). The worker writes its chunk into a temporary file and
renames it to ``OUT.h5.parts/chunk-START-STOP.h5``: a part is whole or absent. A task that
Dask re-runs after its worker died finds the part already there when the dead worker had
finished it, and keeps it: no frame is lost or written twice.

Resume. A frame is done when some part covers it; a re-run computes only the others (any
chunk size, any worker count). ``batch.json`` in the parts folder fingerprints the frames
and settings, so parts made by a different command are never mixed in (``overwrite``).

Output. ``OUT.h5`` holds ``cubes`` (N,K,H,W), an HDF5 virtual dataset over the parts (NaN
where a frame failed), ``wavelengths`` and per-frame ``iterations``, ``stop_reason``,
``seconds``, ``error``; it is rebuilt, atomically, at the end of every run.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import pickle
import re
import shutil
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .calibration import Calibration, Preprocessing, preprocess
from .errors import InputError
from .frames import FrameSource
from .io import atomic_output
from .solver import Settings, Solver

MAX_CHUNK = 64          # default chunk cap: bounds the work a crash loses and keeps tasks balanced
_SOLVERS: dict = {}     # per process: spec key -> (solver, raw calibration, wavelengths)
_PART = re.compile(r"chunk-(\d+)-(\d+)\.h5$")
_TEXT = ("stop_reason", "error")


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


# ---- one chunk: a warm-started stream ---------------------------------------------------------
def solve_chunk(spec: BatchSpec, start: int, stop: int, part: str, report=None) -> list[dict]:
    """Reconstruct frames [start, stop) into the part file; per-frame records."""
    return _stream(spec, start, stop, Path(part), report)[0]


def _stream(spec: BatchSpec, start: int, stop: int, part: Path, report=None, past=(None, None)):
    """(records, (x̂_{stop−2}, x̂_{stop−1})): the chunk as one stream, read-ahead and write-behind
    around each solve; ``past`` = the two cubes before ``start`` (None: unknown or failed)."""
    import h5py

    if part.exists():  # written by a worker that died before Dask heard of it: keep it
        return _records(part), (None, None)
    source = FrameSource(spec.frames)
    records, pending = [], None
    with atomic_output(part) as tmp, h5py.File(tmp, "w") as out, \
            ThreadPoolExecutor(1) as reader, ThreadPoolExecutor(1) as writer:
        out.attrs["writer"] = f"{os.uname().nodename}:{os.getpid()}"
        upcoming = reader.submit(_read, source, start)
        for i in range(start, stop):
            frame, error = upcoming.result()
            if i + 1 < stop:
                upcoming = reader.submit(_read, source, i + 1)
            record = {"index": i, "iterations": 0, "stop_reason": "failed", "seconds": 0.0, "error": error or ""}
            cube, x0 = None, predict(*past) if spec.warm_start else None
            if error is None:
                try:
                    cube, wavelengths = _solve_frame(spec, frame, x0, record)
                except Exception as exc:  # noqa: BLE001 - a frame's failure is recorded, the stream goes on
                    record["error"] = _reason(exc)
            past = (past[1], cube)
            if pending is not None:
                pending.result()
            if cube is not None:
                pending = writer.submit(_write_cube, out, i - start, stop - start, cube, wavelengths)
            records.append(record)
            if report is not None:
                report(i)
        if pending is not None:
            pending.result()
        for key in records[0]:
            out[key] = np.array([r[key] for r in records], dtype=h5py.string_dtype() if key in _TEXT else None)
    return records, past


def predict(before, previous, min_shift: float = 0.05):
    """Warm start for frame i from x̂_{i−2} (``before``) and x̂_{i−1} (``previous``), assuming constant velocity.

    The drift d is the peak of the phase correlation of the band sums s = Σ_k x̂_k,
    c = ℱ⁻¹[ℱs_{i−1}·conj(ℱs_{i−2}) / |ℱs_{i−1}·conj(ℱs_{i−2})|], refined to sub-pixel by a parabola
    through the peak and its two neighbours on each axis; x0 = x̂_{i−1} shifted by d (bilinear,
    zero fill, clipped at 0). Without ``before``, or for |d| < ``min_shift`` px, x0 = x̂_{i−1}.
    """
    if previous is None or before is None:
        return previous
    import scipy.ndimage as ndi

    cross = np.fft.fft2(previous.sum(0)) * np.conj(np.fft.fft2(before.sum(0)))
    c = np.fft.ifft2(cross / np.maximum(np.abs(cross), 1e-12 * np.abs(cross).max())).real
    peak = np.unravel_index(np.argmax(c), c.shape)
    drift = []
    for axis, n in enumerate(c.shape):
        lo, mid, hi = (c[tuple((p + (k if a == axis else 0)) % c.shape[a] for a, p in enumerate(peak))] for k in (-1, 0, 1))
        d = peak[axis] + (0.5 * (lo - hi) / (lo - 2 * mid + hi) if lo - 2 * mid + hi else 0.0)
        drift.append(d - n if d > n / 2 else d)
    if np.hypot(*drift) < min_shift:
        return previous
    return np.maximum(ndi.shift(previous, (0, *drift), order=1), 0).astype(np.float32)


def _read(source: FrameSource, i: int):
    try:
        return source.read(i), None
    except Exception as exc:  # noqa: BLE001 - loaders raise many types on damaged files
        return None, _reason(exc)


def _reason(exc: BaseException) -> str:
    return str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"


def _solve_frame(spec: BatchSpec, frame, x0, record: dict):
    solver, raw, wavelengths = _cached_solver(spec, frame)
    b = _measurement(spec.preprocessing, raw, frame)
    start = time.perf_counter()
    result = solver.solve(b, x0=x0)
    record.update(iterations=result.iterations, stop_reason=result.stop_reason, seconds=time.perf_counter() - start)
    return result.cube, wavelengths


def _measurement(options: Preprocessing, raw: Calibration, frame):
    """The frame after the crop / defect / dead-pixel steps (the calibration's steps are done once)."""
    if options.crop is None and not options.zero_defect and options.dead_pixels is None:
        return frame
    return preprocess(raw, frame, options)[1]


def _cached_solver(spec: BatchSpec, frame):
    """This process's solver for ``spec``, built on first use (once per worker, not per frame)."""
    key = pickle.dumps((spec.calibration, spec.preprocessing, spec.settings, spec.backend, spec.device, spec.fft))
    if key not in _SOLVERS:
        raw = Calibration.load(spec.calibration)
        calibration, _ = preprocess(raw, frame, spec.preprocessing)
        solver = Solver(calibration, backend=spec.backend, device=_worker_device(spec), settings=spec.settings,
                        fft=spec.fft)
        _SOLVERS[key] = (solver, raw, np.asarray(calibration.wavelengths))
    return _SOLVERS[key]


def _worker_device(spec: BatchSpec):
    """``--device`` if given, else PYOPENCL_CTX if set (the way to pin one device per worker), else,
    on a worker named by an integer n (LocalCluster's are 0…N−1), GPU number n mod the GPU count."""
    if spec.device or spec.backend != "opencl" or os.environ.get("PYOPENCL_CTX"):
        return spec.device
    try:
        from distributed import get_worker

        n = int(get_worker().name)
    except (ImportError, ValueError, TypeError):
        return None
    from .backends.cl_devices import _all_devices, import_pyopencl

    gpus = [d for _, d in _all_devices() if d.type & import_pyopencl().device_type.GPU]
    return gpus[n % len(gpus)] if gpus else None


def _write_cube(out, j: int, n: int, cube: np.ndarray, wavelengths):
    if "cubes" not in out:
        out.create_dataset("cubes", (n,) + cube.shape, np.float32, chunks=(1,) + cube.shape, fillvalue=np.nan)
        out["wavelengths"] = wavelengths
    out["cubes"][j] = cube


def _records(part: Path) -> list[dict]:
    import h5py

    with h5py.File(part, "r") as f:
        columns = {k: f[k].asstr()[...] if k in _TEXT else f[k][...] for k in ("index", "iterations", "seconds") + _TEXT}
    return [dict(zip(columns, row)) for row in zip(*columns.values())]


# ---- the whole batch --------------------------------------------------------------------------
def chunk_bounds(n_frames: int, chunk: int, first: int = 0) -> list[tuple[int, int]]:
    return [(s, min(s + chunk, n_frames)) for s in range(first, n_frames, chunk)]


def parts_dir(output: Path) -> Path:
    output = Path(output)
    return output.with_name(output.name + ".parts")


def run_batch(spec: BatchSpec, output, workers: int = 1, scheduler: str | None = None, chunk: int | None = None,
              overwrite: bool = False, progress=None, on_plan=None) -> BatchSummary:
    """Reconstruct every frame not yet in ``output``'s parts, then (re)build ``output``.

    ``workers`` = 0 (and no scheduler): one in-process stream (warm starts carried across its
    chunks); otherwise Dask distributed, an embedded LocalCluster of ``workers`` processes or
    the cluster at ``scheduler``. ``chunk`` defaults to ⌈missing / (2·worker threads)⌉, at
    most MAX_CHUNK. ``on_plan(n_frames, n_missing)`` is called once the missing frames are
    known, ``progress(k)`` as k more frames are done.
    """
    output = Path(output).resolve()
    spec = replace(spec, frames=tuple(str(Path(p).resolve()) for p in spec.frames),
                   calibration=str(Path(spec.calibration).resolve()))  # workers may run elsewhere
    n = len(FrameSource(spec.frames))
    parts = parts_dir(output)
    if overwrite:
        shutil.rmtree(parts, ignore_errors=True)
        output.unlink(missing_ok=True)
    _claim(parts, spec, n)
    missing = _missing(parts, n)
    if on_plan is not None:
        on_plan(n, len(missing))
    try:
        progress = _Progress(progress)
        start = time.perf_counter()
        lost = {}
        if missing and workers == 0 and scheduler is None:
            _run_serial(spec, parts, _chunks(missing, chunk, 1), progress)
        elif missing:
            with _client(workers, scheduler) as client:
                slots = sum(client.nthreads().values()) or max(workers, 1)
                lost = _run_dask(client, spec, parts, _chunks(missing, chunk, slots), progress)
    except BaseException:
        if not _parts(parts):  # nothing computed (e.g. no scheduler): leave no trace
            shutil.rmtree(parts, ignore_errors=True)
        raise
    summary = _assemble(output, n, lost)
    summary.computed_frames, summary.seconds = len(missing), time.perf_counter() - start
    return summary


def _claim(parts: Path, spec: BatchSpec, n: int):
    """Fingerprint the batch in ``parts/batch.json``; InputError if the parts belong to another one."""
    what = (spec.frames, spec.calibration, spec.preprocessing, spec.settings, spec.warm_start, n)
    stamp = {"fingerprint": hashlib.sha256(pickle.dumps(what)).hexdigest(), "frames": n,
             "settings": repr(spec.settings), "warm_start": spec.warm_start}
    path = parts / "batch.json"
    if path.exists():
        if json.loads(path.read_text())["fingerprint"] != stamp["fingerprint"]:
            raise InputError(f"{parts} holds frames of another batch (other frames, calibration or settings); "
                             "use --overwrite to start again")
        return
    parts.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(stamp, indent=1))


def _parts(parts: Path) -> list[tuple[int, int, Path]]:
    """The finished parts, as (start, stop, path), by start."""
    found = (( _PART.fullmatch(p.name), p) for p in parts.glob("chunk-*.h5"))
    return sorted((int(m[1]), int(m[2]), p) for m, p in found if m)


def _missing(parts: Path, n: int) -> list[int]:
    done = np.zeros(n, bool)
    for s, e, _ in _parts(parts):
        done[s:e] = True
    return [int(i) for i in np.flatnonzero(~done)]


def _chunks(missing: list[int], chunk: int | None, slots: int) -> list[tuple[int, int]]:
    """Contiguous runs of the missing frames, cut into chunks of ``chunk`` frames."""
    chunk = chunk or min(MAX_CHUNK, max(1, math.ceil(len(missing) / (2 * slots))))
    runs, first = [], missing[0]
    for a, b in zip(missing, missing[1:] + [None]):
        if b != a + 1:
            runs += chunk_bounds(a + 1, chunk, first)
            first = b
    return runs


def _part_path(parts: Path, start: int, stop: int) -> Path:
    return parts / f"chunk-{start:06d}-{stop:06d}.h5"


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
    past, last = (None, None), None
    for s, e in bounds:
        _, past = _stream(spec, s, e, _part_path(parts, s, e), lambda i: progress([i]), past if s == last else (None, None))
        last = e


def _dask_chunk(spec, start, stop, part, topic):
    """solve_chunk on a Dask worker, announcing each finished frame on the event ``topic``."""
    from distributed import get_worker

    worker = get_worker()
    return solve_chunk(spec, start, stop, part, lambda i: worker.log_event(topic, i))


def _run_dask(client, spec, parts, bounds, progress) -> dict[int, str]:
    """Run the chunks as tasks; {frame: reason} for the frames of chunks that failed as a whole
    (e.g. their worker died more often than Dask's allowed-failures): a re-run retries them."""
    from distributed import as_completed

    topic = f"clsdcam-frames-{uuid.uuid4().hex}"
    client.subscribe_topic(topic, lambda event: progress([event[1]]))
    futures = {client.submit(_dask_chunk, spec, s, e, str(_part_path(parts, s, e)), topic, pure=False,
                             key=f"clsdcam-chunk-{s}-{e}-{uuid.uuid4().hex}"): (s, e) for s, e in bounds}
    lost = {}
    try:
        for future in as_completed(futures, loop=client.loop):
            if future.status == "finished":
                progress(r["index"] for r in future.result())
            else:
                lost.update(dict.fromkeys(range(*futures[future]), f"chunk failed: {_reason(future.exception())}"))
    finally:
        client.unsubscribe_topic(topic)
        client.cancel(list(futures))
    return lost


class _client:
    """A Dask client on an embedded LocalCluster (``workers`` processes) or on ``scheduler``."""

    def __init__(self, workers: int, scheduler: str | None):
        self.workers, self.scheduler, self.cluster = workers, scheduler, None

    def __enter__(self):
        import logging

        from distributed import Client, LocalCluster

        if self.scheduler:
            try:
                self.client = Client(self.scheduler, timeout=30)
            except OSError as exc:
                raise InputError(f"--scheduler {self.scheduler}: cannot connect ({exc})") from None
        else:
            self.cluster = LocalCluster(n_workers=max(self.workers, 1), threads_per_worker=1, processes=True,
                                        dashboard_address=":0", silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
        return self.client

    def __exit__(self, *exc):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def _assemble(output: Path, n: int, lost: dict[int, str]) -> BatchSummary:
    """OUT.h5: a virtual ``cubes`` over the parts (NaN where a frame failed or is ``lost``) and per-frame records."""
    import h5py

    per_frame = {"iterations": np.zeros(n, np.int64), "seconds": np.zeros(n), "stop_reason": [""] * n, "error": [""] * n}
    layout, wavelengths = None, None
    for s, e, path in _parts(parts_dir(output)):
        for r in _records(path):
            for key in per_frame:
                per_frame[key][r["index"]] = r[key]
        with h5py.File(path, "r") as part:
            if "cubes" not in part:
                continue
            shape, wavelengths = part["cubes"].shape, part["wavelengths"][...]
            layout = layout or h5py.VirtualLayout(shape=(n,) + shape[1:], dtype=np.float32)
            layout[s:e] = h5py.VirtualSource(f"{path.parent.name}/{path.name}", "cubes", shape=shape)
    for i, reason in lost.items():
        per_frame["stop_reason"][i], per_frame["error"][i] = "failed", reason
    failed = [(i, per_frame["error"][i]) for i in range(n) if per_frame["error"][i]]
    if layout is None:
        raise InputError(f"no frame of {n} could be reconstructed; first error: {failed[0][1]}")
    with atomic_output(output) as tmp, h5py.File(tmp, "w") as f:
        f.create_virtual_dataset("cubes", layout, fillvalue=np.nan)
        f["wavelengths"] = wavelengths
        for key, values in per_frame.items():
            f[key] = np.array(values, dtype=h5py.string_dtype() if key in _TEXT else None)
        f.attrs.update(json.loads((parts_dir(output) / "batch.json").read_text()))
    return BatchSummary(n_frames=n, computed_frames=0, failed=failed)
