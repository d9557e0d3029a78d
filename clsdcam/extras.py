"""The optional extras: which use needs which, and the check each use makes before it reads or writes anything.

The core install (``pip install clsdcam``, pyproject's ``dependencies``) reconstructs a frame, draws its pictures
and reads and writes HDF5. The rest comes in extras (pyproject's ``optional-dependencies``):

- ``video``: ``clsdcam batch`` (Dask distributed runs the chunks, scikit-image's phase correlation reads the drift
  between frames), a batch output's frames read lazily (dask.array), the simulator's natural scenes
  (scikit-image's photographs);
- ``export``: ``clsdcam export`` to NetCDF (xarray, h5netcdf) and ENVI (Spectral Python).

:func:`require` looks the modules up without importing them (``importlib.util.find_spec``): the check costs
nothing where they are installed, and where one is missing it is an :class:`~clsdcam.errors.InputError` (one line,
exit 2 on the command line) naming the extra's install command.
"""
from __future__ import annotations

import importlib.util

from .errors import InputError

# a use -> (the extra that holds what it needs, the top-level modules it imports)
NEEDS = {
    "batch": ("video", ("dask", "distributed", "skimage")),
    "reading a batch output's frames lazily": ("video", ("dask",)),
    "the natural scene kind": ("video", ("skimage",)),
    "NetCDF export": ("export", ("xarray", "h5netcdf")),
    "ENVI export": ("export", ("spectral",)),
}


def missing(modules) -> list[str]:
    """Those of ``modules`` (top-level names) that cannot be imported here."""
    return [name for name in modules if importlib.util.find_spec(name) is None]


def require(use: str) -> None:
    """Return when every module ``use`` (a key of NEEDS) needs is installed; else InputError naming its extra."""
    extra, modules = NEEDS[use]
    absent = missing(modules)
    if absent:
        raise InputError(f"{use} needs the {extra} extra: pip install 'clsdcam[{extra}]' "
                         f"(not installed: {', '.join(absent)})")
