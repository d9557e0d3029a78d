"""Calibration: the PSF, the filter function and the band wavelengths; loading and preprocessing.

Layouts read:
- the paper's ``calibration.mat``: ``psf`` (H,W), ``mask`` (H,W,K), ``wavs`` (1,K) or (K,1),
  in MATLAB v5 (scipy.io) or v7.3 (HDF5; MATLAB stores arrays transposed, undone here);
- our HDF5: ``psf`` (H,W), ``filters`` (K,H,W), ``wavelength`` (K,) (``wavelengths`` in files written before
  :data:`clsdcam.io.WAVELENGTH`); optionally ``dead_pixels`` (H,W) bool
  (pixels left out of every reconstruction, from ``clsdcam calibrate filters``) and a group ``raw``: the steps that
  turned raw frames into the calibration's size (:mod:`clsdcam.camera.raw`), which ``prepare`` applies to a
  measurement of the recorded raw size.
Inside, filters are (K,H,W) (docs/conventions.md); the file's (H,W,K) is converted at load time.

Preprocessing (each step an option, the reference set in :meth:`Preprocessing.reference`):
crop a window of calibration and measurement, drop the last band, zero the 4×4 defective
block around the brightest pixel of Σ_k F_k (in filters and measurement), PSF → PSF/‖PSF‖₂,
filters → F/max F. Before them, :func:`clsdcam.calibrate.measurement.prepare` gives the measurement its raw steps: the calibration's recorded
ones for a raw-size frame, else its own dark and binning (``Preprocessing.dark``, ``.bin``;
:mod:`clsdcam.calibrate.measurement`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .raw import RawSteps, read_record, write_record
from ..errors import InputError, shape_text
from ..io import (MAX_DATASET_BYTES, WAVELENGTH, as_real_array, atomic_output, existing_file, first_line,
                  read_dataset, require_finite, wavelength_key, write_wavelengths)

REFERENCE_CROP = (100, 420, 80, 540)  # rows 100:420, cols 80:540 of the 494×659 raw frame
DEFECT_HALF = 2                        # the reference zeroes [i−2:i+2, j−2:j+2]


@dataclass
class Calibration:
    """psf (H,W), filters (K,H,W), wavelengths (K,) in nm, and where they came from.

    ``scale``: the factor the model A was divided by when the PSF and filters were normalised
    (:func:`preprocess`); a cube solved on this calibration, divided by it, is in the units of the
    calibration as it was measured (normalising conditions the solve, it does not change the units).
    ``raw``: the raw steps of the PSF frames (:class:`clsdcam.camera.raw.RawSteps`), None if unknown;
    ``dead_pixels``: (H,W) bool, pixels whose filter function is not to be trusted (None: none).
    """

    psf: np.ndarray
    filters: np.ndarray
    wavelengths: np.ndarray
    source: str = "memory"
    scale: float = 1.0
    raw: RawSteps | None = None
    dead_pixels: np.ndarray | None = None

    def __post_init__(self):
        self.psf = require_finite(as_real_array(self.psf, f"{self.source}: psf"), f"{self.source}: psf")
        self.filters = require_finite(as_real_array(self.filters, f"{self.source}: filters"), f"{self.source}: filters")
        self.wavelengths = require_finite(as_real_array(self.wavelengths, f"{self.source}: wavelengths"),
                                          f"{self.source}: wavelengths").ravel()
        self._check_shapes()

    def _check_shapes(self):
        src, psf, filters = self.source, self.psf, self.filters
        if psf.ndim != 2 or min(psf.shape) < 1:
            raise InputError(f"{src}: psf must be a 2-D image, found shape {psf.shape}")
        if filters.ndim != 3:
            raise InputError(f"{src}: filters must be 3-D (K, {psf.shape[0]}, {psf.shape[1]}) for the "
                             f"{shape_text(psf.shape)} psf, found {filters.ndim}-D shape {shape_text(filters.shape)}")
        if filters.shape[1:] != psf.shape:
            raise InputError(f"{src}: filters of {shape_text(filters.shape[1:])} per band do not match psf "
                             f"{shape_text(psf.shape)}")
        if self.wavelengths.shape != (filters.shape[0],):
            raise InputError(f"{src}: {self.wavelengths.size} wavelengths for {filters.shape[0]} bands")
        if not np.any(psf):
            raise InputError(f"{src}: the psf is all zeros")
        if not np.any(filters):
            raise InputError(f"{src}: the filters are all zeros")
        if self.dead_pixels is not None:
            self.dead_pixels = np.asarray(self.dead_pixels) != 0
            if self.dead_pixels.shape != psf.shape:
                raise InputError(f"{src}: dead_pixels {shape_text(self.dead_pixels.shape)} do not match psf "
                                 f"{shape_text(psf.shape)}")

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.psf.shape)

    @property
    def n_bands(self) -> int:
        return self.filters.shape[0]

    @classmethod
    def load(cls, path) -> "Calibration":
        """Read the paper's ``calibration.mat`` (v5 or v7.3) or our HDF5 layout."""
        path = existing_file(path, "calibration")
        psf, filters, wavelengths, *extras = _read_mat_v5(path) if _is_mat_v5(path) else _read_hdf5_calibration(path)
        return cls(psf, filters, wavelengths, source=str(path), **(extras[0] if extras else {}))

    def save(self, path) -> Path:
        """Write our HDF5 layout atomically."""
        import h5py

        path = Path(path)
        with atomic_output(path) as tmp, h5py.File(tmp, "w") as f:
            f["psf"] = self.psf.astype(np.float32)
            f["filters"] = self.filters.astype(np.float32)
            write_wavelengths(f, self.wavelengths)
            f.attrs["source"] = self.source
            f.attrs["units_scale"] = self.scale
            if self.dead_pixels is not None:
                f["dead_pixels"] = self.dead_pixels
            if self.raw is not None:
                write_record(f, self.raw)
        return path


# ---- file layouts ---------------------------------------------------------------------------
def _is_mat_v5(path: Path) -> bool:
    """MATLAB v5 files start with a 116-byte text header 'MATLAB 5.0 MAT-file'; v7.3 is HDF5."""
    with open(path, "rb") as f:
        head = f.read(128)
    return head.startswith(b"MATLAB") and b"MATLAB 7.3" not in head


def _read_mat_v5(path: Path):
    """The numeric variables of a v5 file, through our bounds-checked reader (see ``matv5``)."""
    from ..matv5 import MatFormatError, read_mat_v5

    try:
        contents = read_mat_v5(path.read_bytes(), MAX_DATASET_BYTES)
    except MatFormatError as exc:
        raise InputError(f"calibration {path}: not a readable MATLAB v5 file ({exc})") from None
    return _paper_layout(path, contents)


def _read_hdf5_calibration(path: Path):
    """Our layout (``filters`` (K,H,W)) or a MATLAB v7.3 file (``mask``, transposed by MATLAB)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if "filters" in f:
                keys = ("psf", "filters", wavelength_key(f) or WAVELENGTH)
                return (*(read_dataset(f, key, f"calibration {path}") for key in keys),
                        _our_extras(f, f"calibration {path}"))
            contents = {key: read_dataset(f, key, f"calibration {path}").T for key in ("psf", "mask", "wavs") if key in f}
            contents["__keys__"] = list(f.keys())
    except (OSError, ValueError, TypeError, KeyError, RuntimeError, MemoryError) as exc:
        raise InputError(f"calibration {path}: neither a MATLAB nor an HDF5 file ({first_line(exc)})") from None
    return _paper_layout(path, contents)


def _our_extras(f, name: str) -> dict:
    """Calibration's optional fields from our layout: scale, dead_pixels, raw."""
    dead = read_dataset(f, "dead_pixels", name) if "dead_pixels" in f else None
    return {"scale": float(f.attrs.get("units_scale", 1.0)), "dead_pixels": dead, "raw": read_record(f, name)}


def _paper_layout(path, contents: dict):
    """(psf, filters (K,H,W), wavelengths) from ``psf`` (H,W), ``mask`` (H,W,K), ``wavs`` (1,K)."""
    missing = [key for key in ("psf", "mask", "wavs") if key not in contents]
    if missing:
        found = [k for k in contents.get("__keys__", contents) if not k.startswith("__")]
        raise InputError(f"calibration {path}: missing {', '.join(missing)} (found: {', '.join(found) or 'nothing'})")
    mask = as_real_array(contents["mask"], f"calibration {path}: mask")
    if mask.ndim == 2:  # one band saved without its trailing axis
        mask = mask[:, :, None]
    if mask.ndim != 3:
        raise InputError(f"calibration {path}: mask must be (H, W, K), found shape {mask.shape}")
    return contents["psf"], np.moveaxis(mask, -1, 0), np.ravel(contents["wavs"])


# ---- preprocessing ----------------------------------------------------------------------------
@dataclass(frozen=True)
class PixelMask:
    """A set of pixels of an (H, W) frame, as sorted (y, x) pairs: hashable, comparable and picklable, so the
    :class:`Preprocessing` holding it is too (an ndarray field would make ``==`` and ``hash`` raise)."""

    shape: tuple[int, int]
    pixels: tuple[tuple[int, int], ...]

    @classmethod
    def of(cls, mask) -> "PixelMask":
        """The non-zero pixels of a 2-D array."""
        mask = np.asarray(mask) != 0
        return cls(tuple(int(n) for n in mask.shape), tuple((int(y), int(x)) for y, x in np.argwhere(mask)))

    def array(self) -> np.ndarray:
        """(H, W) bool, True at the pixels."""
        mask = np.zeros(self.shape, bool)
        if self.pixels:
            mask[tuple(np.array(self.pixels).T)] = True
        return mask


@dataclass(frozen=True)
class Preprocessing:
    """Which preprocessing steps to apply; the defaults suit an already-cropped calibration."""

    crop: tuple[int, int, int, int] | None = None  # (y0, y1, x0, x1), half-open
    normalize_psf: bool = True
    normalize_filters: bool = True
    zero_defect: bool = False
    drop_last_band: bool = False
    saturation: float | str | None = None    # exclude pixels with b ≥ saturation from the data term; "auto":
                                             # clsdcam.calibrate.measurement.saturation_level's level
    dead_pixels: PixelMask | None = None     # pixels to exclude, on the frame after cropping
    dark: float | tuple[str, ...] | None = None   # the measurement's dark: a level or dark frame files (averaged)
    bin: int = 1                             # the measurement's n × n binning (:mod:`.calibrate.measurement`)

    @classmethod
    def reference(cls) -> "Preprocessing":
        """The authors' published preprocessing of ``calibration.mat`` and their raw frames."""
        return cls(crop=REFERENCE_CROP, zero_defect=True, drop_last_band=True)


def parse_crop(text: str) -> tuple[int, int, int, int]:
    """``"Y0:Y1,X0:X1"`` → (y0, y1, x0, x1), or InputError."""
    try:
        rows, cols = text.split(",")
        (y0, y1), (x0, x1) = (tuple(int(v) for v in part.split(":")) for part in (rows, cols))
    except ValueError:
        raise InputError(f"--crop {text!r}: expected Y0:Y1,X0:X1, e.g. 100:420,80:540") from None
    if not (0 <= y0 < y1 and 0 <= x0 < x1):
        raise InputError(f"--crop {text!r}: need 0 ≤ Y0 < Y1 and 0 ≤ X0 < X1")
    return (y0, y1, x0, x1)


def preprocess(calibration: Calibration, measurement: np.ndarray, options: Preprocessing):
    """Apply ``options`` to a calibration and its measurement; returns both, new arrays.

    A measurement whose shape differs from the calibration is rejected unless a crop is given,
    in which case both must contain the crop window (the raw frame may be larger). The calibration's own
    ``dead_pixels`` are excluded with those of ``options`` (the result has them applied: its ``dead_pixels``
    is None).
    """
    psf, filters, b = calibration.psf, calibration.filters, np.asarray(measurement, np.float64)
    dead = np.zeros(psf.shape, bool) if calibration.dead_pixels is None else calibration.dead_pixels
    if options.crop is not None:
        window = _crop_window(options.crop, calibration, b)
        psf, filters, b, dead = psf[window], filters[(slice(None),) + window], b[window], dead[window]
    elif b.shape != psf.shape:
        raise InputError(f"measurement {shape_text(b.shape)} does not match calibration {shape_text(psf.shape)} "
                         f"({calibration.source}); give --crop Y0:Y1,X0:X1")
    wavelengths = calibration.wavelengths
    if options.drop_last_band:
        if filters.shape[0] < 2:
            raise InputError(f"{calibration.source}: cannot drop the last of {filters.shape[0]} band")
        filters, wavelengths = filters[:-1], wavelengths[:-1]
    if options.zero_defect:
        filters, b = zero_defect_block(filters, b)
    filters, b = exclude_pixels(filters, b, excluded_pixels(b, options) | dead)
    scale = calibration.scale
    if options.normalize_psf:
        scale *= np.linalg.norm(psf)
        psf = psf / np.linalg.norm(psf)
    if options.normalize_filters:
        scale *= np.max(filters)
        filters = filters / np.max(filters)
    out = replace(calibration, psf=psf, filters=filters, wavelengths=wavelengths, scale=float(scale), dead_pixels=None)
    return out, b


def _crop_window(crop, calibration: Calibration, b: np.ndarray) -> tuple[slice, slice]:
    y0, y1, x0, x1 = crop
    for name, shape in (("calibration", calibration.shape), ("measurement", b.shape)):
        if y1 > shape[0] or x1 > shape[1]:
            raise InputError(f"--crop {y0}:{y1},{x0}:{x1} lies outside the {name} {shape_text(shape)}")
    return slice(y0, y1), slice(x0, x1)


def zero_defect_block(filters: np.ndarray, b: np.ndarray):
    """Zero the 4×4 block [i−2:i+2, j−2:j+2] at (i, j) = argmax Σ_k F_k in filters and measurement.

    The prototype has a defective, over-bright pixel cluster in its calibration; the authors
    remove it from both the filter function and the data.
    """
    i, j = np.unravel_index(np.argmax(filters.sum(axis=0)), filters.shape[1:])
    block = (slice(max(i - DEFECT_HALF, 0), i + DEFECT_HALF), slice(max(j - DEFECT_HALF, 0), j + DEFECT_HALF))
    filters, b = filters.copy(), b.copy()
    filters[(slice(None),) + block] = 0
    b[block] = 0
    return filters, b


def excluded_pixels(b: np.ndarray, options: Preprocessing) -> np.ndarray:
    """(H, W) bool: saturated (b ≥ ``saturation``) or listed dead pixels."""
    excluded = np.zeros(b.shape, bool)
    if options.saturation is not None:
        excluded |= b >= options.saturation
    if options.dead_pixels is not None:
        if options.dead_pixels.shape != b.shape:
            raise InputError(f"dead-pixel mask {shape_text(options.dead_pixels.shape)} does not match the "
                             f"measurement {shape_text(b.shape)} (after cropping)")
        excluded |= options.dead_pixels.array()
    return excluded


def exclude_pixels(filters: np.ndarray, b: np.ndarray, excluded: np.ndarray):
    """Remove pixels from the data term: F_k = 0 and b = 0 there, so row (y, x) of A and of b vanish
    and ½‖b − Av‖² no longer sees them (their scene content is still inferred from the rest)."""
    if not excluded.any():
        return filters, b
    if excluded.all():
        raise InputError("every pixel is excluded (saturated or dead): nothing left to reconstruct from")
    return np.where(excluded, 0.0, filters), np.where(excluded, 0.0, b)

