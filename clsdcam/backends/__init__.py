"""Backends: the contract of ``base.py`` (Math, Platform, optional Fusions), on NumPy (reference) and OpenCL, chosen
by name.

The bottom layer: modules here import nothing of clsdcam's but ``errors`` and each other. The OpenCL
backend is imported only when asked for, so ``import clsdcam`` and the NumPy backend work on machines
without any OpenCL driver.
"""
from __future__ import annotations

from ..errors import InputError

BACKENDS = ("numpy", "opencl")


def get_backend(name: str = "numpy", dtype="float32", device: str | None = None, fft: str = "auto",
                path: str = "auto"):
    """A backend instance by name: ``numpy`` or ``opencl`` (``device`` picks an OpenCL device by
    substring; ``path`` and ``fft`` its code path and FFT engine, see ``base.py``)."""
    if name == "numpy":
        from .base import check_engine, resolve_path
        from .numpy import NumpyBackend

        check_engine(resolve_path(path, cpu_device=True), fft)
        return NumpyBackend(dtype)
    if name == "opencl":
        from .opencl import OpenCLBackend

        return OpenCLBackend(dtype, device=device, fft=fft, path=path)
    raise InputError(f"--backend {name!r}: expected one of {', '.join(BACKENDS)}")
