"""Reading lab frames: a few frames of one scene averaged, and a monochromator sweep read one frame at a time
(a real sweep, hundreds of 16-bit frames, does not fit in memory as float64).

A sweep is a folder of frames (PNG/TIFF 8/16-bit or 2-D .npy; hidden files skipped) sorted by file name, or
one stack (N, H, W): a .npy array, an HDF5 file with dataset ``frames``, or a multi-page TIFF (a single-page
TIFF is one frame).
Every frame must have the first one's size. The stored integer type gives the saturation code: the largest
value of the type (65535 for 16-bit frames; None for floating-point frames). Folder frames and TIFF pages are
read one by one, a .npy stack is memory-mapped, an HDF5 stack is read whole in its stored type.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import InputError, shape_text
from ..io import IMAGE_SUFFIXES, read_image, read_npy, as_real_array, code_max, existing_file, first_line
from ..io import load_frame, load_measurement
from ..io import read_h5_dataset, require_finite

FRAME_SUFFIXES = IMAGE_SUFFIXES + (".npy",)
STACK_KEY = "frames"


def average_frames(paths, what: str = "frame") -> tuple[np.ndarray, float | None]:
    """((1/n) Σ_i frame_i, code) of the files (read by :func:`clsdcam.io.load_frame`, errors naming them as
    ``what``), code the saturation code of the first frame's stored type; InputError naming the first file whose
    size differs from the first frame's."""
    paths = [Path(p) for p in paths]
    total, code = load_frame(paths[0], what)
    for path in paths[1:]:
        frame = load_measurement(path, what)
        if frame.shape != total.shape:
            raise InputError(f"{what} {path}: {shape_text(frame.shape)}, but {paths[0]} is "
                             f"{shape_text(total.shape)} (frames of mixed sizes)")
        total += frame
    return total / len(paths), code


@dataclass(frozen=True)
class Sweep:
    """N frames of one size; ``frame(i)`` reads frame i as float64 (H, W)."""

    source: Path
    names: tuple[str, ...]
    shape: tuple[int, int]
    code_max: float | None
    reader: Callable[[int], np.ndarray]

    def __len__(self) -> int:
        return len(self.names)

    def frame(self, i: int) -> np.ndarray:
        name = f"sweep {self.source}: frame {self.names[i]}"
        frame = require_finite(as_real_array(self.reader(i), name), name)
        if frame.shape != self.shape:
            raise InputError(f"{name} is {shape_text(frame.shape)}, the first is {shape_text(self.shape)} "
                             "(frames of mixed sizes)")
        return frame


def open_sweep(path) -> Sweep:
    """A folder of frames or one stack file (see the module docstring); InputError when unreadable."""
    path = Path(path)
    if path.is_dir():
        return _folder(path)
    path = existing_file(path, "sweep")
    suffix = path.suffix.lower()
    opener = {".npy": _npy_stack, ".h5": _h5_stack, ".hdf5": _h5_stack, ".tif": _tiff_stack, ".tiff": _tiff_stack}
    if suffix not in opener:
        raise InputError(f"sweep {path}: expected a folder of frames, a .npy/.h5 stack or a multi-page TIFF")
    return opener[suffix](path)


def _native(path: Path) -> np.ndarray:
    """One frame file as stored (its integer type kept), through clsdcam.io's readers."""
    return read_npy(path) if path.suffix.lower() == ".npy" else read_image(path)


def _folder(path: Path) -> Sweep:
    files = sorted(p for p in path.iterdir()
                   if p.is_file() and p.suffix.lower() in FRAME_SUFFIXES and not p.name.startswith("."))
    if not files:
        raise InputError(f"sweep {path}: no frames ({', '.join(FRAME_SUFFIXES)}) in the folder")
    first = _native(files[0])
    if first.ndim != 2:
        raise InputError(f"sweep {files[0]}: expected a 2-D frame, found shape {first.shape}")
    return Sweep(path, tuple(p.name for p in files), first.shape, code_max(first.dtype),
                 lambda i: _native(files[i]))


def _stack(path: Path, shape, dtype, reader) -> Sweep:
    if len(shape) != 3 or 0 in shape:
        raise InputError(f"sweep {path}: expected a stack (N, H, W), found shape {tuple(shape)}")
    return Sweep(path, tuple(str(i) for i in range(shape[0])), tuple(shape[1:]), code_max(dtype), reader)


def _npy_stack(path: Path) -> Sweep:
    try:
        stack = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as exc:  # numpy's header parser raises many types
        raise InputError(f"sweep {path}: not a readable .npy array ({first_line(exc)})") from None
    return _stack(path, stack.shape, stack.dtype, lambda i: np.asarray(stack[i]))


def _h5_stack(path: Path) -> Sweep:
    stack = read_h5_dataset(path, STACK_KEY, "sweep")
    return _stack(path, stack.shape, stack.dtype, lambda i: stack[i])


def _tiff_stack(path: Path) -> Sweep:
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            pages = [page.shape for page in tif.pages]
            dtype = tif.pages[0].dtype
    except Exception as exc:  # tifffile raises many types for corrupt files
        raise InputError(f"sweep {path}: not a readable TIFF ({first_line(exc)})") from None
    return _stack(path, (len(pages), *pages[0]), dtype, lambda i: _tiff_page(path, i))


def _tiff_page(path: Path, i: int) -> np.ndarray:
    import tifffile

    try:
        return tifffile.imread(path, key=i)
    except Exception as exc:  # a truncated page
        raise InputError(f"sweep {path}: page {i} is not readable ({first_line(exc)})") from None
