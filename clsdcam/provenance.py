"""Where an output came from: the inputs' paths and SHA-256, the preprocessing, the command line, the time and
the version, as HDF5 attributes (``reconstruct`` and ``batch`` write the same ones)."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
from datetime import datetime, timezone
from pathlib import Path

from . import __version__

CHUNK = 1 << 20


def sha256(path) -> str:
    """The SHA-256 of a file's bytes (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(CHUNK), b""):
            digest.update(block)
    return digest.hexdigest()


def provenance(inputs: dict, preprocessing=None, argv=None) -> dict:
    """HDF5-storable attributes: ``<name>_path`` and ``<name>_sha256`` for each input file (name -> path; a
    list of paths is hashed in order into one digest), the preprocessing as JSON, the command line, an ISO
    timestamp (UTC) and clsdcam's version."""
    attrs = {}
    for name, paths in inputs.items():
        paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
        attrs[f"{name}_path"] = str(paths[0]) if len(paths) == 1 else json.dumps([str(p) for p in paths])
        attrs[f"{name}_sha256"] = sha256(paths[0]) if len(paths) == 1 else \
            hashlib.sha256("".join(sha256(p) for p in paths).encode()).hexdigest()
    if preprocessing is not None:
        attrs["preprocessing"] = json.dumps(dataclasses.asdict(preprocessing), default=str)
    attrs["command_line"] = " ".join(sys.argv if argv is None else argv)
    attrs["created"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    attrs["clsdcam_version"] = __version__
    return attrs
