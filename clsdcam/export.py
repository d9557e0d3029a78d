"""Cubes out to other tools: ENVI, multi-page TIFF, NetCDF, a false-colour PNG; batch outputs made self-contained.

The cube is one cube file's ``cube`` (K, H, W), or one frame of a batch output's ``cubes`` (N, K, H, W);
wavelengths are in nm. Each writer goes through :func:`clsdcam.io.atomic_output`:

- ENVI (Spectral Python): ``NAME.hdr`` + ``NAME.img``, band sequential (BSQ), float32 in the machine's byte
  order; the header holds ``wavelength = {…}`` and ``wavelength units = nm``.
- TIFF (tifffile): K pages of (H, W) float32, one per band, in band order; the first page's ImageDescription
  is tifffile's shaped-metadata JSON ``{"shape": [K, H, W], "axes": "CYX", "wavelength": […],
  "wavelength_units": "nm"}`` (``TiffFile.shaped_metadata[0]``).
- NetCDF-4 (xarray, h5netcdf engine): variable ``cube`` (wavelength, y, x) float32, coordinate
  ``wavelength`` (units nm), pixel coordinates ``y``, ``x``; the cube file's attributes as global attributes
  where netCDF can store them (strings, numbers, 1-D numeric arrays; booleans as 0/1).
- PNG: :func:`clsdcam.render.false_colour` as 8-bit sRGB; for K = 1 an 8-bit grey image.
- h5: a batch output's virtual ``cubes`` copied in (chunked one frame per chunk, copied frame by frame),
  its per-frame records and attributes kept: the copy no longer needs ``OUT.h5.parts/``.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import InputError
from .extras import require
from .io import atomic_output, existing_file, first_line, read_cube, read_wavelengths

SUFFIXES = {".hdr": "envi", ".img": "envi", ".tif": "tiff", ".tiff": "tiff", ".nc": "netcdf", ".png": "png",
            ".h5": "h5"}
FORMATS = ("envi", "tiff", "netcdf", "png", "h5")
EXTRA_USES = {"envi": "ENVI export", "netcdf": "NetCDF export"}   # formats whose writer needs the export extra


def format_for(path, fmt: str | None = None) -> str:
    """``fmt`` when given, else the format of ``path``'s suffix (SUFFIXES); InputError when neither gives one."""
    fmt = fmt or SUFFIXES.get(Path(path).suffix.lower())
    if fmt not in FORMATS:
        raise InputError(f"output {path}: no format given and none known for its suffix "
                         f"(use --format {'|'.join(FORMATS)}, or a suffix {', '.join(SUFFIXES)})")
    return fmt


def output_paths(path, fmt: str) -> list[Path]:
    """The files an export writes: ENVI writes ``STEM.hdr`` and ``STEM.img``, the others ``path`` itself."""
    path = Path(path)
    return [path.with_suffix(".hdr"), path.with_suffix(".img")] if fmt == "envi" else [path]


def export(source, output, fmt: str, frame: int = 0) -> list[Path]:
    """Write ``source``'s cube (frame ``frame`` of a batch output) to ``output`` as ``fmt``; the paths written.
    ``h5`` makes a self-contained copy of a batch output. InputError, nothing read or written, when ``fmt``'s
    writer needs an extra that is not installed (:mod:`clsdcam.extras`)."""
    if fmt in EXTRA_USES:
        require(EXTRA_USES[fmt])
    if fmt == "h5":
        return [copy_batch(source, output)]
    data = read_source(source, frame)
    cube = np.asarray(data["cube"], np.float32)
    wavelengths = np.asarray(data["wavelengths"], np.float64)
    try:
        return WRITERS[fmt](output, cube, wavelengths, data["attrs"])
    except InputError as exc:  # the data's own problems (e.g. NaN for a PNG), said with the file's name
        raise InputError(f"{source}: {exc}") from None


# ---- reading ------------------------------------------------------------------------------------------
def read_source(path, frame: int = 0) -> dict:
    """{'cube', 'wavelengths', 'attrs', …}: a cube file's cube (:func:`clsdcam.io.read_cube`), or frame
    ``frame`` of a file holding ``cubes`` but no ``cube`` (a batch output), its attributes plus ``frame``."""
    path = existing_file(path, "cube")
    with _open(path, "cube") as f:
        batch = "cubes" in f and "cube" not in f
    return read_frame(path, frame) if batch else read_cube(path)


def read_frame(path, frame: int) -> dict:
    """Frame ``frame`` of a file of ``cubes`` (a batch output, or a simulated video's truth), after
    :func:`check_virtual_sources`; InputError for a frame out of range or one that failed (a batch output's
    ``error`` record)."""
    path = check_virtual_sources(path)
    with _open(path, "cube file") as f:
        cubes = f["cubes"]
        if cubes.ndim != 4:
            raise InputError(f"cube file {path}: expected cubes (N, K, H, W), found shape {cubes.shape}")
        if not 0 <= frame < len(cubes):
            raise InputError(f"cube file {path}: no frame {frame} (its cubes are frames 0 to {len(cubes) - 1})")
        error = f["error"].asstr()[frame] if "error" in f else ""
        if error:
            raise InputError(f"batch output {path}: frame {frame} failed ({error})")
        return {"cube": cubes[frame], "wavelengths": read_wavelengths(f, cubes.shape[1]),
                "attrs": {**f.attrs, "frame": frame}}


def check_virtual_sources(path) -> Path:
    """``path`` after checking that every source file of its top-level virtual datasets exists and is HDF5.

    HDF5 reads a missing source of a virtual dataset as the fill value (NaN for a batch output's ``cubes``)
    without a word, so this is checked before reading; relative source names are resolved from the file's
    folder, as HDF5 does. InputError naming the folder the frames come from and the missing file otherwise.
    """
    import h5py

    path = existing_file(path, "batch output")
    with _open(path, "batch output") as f:
        names = {source.file_name for item in f.values() if isinstance(item, h5py.Dataset) and item.is_virtual
                 for source in item.virtual_sources()} - {"."}
    for name in sorted(names):
        problem = _source_problem(path.parent / name)
        if problem:
            raise InputError(f"batch output {path}: reads its frames from {Path(name).parent}/ beside it, and "
                             f"{problem} (restore it, or re-run the batch)")
    return path


def _source_problem(source: Path) -> str | None:
    """What is wrong with a virtual source file, or None when it is an HDF5 file."""
    import h5py

    if not source.parent.is_dir():
        return "that folder is missing"
    if not source.is_file():
        return f"its part {source.name} is missing"
    return None if h5py.is_hdf5(source) else f"its part {source.name} is not an HDF5 file"


def _open(path: Path, what: str):
    """An open h5py.File, or InputError naming the file."""
    import h5py

    try:
        return h5py.File(path, "r")
    except (OSError, ValueError) as exc:
        raise InputError(f"{what} {path}: not a readable HDF5 file ({first_line(exc)})") from None


# ---- writers ------------------------------------------------------------------------------------------
def write_envi(path, cube, wavelengths, attrs) -> list[Path]:
    """``STEM.hdr`` + ``STEM.img`` (BSQ float32) with Spectral Python's ``envi.save_image``."""
    from spectral import envi

    header, data = output_paths(path, "envi")
    metadata = {"wavelength": wavelengths.tolist(), "wavelength units": "nm"}
    with atomic_output(data) as tmp_data, atomic_output(header) as tmp_header:
        staged = tmp_data.with_suffix(".hdr")  # spectral names the data file after its header: STEM.hdr → STEM.img
        try:
            envi.save_image(str(staged), np.moveaxis(cube, 0, -1), ext=".img", interleave="bsq", dtype=np.float32,
                            metadata=metadata, force=True)
            os.replace(staged, tmp_header)
        finally:
            staged.unlink(missing_ok=True)
    return [header, data]


def write_tiff(path, cube, wavelengths, attrs) -> list[Path]:
    """One float32 page per band with tifffile; the wavelengths in the shaped-metadata JSON."""
    import tifffile

    with atomic_output(path) as tmp:
        tifffile.imwrite(tmp, cube, photometric="minisblack",
                         metadata={"axes": "CYX", "wavelength": wavelengths.tolist(), "wavelength_units": "nm"})
    return [Path(path)]


def write_netcdf(path, cube, wavelengths, attrs) -> list[Path]:
    """NetCDF-4 through xarray's h5netcdf engine: ``cube`` (wavelength, y, x) with its coordinates."""
    import xarray

    _, h, w = cube.shape
    dataset = xarray.Dataset(
        {"cube": (("wavelength", "y", "x"), cube)},
        coords={"wavelength": ("wavelength", wavelengths, {"units": "nm", "long_name": "band centre wavelength"}),
                "y": np.arange(h), "x": np.arange(w)},
        attrs=netcdf_attributes(attrs))
    with atomic_output(path) as tmp:
        dataset.to_netcdf(tmp, engine="h5netcdf")
    return [Path(path)]


def netcdf_attributes(attrs: dict) -> dict:
    """The attributes netCDF can store (names not starting with "_", which netCDF reserves), in netCDF form."""
    converted = {key: _netcdf_attribute(value) for key, value in attrs.items() if not key.startswith("_")}
    return {key: value for key, value in converted.items() if value is not None}


def _netcdf_attribute(value):
    """``value`` as a netCDF attribute (booleans as 0/1 int8), or None when netCDF has no form for it."""
    value = np.asarray(value)
    if value.dtype.kind == "b":
        value = value.astype(np.int8)
    if value.dtype.kind in "US" and value.ndim == 0:
        return value.item()
    if value.dtype.kind in "iuf" and value.ndim <= 1:
        return value if value.ndim else value[()]
    return None


def write_png(path, cube, wavelengths, attrs) -> list[Path]:
    """The false-colour image as 8-bit sRGB (8-bit grey for one band) with Pillow."""
    from PIL import Image

    from .render import false_colour

    image = false_colour(cube, wavelengths)
    image = image[..., 0] if cube.shape[0] == 1 else image
    with atomic_output(path) as tmp:
        Image.fromarray(np.round(image * 255).astype(np.uint8)).save(tmp, format="PNG")
    return [Path(path)]


WRITERS = {"envi": write_envi, "tiff": write_tiff, "netcdf": write_netcdf, "png": write_png}


# ---- self-contained batch outputs ---------------------------------------------------------------------
SCALE_ATTRIBUTES = ("CLASS", "NAME", "DIMENSION_LIST", "REFERENCE_LIST", "DIMENSION_LABELS")  # HDF5 DS bookkeeping


def copy_batch(source, output) -> Path:
    """``output``: ``source``'s ``cubes`` copied in frame by frame (chunks of one frame, NaN fill), its other
    top-level datasets and all attributes copied, the dimension scales attached as in ``source``."""
    import h5py

    source = check_virtual_sources(source)
    with _open(source, "batch output") as f:
        if "cubes" not in f or f["cubes"].ndim != 4:
            raise InputError(f"{source}: no 4-D 'cubes', so not a batch output (--format h5 copies one; "
                             "a cube file exports as envi, tiff, netcdf or png)")
        with atomic_output(output) as tmp, h5py.File(tmp, "w") as out:
            cubes = f["cubes"]
            copy = out.create_dataset("cubes", cubes.shape, np.float32, chunks=(1,) + cubes.shape[1:],
                                      fillvalue=np.nan)
            for i in range(len(cubes)):
                copy[i] = cubes[i]
            for key in f:
                if key != "cubes":
                    f.copy(f[key], out, name=key, without_attrs=True)  # references would point into ``source``
            _copy_attributes(f, out)
            _attach_scales_as_in(f, out)
    return Path(output)


def _copy_attributes(f, out):
    """The file's and each top-level dataset's attributes, but the dimension-scale bookkeeping (references)."""
    for key, item in [("/", f), *f.items()]:
        out[key].attrs.update({k: v for k, v in item.attrs.items() if k not in SCALE_ATTRIBUTES})


def _attach_scales_as_in(f, out):
    """Make the same datasets dimension scales (same names) and attach them to the same axes (same labels)."""
    import h5py

    for key, item in f.items():
        if h5py.h5ds.is_scale(item.id):
            out[key].make_scale(h5py.h5ds.get_scale_name(item.id).decode())
    for key, item in f.items():
        for axis, dim in enumerate(item.dims):
            for scale in dim.values():
                out[key].dims[axis].attach_scale(out[scale.name])
            if dim.label:
                out[key].dims[axis].label = dim.label
