"""Frame sources for batches: a list of single-frame files, a folder of them, or one stack
(``.npy``/``.h5`` (N,H,W), multi-page TIFF), read lazily — one frame (or, to check them, one block
of frames) at a time, never the stack."""
from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import IMAGE_SUFFIXES, as_real_array, load_measurement, require_finite
from .parts import chunks

FRAME_SUFFIXES = IMAGE_SUFFIXES + (".npy", ".h5", ".hdf5")
STACK_KEYS = ("frames", "measurement", "measurements")
CHECK_BYTES = 64 << 20  # a stack is checked in blocks of about this many bytes (at least one frame)


class FrameSource:
    """``len(source)`` frames; ``source.read(i)`` → (H, W) float64 or InputError naming the frame;
    ``source.check(indices)`` → None or InputError naming the first bad frame."""

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
        self.stack, self.frame_bytes = _stack_layout(paths[0]) if len(paths) == 1 else (None, 0)
        self.description = f"{paths[0]} ({self.stack} frames)" if self.stack else f"{len(paths)} files"

    def __len__(self) -> int:
        return self.stack or len(self.paths)

    def read(self, i: int) -> np.ndarray:
        if self.stack is None:
            return load_measurement(self.paths[i])
        frame = as_real_array(_read_stack_block(self.paths[0], i, i + 1)[0], self._name(i))
        return require_finite(frame, self._name(i))

    def check(self, indices) -> None:
        """Read frames ``indices`` (ascending) once, before any work: InputError (one line) naming the first that
        cannot be read, is not real numbers, or holds NaN/Inf (with its count and first pixel (y, x)).

        Cost: one pass over those frames on disk, nothing kept. Single-frame files are each loaded and
        checked as ``read`` does (one frame in memory at a time). A stack is read in contiguous blocks of
        about CHECK_BYTES (64 MiB, at least one frame) and tested with ``np.isfinite`` (a boolean mask of the
        block beside it), so memory stays O(block) whatever the video's length; the time is one read of the
        frames (for a stack, its size over the disk's bandwidth) plus one comparison per value.
        """
        indices = list(indices)
        if not indices:
            return
        if self.stack is None:
            for i in indices:
                self.read(i)
            return
        for start, stop in chunks(indices, max(1, CHECK_BYTES // max(self.frame_bytes, 1)), 1):
            _check_block(_read_stack_block(self.paths[0], start, stop), start, self._name)

    def _name(self, i: int) -> str:
        return f"frame {i} of {self.paths[0]}"


def _check_block(block: np.ndarray, start: int, name) -> None:
    """InputError for the first frame of ``block`` (frames ``start``…) that is not real numbers or not finite."""
    if block.dtype.kind not in "biuf":
        as_real_array(block[:1], name(start))  # raises: names the dtype
    if block.dtype.kind == "f":
        finite = np.isfinite(block).reshape(len(block), -1).all(axis=1)
        if not finite.all():
            first = int(np.argmin(finite))
            require_finite(block[first], name(start + first))  # raises: the count and first pixel (y, x)


@contextlib.contextmanager
def _readable(path: Path):
    """Any loader's exception as one InputError line: the stack is damaged or not what it claims to be."""
    try:
        yield
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - loaders raise many types on damaged files
        raise InputError(f"frames {path}: not readable ({exc})") from None


def _stack_layout(path: Path) -> tuple[int | None, int]:
    """(N, bytes of one frame) for an (N, H, W) stack file, (None, 0) for a single frame."""
    suffix = path.suffix.lower()
    with _readable(path):
        if suffix == ".npy":
            array = np.load(path, mmap_mode="r")
            shape, itemsize = array.shape, array.itemsize
        elif suffix in (".h5", ".hdf5"):
            import h5py

            with h5py.File(path, "r") as f:
                key = next((k for k in STACK_KEYS if k in f), None)
                shape, itemsize = (f[key].shape, f[key].dtype.itemsize) if key else ((), 0)
        elif suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tif:
                page = tif.pages[0]
                shape, itemsize = (len(tif.pages),) + tuple(page.shape), page.dtype.itemsize
        else:
            return None, 0
    if len(shape) != 3 or (shape[0] < 2 and suffix in (".tif", ".tiff")):  # one TIFF page: a single frame
        return None, 0
    return shape[0], int(np.prod(shape[1:])) * itemsize


def _read_stack_block(path: Path, start: int, stop: int) -> np.ndarray:
    """Frames [start, stop) of the stack as one (stop − start, H, W) array in its stored dtype."""
    suffix = path.suffix.lower()
    with _readable(path):
        if suffix == ".npy":
            return np.array(np.load(path, mmap_mode="r")[start:stop])
        if suffix in (".tif", ".tiff"):
            import tifffile

            block = tifffile.imread(path, key=range(start, stop))
            return block.reshape((stop - start,) + block.shape[-2:])
        import h5py

        with h5py.File(path, "r") as f:
            return f[next(k for k in STACK_KEYS if k in f)][start:stop]
