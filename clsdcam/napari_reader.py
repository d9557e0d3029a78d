"""The napari reader (npe2 manifest ``clsdcam/napari.yaml``): ``napari cube.h5`` opens a clsdcam cube.

A file is taken when it is HDF5 with a ``cube`` (K, H, W) or ``cubes`` (N, K, H, W) dataset: what
``reconstruct``, ``demo`` and ``Result.save`` write, ``batch`` outputs and the simulator's truth files (a
single frame's and a video's). Any other file is left to other readers (``napari_get_reader`` returns None).

Each file becomes one image layer:

- data: the cube in memory; N frames stay on disk as a dask array read one band image at a time (a batch of
  many frames is not loaded whole; napari's sliders over frame and band read what they show);
- ``axis_labels``: ("λ", "y", "x"), with "frame" in front for N frames;
- ``metadata``: ``wavelengths`` (K,) in nm (index k of the λ slider is ``wavelengths[k]``), ``wavelength_unit``,
  ``path`` and ``attrs`` (the file's attributes: every setting, the chosen weights, the provenance);
- name: the file's stem; colormap ``magma``; contrast limits [0, p], p the 99.9th percentile of the first
  frame's finite values (cubes are ≥ 0; 1 when that frame holds no positive value).

napari itself is not needed to call these functions: they return napari's LayerData tuples
``(data, kwargs, "image")``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .extras import require

CUBE_KEYS = ("cube", "cubes")     # (K, H, W) and (N, K, H, W)
COLORMAP = "magma"
PERCENTILE = 99.9


def napari_get_reader(path):
    """npe2's reader command: ``read_cubes`` when every path is a clsdcam cube file, else None."""
    paths = as_paths(path)
    if paths and all(cube_key(p) for p in paths):
        return read_cubes
    return None


def as_paths(path) -> list:
    """npe2 passes one path or a list of them (several files opened at once)."""
    return [path] if isinstance(path, (str, Path)) else list(path)


def cube_key(path) -> str | None:
    """The cube dataset's name in ``path`` ("cube" with 3 axes or "cubes" with 4), or None when ``path`` is not
    a readable HDF5 file holding one."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return next((key for key, ndim in zip(CUBE_KEYS, (3, 4))
                         if isinstance(f.get(key), h5py.Dataset) and f[key].ndim == ndim), None)
    except (OSError, ValueError):
        return None


def read_cubes(path) -> list[tuple]:
    """One image layer (data, kwargs, "image") per path."""
    return [cube_layer(Path(p)) for p in as_paths(path)]


def cube_layer(path: Path) -> tuple:
    """The image layer of one cube file (see the module's docstring). napari brings dask; called without napari,
    N frames need the video extra (InputError before the file is opened)."""
    import h5py

    from .io import read_dataset, read_wavelengths

    key = cube_key(path)
    if key == "cubes":
        require("reading a batch output's frames lazily")
    f = h5py.File(path, "r")
    wavelengths, attrs = read_wavelengths(f, f[key].shape[-3]), dict(f.attrs)
    if key == "cubes":
        data = frames_lazily(f[key])     # f stays open: the dask array reads from it
    else:
        with f:
            data = read_dataset(f, key, f"cube {path}")
    first = np.asarray(data if data.ndim == 3 else data[0])
    kwargs = {"name": path.stem, "axis_labels": ("frame", "λ", "y", "x")[-data.ndim:], "colormap": COLORMAP,
              "contrast_limits": contrast_limits(first),
              "metadata": {"wavelengths": np.asarray(wavelengths, np.float64), "wavelength_unit": "nm",
                           "path": str(path), "attrs": attrs}}
    return data, kwargs, "image"


def frames_lazily(dataset):
    """(N, K, H, W) ``dataset`` as a dask array in chunks of one band image (1, 1, H, W)."""
    import dask.array as da

    return da.from_array(dataset, chunks=(1, 1) + dataset.shape[2:])


def contrast_limits(cube: np.ndarray) -> tuple[float, float]:
    """[0, the 99.9th percentile of the finite values], or [0, 1] when it is not positive (an empty or failed frame)."""
    finite = cube[np.isfinite(cube)]
    top = float(np.percentile(finite, PERCENTILE)) if finite.size else 0.0
    return 0.0, top if top > 0 else 1.0
