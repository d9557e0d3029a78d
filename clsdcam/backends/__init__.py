"""Backends: the same primitives on NumPy (reference) and OpenCL, chosen by name.

The OpenCL backend is imported only when asked for, so ``import clsdcam`` and the NumPy
backend work on machines without any OpenCL driver.
"""
from __future__ import annotations

from ..errors import InputError

BACKENDS = ("numpy", "opencl")


def get_backend(name: str = "numpy", dtype="float32", device: str | None = None, fft: str = "auto"):
    """A backend instance by name: ``numpy`` or ``opencl`` (``device`` picks an OpenCL device by
    substring, ``fft`` its FFT engine: auto, host, reikna or vkfft)."""
    if name == "numpy":
        from .numpy import NumpyBackend

        return NumpyBackend(dtype)
    if name == "opencl":
        from .opencl import OpenCLBackend

        return OpenCLBackend(dtype, device=device, fft=fft)
    raise InputError(f"--backend {name!r}: expected one of {', '.join(BACKENDS)}")
