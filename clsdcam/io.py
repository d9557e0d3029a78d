"""Files: measurements in (PNG/TIFF 8/16-bit, .npy, .h5), cubes out (HDF5), atomic writes.

Every reader turns a missing, empty, truncated or wrongly shaped file into an ``InputError``
that names the file; every writer goes through :func:`atomic_output`, so a failure or a kill
leaves either the old file or the new one, never a partial one.
"""
from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path

import numpy as np

from .errors import InputError

IMAGE_SUFFIXES = (".png", ".tif", ".tiff")
MAX_DATASET_BYTES = 8 << 30   # refuse to read more than 8 GiB from one dataset (a corrupt or hostile header)
WAVELENGTH = "wavelength"       # the bands' wavelengths (nm) in every file clsdcam writes: the netCDF dimension name
OLD_WAVELENGTH = "wavelengths"  # their name in calibrations, truths and batch parts written before; still read


# ---- atomic writes ----------------------------------------------------------------------
@contextlib.contextmanager
def atomic_output(path):
    """Yield a temporary path next to ``path`` (same suffix); rename it onto ``path`` on success.

    The temporary name is ``.NAME.RANDOM.SUFFIX`` in the same directory, so the rename is
    atomic on POSIX; on any exception (or KeyboardInterrupt) the temporary file is removed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def check_output(path, what: str = "output") -> Path:
    """``path`` as a Path, after checking, before any work, that a file can be written there: not an existing
    directory, in a folder that exists or can be created (:func:`check_folder`); InputError (one line) otherwise.
    Nothing is created: a missing folder is made when the file is written (:func:`atomic_output`)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{what} {path}: is a directory (give a file name)")
    check_folder(path.parent, f"{what} {path}")
    return path


def check_folder(folder, what: str = "output folder") -> Path:
    """``folder`` as a Path, after checking that files can be written into it, creating nothing that lasts: its
    nearest existing ancestor (itself, when it exists) must be a folder in which a probe file can be made (and
    is removed); InputError (one line, naming ``what``) otherwise."""
    folder = Path(folder)
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    if not existing.is_dir():
        raise InputError(f"{what}: cannot write there: {existing} is a file, not a folder")
    try:
        probe = existing / f".clsdcam.{secrets.token_hex(4)}.probe"
        probe.touch()
        probe.unlink()
    except OSError as exc:
        raise InputError(f"{what}: cannot write there: {existing} ({exc.strerror or exc})") from None
    return folder


# ---- reading helpers ----------------------------------------------------------------------
def existing_file(path, what: str) -> Path:
    """``path`` as a Path, or InputError if it is missing, a directory or empty."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{what} {path}: no such file")
    if not path.is_file():
        raise InputError(f"{what} {path}: not a file")
    if path.stat().st_size == 0:
        raise InputError(f"{what} {path}: empty file")
    return path


def require_finite(array: np.ndarray, name: str) -> np.ndarray:
    """``array`` unchanged, or InputError with the count and first position of NaN/Inf values."""
    bad = ~np.isfinite(array)
    if bad.any():
        first = ", ".join(str(int(i)) for i in np.argwhere(bad)[0])
        count = int(bad.sum())
        raise InputError(f"{name}: {count} non-finite value{'s' * (count != 1)} (NaN/Inf), first at ({first})")
    return array


def as_real_array(data, name: str) -> np.ndarray:
    """A float64 copy of numeric (bool/int/float) data, or InputError naming the dtype."""
    array = np.asarray(data)
    if array.dtype.kind not in "biuf":
        raise InputError(f"{name}: expected real numbers, found dtype {array.dtype}")
    with np.errstate(invalid="ignore", over="ignore"):  # out-of-range values become inf, then rejected as non-finite
        return array.astype(np.float64)


def read_h5_dataset(path: Path, key: str, what: str) -> np.ndarray:
    """Dataset ``key`` of an HDF5 file, or InputError (not HDF5, truncated, key missing)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return read_dataset(f, key, f"{what} {path}")
    except InputError:      # a readable file without the dataset: said as it is
        raise
    except (OSError, ValueError, KeyError, TypeError, RuntimeError, MemoryError) as exc:
        raise InputError(f"{what} {path}: not a readable HDF5 file ({first_line(exc)})") from None


def read_dataset(f, key: str, name: str) -> np.ndarray:
    """Dataset ``key`` of an open HDF5 file, after checking that it exists and that its declared
    size is sane; InputError prefixed with ``name`` otherwise."""
    import h5py

    if key not in f or not isinstance(f[key], h5py.Dataset):
        raise InputError(f"{name}: no dataset {key!r} (found: {', '.join(sorted(f.keys())) or 'none'})")
    dataset = f[key]
    nbytes = dataset.size * dataset.dtype.itemsize
    if nbytes > MAX_DATASET_BYTES:
        raise InputError(f"{name}: dataset {dataset.name} declares {nbytes / 2**30:.1f} GiB, more than the "
                         f"{MAX_DATASET_BYTES >> 30} GiB limit (corrupt file?)")
    return dataset[...]


def first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


# ---- measurements -------------------------------------------------------------------------
def load_measurement(path, what: str = "measurement") -> np.ndarray:
    """A raw sensor frame (H, W) float64, as stored (8/16-bit images are not rescaled).

    PNG/TIFF: 8- or 16-bit grey (a colour image is rejected); ``.npy``: a 2-D numeric array;
    ``.h5``/``.hdf5``: dataset ``measurement``. NaN/Inf values are rejected with their count
    and first position. Errors name the file as ``what`` (``dark``, ``psf frame``, …).
    """
    return load_frame(path, what)[0]


def load_frame(path, what: str = "measurement") -> tuple[np.ndarray, float | None]:
    """(frame, code): :func:`load_measurement`'s frame and the saturation code of its stored type
    (:func:`code_max`)."""
    path = existing_file(path, what)
    suffix = path.suffix.lower()
    if suffix in IMAGE_SUFFIXES:
        data = read_image(path, what)
    elif suffix == ".npy":
        data = read_npy(path, what)
    elif suffix in (".h5", ".hdf5"):
        data = read_h5_dataset(path, "measurement", what)
    else:
        raise InputError(f"{what} {path}: unknown format {suffix!r} (expected .png, .tif, .npy or .h5)")
    frame = as_real_array(data, f"{what} {path}")
    if frame.ndim != 2:
        raise InputError(f"{what} {path}: expected a 2-D grey image, found shape {frame.shape}")
    return require_finite(frame, f"{what} {path}"), code_max(np.asarray(data).dtype)


def code_max(dtype) -> float | None:
    """The largest value of an integer type (the saturation code), None for other types."""
    dtype = np.dtype(dtype)
    return float(np.iinfo(dtype).max) if dtype.kind in "iu" else None


def read_image(path: Path, what: str = "measurement") -> np.ndarray:
    """8/16-bit grey PNG or TIFF as an integer array (PIL for PNG, tifffile for TIFF). A file that holds no image
    data (tifffile reads a truncated TIFF as an empty array, and logs why) is an InputError, without the log."""
    try:
        if path.suffix.lower() == ".png":
            from PIL import Image

            with Image.open(path) as image:
                data = np.asarray(image)
        else:
            data = _read_tiff(path)
    except Exception as exc:  # the imaging libraries raise many types for corrupt files
        raise InputError(f"{what} {path}: not a readable image ({first_line(exc)})") from None
    if data.size == 0:
        raise InputError(f"{what} {path}: not a readable image (no image data: truncated or damaged file)")
    return data


def _read_tiff(path: Path) -> np.ndarray:
    """tifffile.imread with tifffile's logger silenced: a damaged file becomes one InputError line, not a log line
    and then an error."""
    import logging

    import tifffile

    log = logging.getLogger("tifffile")
    disabled, log.disabled = log.disabled, True
    try:
        return tifffile.imread(path)
    finally:
        log.disabled = disabled


def read_npy(path: Path, what: str = "measurement") -> np.ndarray:
    """Memory-map first, so a header that declares more data than the file holds fails cheaply."""
    try:
        return np.array(np.load(path, mmap_mode="r", allow_pickle=False))
    except Exception as exc:  # numpy's header parser raises ValueError, SyntaxError, TokenError, EOFError, …
        raise InputError(f"{what} {path}: not a readable .npy array ({first_line(exc)})") from None


def save_measurement(path, frame: np.ndarray) -> Path:
    """Write a frame as ``.npy`` or ``.h5`` (dataset ``measurement``), atomically."""
    path = Path(path)
    with atomic_output(path) as tmp:
        if path.suffix.lower() == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, np.asarray(frame, np.float32))
        else:
            import h5py

            with h5py.File(tmp, "w") as f:
                f["measurement"] = np.asarray(frame, np.float32)
    return path


# ---- cubes --------------------------------------------------------------------------------
def write_cube(path, cube, wavelengths, history=(), attrs=None, full_field=None) -> Path:
    """OUT.h5: ``cube`` (K,H,W) float32 with HDF5 dimension scales ``wavelength`` (K,) in nm, ``y`` and ``x``
    (pixel indices), so netCDF readers (xarray's h5netcdf engine) see dims (wavelength, y, x) with
    coordinates; group ``history`` (one dataset per record key, one entry per
    iteration), attributes ``attrs``; optional ``full_field``."""
    import h5py

    path = Path(path)
    with atomic_output(path) as tmp, h5py.File(tmp, "w") as f:
        write_scaled(f, "cube", np.asarray(cube, np.float32), wavelengths)
        if full_field is not None:
            f["full_field"] = np.asarray(full_field, np.float32)
        group = f.create_group("history")
        for key in (history[0].keys() if history else ()):
            group[key] = np.array([record[key] for record in history])
        for key, value in (attrs or {}).items():
            f.attrs[key] = _attribute(value)
    return path


def write_scaled(f, name: str, data: np.ndarray, wavelengths):
    """Dataset ``name`` (…, K, H, W) with :func:`attach_scales`."""
    return attach_scales(f, f.create_dataset(name, data=data), wavelengths)


def attach_scales(f, cube, wavelengths):
    """``cube`` (…, K, H, W) with dimension scales on its last three axes: ``wavelength`` (nm), ``y``, ``x``
    (pixel indices); leading axes (frames) get a ``frame`` scale (frame indices)."""
    write_wavelengths(f, wavelengths)
    axes = ["frame"] * (cube.ndim - 3) + [WAVELENGTH, "y", "x"]
    for axis, label in enumerate(axes):
        if label not in f:
            f[label] = np.arange(cube.shape[axis], dtype=np.int64)
        f[label].make_scale(label)
        cube.dims[axis].attach_scale(f[label])
    return cube


def _attribute(value):
    """HDF5-storable form of a setting: None → "", tuples → arrays, the rest as is."""
    if value is None:
        return ""
    if isinstance(value, (tuple, list)):
        return np.asarray(value)
    return value


def write_wavelengths(f, wavelengths):
    """Dataset WAVELENGTH (K,) float64, nm, with its units: every file clsdcam writes names its bands' wavelengths
    so (a cube's dimension scale, a calibration's, a truth's, a batch part's)."""
    f[WAVELENGTH] = np.asarray(wavelengths, np.float64)
    f[WAVELENGTH].attrs.update(units="nm", long_name="band centre wavelength")
    return f[WAVELENGTH]


def wavelength_key(f) -> str | None:
    """The name of an open file's wavelength dataset: WAVELENGTH, else OLD_WAVELENGTH (files written before the
    one name), else None."""
    return next((key for key in (WAVELENGTH, OLD_WAVELENGTH) if key in f), None)


def read_wavelengths(f, n_bands: int) -> np.ndarray:
    """A file's band wavelengths (:func:`wavelength_key`), else 0 … K−1."""
    key = wavelength_key(f)
    return f[key][...] if key else np.arange(n_bands, dtype=float)


def read_cube(path) -> dict:
    """{'cube', 'wavelengths', 'history', 'attrs'} from a file written by :func:`write_cube`
    (or any HDF5 file with a 3-D ``cube`` dataset, e.g. the simulator's ``truth.h5``)."""
    import h5py

    path = existing_file(path, "cube")
    cube = read_h5_dataset(path, "cube", "cube")
    if cube.ndim != 3:
        raise InputError(f"cube {path}: expected (K, H, W), found shape {cube.shape}")
    with h5py.File(path, "r") as f:
        wavelengths = read_wavelengths(f, cube.shape[0])
        history = {k: v[...] for k, v in f["history"].items()} if "history" in f else {}
        attrs = dict(f.attrs)
    return {"cube": cube, "wavelengths": wavelengths, "history": history, "attrs": attrs}
