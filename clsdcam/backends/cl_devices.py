"""OpenCL devices: listing, choosing by name, one context and queue per device (a bounded cache).

Every failure a user can meet here (no pyopencl, no driver, no matching device, a device whose compiler cannot
build here, no fp64, too little memory) is an :class:`~clsdcam.errors.InputError` with one line saying what
to do, so the CLI prints it and exits with code 2.

A device is chosen only if it builds a one-line probe kernel (:func:`build_failure`). The PoCL bundled with
pyopencl's wheels (3.0, LLVM 14) lists the CPU of an AMD Zen 5 machine but cannot compile for it: LLVM 14 does
not know CPU family 26, calls it "generic", and rejects that name ("unknown target CPU 'generic'").
"""
from __future__ import annotations

import os
from functools import lru_cache

import numpy as np

from ..errors import InputError

INSTALL_HINT = ("install an OpenCL driver, e.g. the portable CPU driver PoCL: "
                "pip install 'clsdcam[pocl]' (PyPI pocl-binary-distribution)")

CONTEXT_CACHE = 8      # (context, queue) pairs kept, one per device in use


def import_pyopencl():
    """The pyopencl module, or InputError saying how to get an OpenCL stack."""
    try:
        import pyopencl
    except ImportError as exc:
        raise InputError(f"the OpenCL backend needs pyopencl and a driver ({exc}); {INSTALL_HINT}") from exc
    return pyopencl


def all_devices() -> list:
    """Every (platform, device) pair, or InputError when there is no OpenCL platform."""
    cl = import_pyopencl()
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:
        raise InputError(f"no OpenCL platform found ({exc}); {INSTALL_HINT}") from exc
    devices = [(p, d) for p in platforms for d in _platform_devices(cl, p)]
    if not devices:
        raise InputError(f"no OpenCL device found; {INSTALL_HINT}")
    return devices


def _platform_devices(cl, platform) -> list:
    try:
        return platform.get_devices()
    except cl.Error:  # a platform with no devices raises DEVICE_NOT_FOUND
        return []


def is_cpu(device) -> bool:
    """A CPU device: its memory is the host's (the host path runs on it). Oclgrind, a simulator, says it is every
    type: a device that says GPU is taken as a GPU (device path, GPU launch shapes, memory of its own)."""
    cl = import_pyopencl()
    return bool(device.type & cl.device_type.CPU) and not device.type & cl.device_type.GPU


def is_gpu(device) -> bool:
    """A GPU that is not also a CPU (Oclgrind says both: it is chosen only by name, or when nothing else is there)."""
    cl = import_pyopencl()
    return bool(device.type & cl.device_type.GPU) and not device.type & cl.device_type.CPU


def has_fp64(device) -> bool:
    return "cl_khr_fp64" in device.extensions or "cl_amd_fp64" in device.extensions


def describe(device) -> str:
    """'device name (platform name)', as recorded in output files."""
    return f"{device.name.strip()} ({device.platform.name.strip()})"


def list_devices() -> list[dict]:
    """One dict per device: platform, device, type, global/max-alloc memory (MiB), compute units, fp64."""
    cl = import_pyopencl()
    return [{
        "platform": p.name.strip(),
        "device": d.name.strip(),
        "type": cl.device_type.to_string(d.type),
        "global_mem_mib": d.global_mem_size >> 20,
        "max_alloc_mib": d.max_mem_alloc_size >> 20,
        "compute_units": d.max_compute_units,
        "fp64": has_fp64(d),
    } for p, d in all_devices()]


def format_devices() -> str:
    """A plain-text table of :func:`list_devices` (for ``clsdcam devices``)."""
    rows = list_devices()
    header = ("#", "platform", "device", "type", "memory MiB", "max alloc MiB", "CUs", "fp64")
    table = [header] + [(str(i), r["platform"], r["device"], r["type"], str(r["global_mem_mib"]),
                         str(r["max_alloc_mib"]), str(r["compute_units"]), "yes" if r["fp64"] else "no")
                        for i, r in enumerate(rows)]
    widths = [max(len(row[c]) for row in table) for c in range(len(header))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in table)


def choose_device(substring: str | None = None):
    """The device to use.

    With ``substring``: the first device whose platform or device name contains it
    (case-insensitive), else InputError listing the devices. Without: the PYOPENCL_CTX
    choice when that variable is set, else the first GPU, else the first CPU, else the first device
    (:func:`is_gpu`, :func:`is_cpu`), of those that build the probe kernel. A named device that cannot build,
    or no device that can, is an InputError giving the compiler's reason.
    """
    devices = all_devices()
    if substring:
        needle = substring.lower()
        for platform, device in devices:
            if needle in platform.name.lower() or needle in device.name.lower():
                return buildable(device)
        names = "; ".join(describe(d) for _, d in devices)
        raise InputError(f"--device {substring!r}: no OpenCL device matches; available: {names}")
    if os.environ.get("PYOPENCL_CTX"):
        return _pyopencl_ctx_device()
    preferred = sorted((device for _, device in devices), key=lambda d: 0 if is_gpu(d) else 1 if is_cpu(d) else 2)
    return next((device for device in preferred if not build_failure(device)), None) or buildable(preferred[0])


PROBE_KERNEL = "__kernel void probe(__global float *a) { a[get_global_id(0)] = 1.0f; }"


@lru_cache(maxsize=None)
def build_failure(device) -> str:
    """Why ``device``'s compiler cannot build the probe kernel (its first error line), or "" when it can; once
    per device and process."""
    cl = import_pyopencl()
    try:
        cl.Program(cl.Context([device]), PROBE_KERNEL).build()
    except cl.Error as exc:
        lines = [line.strip() for line in str(exc).splitlines() if line.strip().startswith("error")]
        return (lines or [str(exc).splitlines()[0]])[0]
    return ""


def buildable(device):
    """``device``, or InputError when its compiler cannot build here."""
    reason = build_failure(device)
    if reason:
        raise InputError(f"OpenCL device {describe(device)} cannot compile kernels on this machine ({reason}); "
                         f"use --backend numpy, or another OpenCL driver (clsdcam devices lists them)")
    return device


def find_gpu():
    """The first OpenCL GPU (:func:`is_gpu`), or None when there is none, no driver or no pyopencl: never an error
    (what ``--backend auto`` asks before it chooses)."""
    try:
        devices = all_devices()
    except InputError:          # no pyopencl (its import failed), no platform, no device
        return None
    return next((device for _, device in devices if is_gpu(device)), None)


def _pyopencl_ctx_device():
    cl = import_pyopencl()
    try:
        device = cl.create_some_context(interactive=False).devices[0]
    except Exception as exc:  # noqa: BLE001 - pyopencl raises several types for a bad PYOPENCL_CTX
        raise InputError(f"PYOPENCL_CTX={os.environ['PYOPENCL_CTX']!r}: {exc}") from exc
    return buildable(device)


@lru_cache(maxsize=CONTEXT_CACHE)
def context_queue(device):
    """The (context, in-order queue) of ``device``, created on first use and cached."""
    cl = import_pyopencl()
    context = cl.Context(devices=[device])
    return context, cl.CommandQueue(context)


def require_dtype(device, dtype) -> None:
    """InputError when float64 is asked of a device without cl_khr_fp64."""
    if np.dtype(dtype) == np.float64 and not has_fp64(device):
        raise InputError(f"--dtype float64: device {describe(device)} has no double precision "
                         "(cl_khr_fp64); use --dtype float32 or another --device")


# ---- memory --------------------------------------------------------------------------------

FIELD_BUFFERS = 6      # FISTA x, x_prev, y, z; the model's field; the prox scratch (an algorithm may say more)
MOST_BANDS = 1024      # bands_that_fit looks no further


def problem_bytes(sensor_shape, field_shape, n_bands: int, dtype="float32",
                  field_buffers: int | None = None) -> tuple[int, int]:
    """(total, largest single buffer) in bytes for one solve.

    Field cubes K·Hp·Wp (``field_buffers`` of them: the algorithm's, FIELD_BUFFERS for FISTA), the half spectrum
    K·Hp·(Wp/2+1) complex,
    filters K·H·W, and the FFT work: up to two full complex field cubes (the packed
    complex transform and its scratch).
    """
    item = np.dtype(dtype).itemsize
    (h, w), (hp, wp) = sensor_shape, field_shape
    field = n_bands * hp * wp * item
    spectrum = n_bands * hp * (wp // 2 + 1) * 2 * item
    fft_work = 2 * ((n_bands + 1) // 2) * hp * wp * 2 * item
    total = (field_buffers or FIELD_BUFFERS) * field + spectrum + n_bands * h * w * item + fft_work + 8 * h * w * item
    return total, max(field, spectrum, fft_work // 2)


def memory_limits(device) -> tuple[int, int]:
    """(global memory, largest single buffer) of ``device`` in bytes, as the driver reports them."""
    return device.global_mem_size, device.max_mem_alloc_size


ADVICE = "use fewer bands, a smaller crop, --support-field, or another --device (clsdcam devices lists them)"


def shortfall(device, needed: int, largest: int = 0) -> str | None:
    """What does not fit on ``device``: None when ``needed`` bytes fit its global memory and ``largest`` its
    largest buffer, else a phrase saying which and by how much (MiB)."""
    mib = 1 << 20
    memory, max_alloc = memory_limits(device)
    if needed > memory:
        return f"needs about {needed / mib:.0f} MiB of device memory but {describe(device)} has {memory / mib:.0f} MiB"
    if largest > max_alloc:
        return (f"needs a {largest / mib:.0f} MiB buffer but {describe(device)} allows at most "
                f"{max_alloc / mib:.0f} MiB per buffer")
    return None


def check_memory(device, needed: int, largest: int = 0) -> None:
    """InputError when ``needed`` bytes exceed the device's global memory, or ``largest`` its max allocation."""
    short = shortfall(device, needed, largest)
    if short:
        raise InputError(f"the problem {short}; {ADVICE}")


def bands_that_fit(device, sensor_shape, field_shape, dtype="float32", most: int = MOST_BANDS,
                   field_buffers: int | None = None) -> int:
    """The most bands K ≤ ``most`` whose solve fits ``device`` (0 when not even one does): problem_bytes grows with
    K, so the answer is found by bisection on K."""
    low, high = 0, most              # K = low fits (or is 0), K = high + 1 does not (or is past most)
    while low < high:
        k = (low + high + 1) // 2
        if shortfall(device, *problem_bytes(sensor_shape, field_shape, k, dtype, field_buffers)):
            high = k - 1
        else:
            low = k
    return low


def check_problem(device, sensor_shape, field_shape, n_bands: int, dtype="float32",
                  field_buffers: int | None = None) -> None:
    """InputError, one line, when one solve of ``n_bands`` on ``field_shape`` by an algorithm keeping
    ``field_buffers`` field cubes (FISTA's by default) does not fit ``device``: what it needs, what the device has,
    and how many bands of that field would fit."""
    short = shortfall(device, *problem_bytes(sensor_shape, field_shape, n_bands, dtype, field_buffers))
    if short:
        fit = bands_that_fit(device, sensor_shape, field_shape, dtype, n_bands, field_buffers)
        field = "×".join(map(str, field_shape))
        raise InputError(f"{n_bands} bands on a {field} field {short}; at most {fit} bands of that field fit: "
                         f"{ADVICE}")
