"""Backends: the contract of ``base.py`` (Math, Platform, optional Fusions), on NumPy (reference) and OpenCL, chosen
by name, or by ``auto`` (OpenCL on a GPU when one is found, else NumPy).

The bottom layer: modules here import nothing of clsdcam's but ``errors`` and each other, and code above reaches
them only through this module and ``base`` (:data:`EXPORTS`, each loaded on first use). The OpenCL
backend is imported only when asked for (``auto`` imports pyopencl only to look for a GPU), so ``import clsdcam``
and the NumPy backend work on machines without any OpenCL driver.
"""
from __future__ import annotations

from ..errors import InputError

BACKENDS = ("auto", "numpy", "opencl")

EXPORTS = {   # name -> the module of this package that defines it, imported when the name is first used
    **dict.fromkeys(("NumpyBackend",), "numpy"),
    **dict.fromkeys(("OpenCLBackend",), "opencl"),
    **dict.fromkeys(("map_blocks", "scratch_buffer", "THREADS_VARIABLE", "available_cores", "host_threads",
                     "single_threaded_blas"), "blocks"),
    **dict.fromkeys(("seen_bands",), "host_convolution"),
    **dict.fromkeys(("irfft2", "irfft2_to_window", "rfft2_of_window"), "host_fft"),
    **dict.fromkeys(("CASES", "Inputs", "benchmarks"), "cases"),
    **dict.fromkeys(("available_engines",), "fft"),
    **dict.fromkeys(("all_devices", "import_pyopencl", "choose_device", "describe", "format_devices", "has_fp64",
                     "is_cpu", "memory_limits", "MOST_BANDS", "bands_that_fit", "problem_bytes", "shortfall"),
                    "cl_devices"),
}


def __getattr__(name):
    if name in EXPORTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def resolve_backend(name: str, device: str | None = None) -> tuple[str, str]:
    """(backend, why) for ``name``: ``auto`` is ``opencl`` when ``device`` names an OpenCL device or an OpenCL GPU is
    found (:func:`~clsdcam.backends.cl_devices.find_gpu`; pyopencl is imported only to look), else ``numpy``; ``why``
    says which ("" for a backend named outright). A CPU's OpenCL device (PoCL) is not chosen: it runs the same host
    FFT code as NumPy and was no faster at the default settings (docs/benchmarks.md)."""
    if name != "auto":
        return name, ""
    if device:
        return "opencl", "--device given"
    from .cl_devices import find_gpu

    return ("opencl", "a GPU was found") if find_gpu() is not None else ("numpy", "no OpenCL GPU")


def get_backend(name: str = "numpy", dtype="float32", device: str | None = None, fft: str = "auto",
                path: str = "auto"):
    """A backend instance by name: ``numpy`` (the default: the reference, the same result on every machine),
    ``opencl`` (``device`` picks an OpenCL device by substring; ``path`` and ``fft`` its code path and FFT engine,
    see ``base.py``) or ``auto`` (:func:`resolve_backend`: OpenCL on a GPU when there is one, the command line's
    default)."""
    name = resolve_backend(name, device)[0]
    if name == "numpy":
        from .base import check_engine, resolve_path
        from .numpy import NumpyBackend

        check_engine(resolve_path(path, cpu_device=True), fft)
        return NumpyBackend(dtype)
    if name == "opencl":
        from .opencl import OpenCLBackend

        return OpenCLBackend(dtype, device=device, fft=fft, path=path)
    raise InputError(f"--backend {name!r}: expected one of {', '.join(BACKENDS)}")
