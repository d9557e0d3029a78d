"""The shared data folder: the real cubes, measured PSFs and lamp spectra that the ``realcube`` scene, ``analyze
resolution`` and the simulated sweep read (``../shared/data`` beside a clone).

The folder is the first of:

1. ``--data DIR`` of the running command (:func:`data_folder`);
2. ``$CLSDCAM_DATA``;
3. the first ``shared/data`` folder found in the working directory or one of its parents (run from a clone that
   sits beside ``shared/``, this is ``../shared/data``);
4. ``shared/data`` beside the clone the package's source lies in (an editable install run from elsewhere).

1 and 2 are taken as given, present or not (a file missing there is reported as missing there); 3 and 4 only
where they exist. Only the standard library is imported here: the command line uses this module.
"""
from __future__ import annotations

import contextlib
import os
from contextvars import ContextVar
from pathlib import Path

ENV = "CLSDCAM_DATA"
NOT_FOUND = "none found"
_CHOSEN: ContextVar[Path | None] = ContextVar("clsdcam_data", default=None)


def shared_data_dir() -> Path:
    """The shared data folder (the module docstring's order); where none is found, ``../shared/data`` from the
    working directory, absent, so that every file in it reads as not present."""
    return locate()[0]


def locate() -> tuple[Path, str]:
    """(the shared data folder, how it was chosen: ``--data``, ``$CLSDCAM_DATA``, ``found`` or NOT_FOUND)."""
    chosen = _CHOSEN.get()
    if chosen is not None:
        return chosen, "--data"
    if os.environ.get(ENV):
        return Path(os.environ[ENV]), f"${ENV}"
    for folder in searched_folders():
        if folder.is_dir():
            return folder, "found"
    return Path.cwd().parent / "shared" / "data", NOT_FOUND


def searched_folders() -> list[Path]:
    """``shared/data`` in the working directory and each of its parents, then beside the package's clone."""
    here = Path.cwd()
    return [folder / "shared" / "data" for folder in (here, *here.parents)] + \
        [Path(__file__).resolve().parents[2] / "shared" / "data"]


def missing_text(relative: str) -> str:
    """One line: ``relative`` is not in the shared data folder, where that folder is and how to name another."""
    folder, how = locate()
    if how == NOT_FOUND:
        return (f"{relative} not present: no shared data folder (no shared/data in {Path.cwd()} or a folder above "
                f"it, nor beside the package); give --data DIR or set ${ENV}")
    where = "" if how == "found" else f" (from {how})"
    return f"{relative} not present in {folder}{where}; name another folder with --data DIR or ${ENV}"


@contextlib.contextmanager
def data_folder(path):
    """``--data DIR`` while the block runs: the shared data folder is ``path`` (None: the search)."""
    token = _CHOSEN.set(None if path is None else Path(path))
    try:
        yield
    finally:
        _CHOSEN.reset(token)
