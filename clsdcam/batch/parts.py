"""Part files: what a batch has done, how it resumes, and the output assembled from them.

Parts. Chunk [s, e) is written into a temporary file renamed to
``OUT.h5.parts/chunk-SSSSSS-EEEEEE.h5``: a part is whole or absent. It holds ``cubes``
(e − s, K, H, W) (NaN where a frame failed), ``wavelength`` and per-frame ``index``,
``iterations``, ``stop_reason``, ``seconds``, ``error``, ``warm`` (started from the previous frame's state).

Resume. A frame is done when some part covers it; a re-run computes only the others (any
chunk size, any worker count), cut into contiguous chunks, after removing the temporaries
(``.chunk-SSSSSS-EEEEEE.h5.RANDOM.h5``) that writers killed in earlier runs left behind.
``batch.json`` in the parts folder fingerprints the frames and settings, so parts made by a
different command are never mixed in (``overwrite``): the fingerprint is SHA-256 of a
canonical JSON text (sorted keys; dataclasses as their fields, tuples as lists, NumPy scalars
as numbers), the same on any Python or NumPy.

Output. ``OUT.h5`` holds ``cubes`` (N,K,H,W), an HDF5 virtual dataset over the parts (NaN
where a frame failed), with dimension scales ``frame``, ``wavelength`` (nm), ``y``, ``x`` as
single cubes have them (xarray's h5netcdf engine reads them as dims and coordinates), per-frame
``iterations``, ``stop_reason``, ``seconds``, ``error``, ``warm`` (on the ``frame`` scale), and as
attributes the provenance (:mod:`clsdcam.provenance`), the batch's settings and, against a truth
(:mod:`clsdcam.batch.truth`), the per-frame ``psnr``, ``spectral_angle`` and ``peak_ratio``; it is
rebuilt, atomically, at the end of every run.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_output, attach_scales, check_output, read_wavelengths, write_wavelengths
from .spec import BatchSpec, BatchSummary

MAX_CHUNK = 64          # default chunk cap: bounds the work a crash loses and keeps tasks balanced
TEXT_KEYS = ("stop_reason", "error")
NUMBER_KEYS = ("index", "iterations", "seconds", "warm")
_PART = re.compile(r"chunk-(\d+)-(\d+)\.h5$")
_TEMPORARY = re.compile(r"\.chunk-\d+-\d+\.h5\.[0-9a-f]+\.h5")  # atomic_output's name for a part being written


# ---- names and chunks -------------------------------------------------------------------------
def parts_dir(output: Path) -> Path:
    output = Path(output)
    return output.with_name(output.name + ".parts")


def part_path(parts: Path, start: int, stop: int) -> Path:
    return parts / f"chunk-{start:06d}-{stop:06d}.h5"


def chunk_bounds(n_frames: int, chunk: int, first: int = 0) -> list[tuple[int, int]]:
    return [(s, min(s + chunk, n_frames)) for s in range(first, n_frames, chunk)]


def chunks(missing: list[int], chunk: int | None, slots: int) -> list[tuple[int, int]]:
    """Contiguous runs of the missing frames, cut into chunks of ``chunk`` frames, by default
    min(MAX_CHUNK, ⌈missing / slots⌉): one chunk per worker slot, so a short batch is cut no more than its
    workers need (each chunk's first frame is a cold start: cutting finer buys no parallelism and costs
    warm starts), and a long one into MAX_CHUNK-frame runs (what a crash loses; balance across workers)."""
    chunk = chunk or min(MAX_CHUNK, max(1, math.ceil(len(missing) / slots)))
    runs, first = [], missing[0]
    for a, b in zip(missing, missing[1:] + [None]):
        if b != a + 1:
            runs += chunk_bounds(a + 1, chunk, first)
            first = b
    return runs


def finished_parts(parts: Path) -> list[tuple[int, int, Path]]:
    """The finished parts, as (start, stop, path), by start."""
    found = ((_PART.fullmatch(p.name), p) for p in parts.glob("chunk-*.h5"))
    return sorted((int(m[1]), int(m[2]), p) for m, p in found if m)


def missing_frames(parts: Path, n: int) -> list[int]:
    """The frames no finished part covers."""
    done = np.zeros(n, bool)
    for s, e, _ in finished_parts(parts):
        done[s:e] = True
    return [int(i) for i in np.flatnonzero(~done)]


# ---- batch.json: the fingerprint --------------------------------------------------------------
def canonical_text(value) -> str:
    """``value`` as JSON with sorted keys: dataclasses as their fields, tuples as lists, NumPy values as numbers."""
    return json.dumps(value, sort_keys=True, default=_plain)


def _plain(value):
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} has no canonical JSON form")


def stamp(spec: BatchSpec, n: int) -> dict:
    """The contents of ``batch.json``: the fingerprint of what decides the cubes, and the settings as text."""
    what = {"frames": spec.frames, "calibration": spec.calibration, "preprocessing": spec.preprocessing,
            "settings": spec.settings, "warm_start": spec.warm_start, "cold_iters": spec.cold_iters, "n_frames": n}
    return {"fingerprint": hashlib.sha256(canonical_text(what).encode()).hexdigest(), "frames": n,
            "settings": canonical_text(spec.settings), "warm_start": spec.warm_start}


def claim(parts: Path, spec: BatchSpec, n: int):
    """Fingerprint the batch in ``parts/batch.json``; InputError if ``parts`` cannot be written or belongs to
    another batch. A resume first removes the temporaries that earlier runs left (never a finished part)."""
    ours = stamp(spec, n)
    path = check_output(parts / "batch.json", "parts folder")
    if not path.exists():
        with atomic_output(path) as tmp:
            tmp.write_text(json.dumps(ours, indent=1))
        return
    if json.loads(path.read_text())["fingerprint"] != ours["fingerprint"]:
        raise InputError(f"{parts} holds frames of another batch (other frames, calibration or settings); "
                         "use --overwrite to start again")
    for stale in (p for p in parts.iterdir() if _TEMPORARY.fullmatch(p.name)):
        stale.unlink(missing_ok=True)


# ---- reading and writing parts ----------------------------------------------------------------
def write_cube(out, j: int, n: int, cube: np.ndarray, wavelengths):
    """Cube j of the part's n (``cubes`` is created, NaN-filled, with the first one)."""
    if "cubes" not in out:
        out.create_dataset("cubes", (n,) + cube.shape, np.float32, chunks=(1,) + cube.shape, fillvalue=np.nan)
        write_wavelengths(out, wavelengths)
    out["cubes"][j] = cube


def write_columns(out, columns: dict):
    """Per-frame columns as datasets, the text ones as UTF-8 strings."""
    import h5py

    for key, values in columns.items():
        out[key] = np.array(values, dtype=h5py.string_dtype() if key in TEXT_KEYS else None)


def read_records(part: Path) -> list[dict]:
    """The per-frame records of a part: ``index``, ``iterations``, ``seconds``, ``warm``, ``stop_reason``,
    ``error``."""
    import h5py

    with h5py.File(part, "r") as f:
        columns = {k: f[k].asstr()[...] if k in TEXT_KEYS else f[k][...] for k in NUMBER_KEYS + TEXT_KEYS}
    return [dict(zip(columns, row)) for row in zip(*columns.values())]


# ---- the output -------------------------------------------------------------------------------
def assemble(output: Path, n: int, lost: dict[int, str], attrs: dict, score=None) -> BatchSummary:
    """OUT.h5: a virtual ``cubes`` over the parts (NaN where a frame failed or is ``lost``) with its dimension
    scales, per-frame records, and ``attrs`` (the provenance) beside the batch's settings; with ``score``
    (``cubes`` → {name: per-frame figures}, :meth:`clsdcam.batch.truth.TruthVideo.score`) its figures too."""
    import h5py

    per_frame, layout, wavelengths = _gather(parts_dir(output), n)
    for i, reason in lost.items():
        per_frame["stop_reason"][i], per_frame["error"][i] = "failed", reason
    failed = [(i, per_frame["error"][i]) for i in range(n) if per_frame["error"][i]]
    if layout is None:
        raise InputError(f"no frame of {n} could be reconstructed; first error: {failed[0][1]}")
    with atomic_output(output) as tmp, h5py.File(tmp, "w") as f:
        cubes = f.create_virtual_dataset("cubes", layout, fillvalue=np.nan)
        write_columns(f, per_frame)
        attach_scales(f, cubes, wavelengths)
        for key in per_frame:
            f[key].dims[0].attach_scale(f["frame"])
        f.attrs.update({**attrs, **json.loads((parts_dir(output) / "batch.json").read_text())})
        accuracy = score(cubes) if score is not None else {}
        f.attrs.update(accuracy)
    return BatchSummary(n_frames=n, computed_frames=0, failed=failed, per_frame=per_frame, accuracy=accuracy)


def _gather(parts: Path, n: int):
    """(per-frame columns, the virtual layout of the parts' cubes (None: no cube anywhere), wavelengths)."""
    import h5py

    per_frame = {"iterations": np.zeros(n, np.int64), "seconds": np.zeros(n), "warm": np.zeros(n, bool),
                 "stop_reason": [""] * n, "error": [""] * n}
    layout, wavelengths = None, None
    for s, e, path in finished_parts(parts):
        for r in read_records(path):
            for key in per_frame:
                per_frame[key][r["index"]] = r[key]
        with h5py.File(path, "r") as part:
            if "cubes" not in part:
                continue
            shape = part["cubes"].shape
            wavelengths = read_wavelengths(part, shape[1])
            layout = layout or h5py.VirtualLayout(shape=(n,) + shape[1:], dtype=np.float32)
            layout[s:e] = h5py.VirtualSource(f"{path.parent.name}/{path.name}", "cubes", shape=shape)
    return per_frame, layout, wavelengths
