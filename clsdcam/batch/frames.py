"""Frame sources for batches: a list of single-frame files, a folder of them, or one stack
(``.npy``/``.h5`` (N,H,W), multi-page TIFF), read lazily — one frame at a time, never the stack."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import IMAGE_SUFFIXES, as_real_array, load_measurement, require_finite

FRAME_SUFFIXES = IMAGE_SUFFIXES + (".npy", ".h5", ".hdf5")
STACK_KEYS = ("frames", "measurement", "measurements")


class FrameSource:
    """``len(source)`` frames; ``source.read(i)`` → (H, W) float64 or InputError naming the frame."""

    def __init__(self, inputs):
        paths = [Path(p) for p in inputs]
        if not paths:
            raise InputError("no frames given")
        if len(paths) == 1 and paths[0].is_dir():
            paths = sorted(p for p in paths[0].iterdir() if p.suffix.lower() in FRAME_SUFFIXES)
            if not paths:
                raise InputError(f"{inputs[0]}: no frame files ({', '.join(FRAME_SUFFIXES)}) in this folder")
        missing = [str(p) for p in paths if not p.is_file()]
        if missing:
            raise InputError(f"frames not found: {', '.join(missing[:3])}{' …' if len(missing) > 3 else ''}")
        self.paths = paths
        self.stack = _stack_length(paths[0]) if len(paths) == 1 else None
        self.description = f"{paths[0]} ({self.stack} frames)" if self.stack else f"{len(paths)} files"

    def __len__(self) -> int:
        return self.stack or len(self.paths)

    def read(self, i: int) -> np.ndarray:
        if self.stack is None:
            return load_measurement(self.paths[i])
        name = f"frame {i} of {self.paths[0]}"
        frame = as_real_array(_read_stack_frame(self.paths[0], i), name)
        return require_finite(frame, name)


def _stack_length(path: Path) -> int | None:
    """N for an (N, H, W) stack file, None for a single frame."""
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            shape = np.load(path, mmap_mode="r").shape
        elif suffix in (".h5", ".hdf5"):
            import h5py

            with h5py.File(path, "r") as f:
                key = next((k for k in STACK_KEYS if k in f), None)
                shape = f[key].shape if key else ()
        elif suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                return len(tif.pages) if len(tif.pages) > 1 else None
        else:
            return None
    except Exception as exc:  # loaders raise many types on damaged files
        raise InputError(f"frames {path}: not readable ({exc})") from None
    return shape[0] if len(shape) == 3 else None


def _read_stack_frame(path: Path, i: int) -> np.ndarray:
    suffix = path.suffix.lower()
    if suffix == ".npy":
        return np.array(np.load(path, mmap_mode="r")[i])
    if suffix in (".tif", ".tiff"):
        import tifffile

        return tifffile.imread(path, key=i)
    import h5py

    with h5py.File(path, "r") as f:
        return f[next(k for k in STACK_KEYS if k in f)][i]
