"""The OpenCL C sources of ``kernels/``: loaded once, built once per (context, dtype), launched simply.

Every kernel is templated on the real type by ``-DREAL=float|double`` (``REAL2`` its complex
pair); reductions accumulate in ``ACC`` = double when the device has fp64, else float with
Kahan compensation. One program holds every family; it is built on first use and kept in a
bounded cache keyed by (context, dtype, accumulator), so PoCL's slow compiles happen once.
"""
from __future__ import annotations

import importlib.resources
from functools import lru_cache
from pathlib import Path

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from .cl_devices import has_fp64, is_cpu

# Build order: common types first, then each family (reduce.cl before bandmix.cl, admm.cl and margin.cl, which use its
# helpers).
FAMILIES = ("common", "mask", "padcrop", "fft", "prox", "fista", "tv", "reduce", "bandmix", "admm", "margin")
TYPES = {np.dtype(np.float32): ("float", "float2"), np.dtype(np.float64): ("double", "double2")}
LOCAL_X = 64          # work-group width along the fastest axis of 2-D/3-D launches (GPUs)
LOCAL_X_CPU = 256     # CPUs (PoCL): one row of 256 work items, which PoCL vectorises best (haar_tv: 90 ms
                      # against 114 ms for 64×16 groups at 64×576×800)
LOCAL_1D = 256        # work-group size of 1-D launches and reductions on GPUs (a power of two)
LOCAL_CPU = 1024      # CPUs (PoCL): large groups amortise the per-group scheduling cost

PROGRAM_CACHE = 8     # built programs kept: (context, dtype, accumulator) combinations in use


def kernel_dir() -> Path:
    """The kernels of the package that is running: ``clsdcam/kernels`` of an installed wheel, else ``kernels/`` of the
    checkout it was imported from, else the installed ``clsdcam.kernels`` mapping. The checkout comes before the
    mapping: an editable install maps ``clsdcam.kernels`` to its own tree, so another checkout put on ``PYTHONPATH``
    (an A/B of two commits) would otherwise run its Python with the installed tree's kernels."""
    package = Path(__file__).resolve().parents[1]
    for candidate in (package / "kernels", package.parent / "kernels"):
        if (candidate / "common.cl").is_file():
            return candidate
    return Path(str(importlib.resources.files("clsdcam.kernels")))


@lru_cache(maxsize=1)
def source() -> str:
    """All kernel families concatenated in build order (read once)."""
    root = kernel_dir()
    return "\n".join(f"/* ---- {name}.cl ---- */\n" + (root / f"{name}.cl").read_text(encoding="utf-8")
                     for name in FAMILIES)


def accumulator(device, kahan: bool | None = None) -> np.dtype:
    """float64 when the device has fp64 (unless ``kahan`` forces compensated float32)."""
    use_double = has_fp64(device) if kahan is None else not kahan
    return np.dtype(np.float64 if use_double else np.float32)


def program(context, dtype, acc) -> cl.Program:
    """The built program for (context, dtype, accumulator), cached."""
    return _built(context, np.dtype(dtype), np.dtype(acc))


@lru_cache(maxsize=PROGRAM_CACHE)
def _built(context, dtype: np.dtype, acc: np.dtype) -> cl.Program:
    real, real2 = TYPES[dtype]
    options = [f"-DREAL={real}", f"-DREAL2={real2}", f"-DACC={TYPES[acc][0]}"]
    if any(has_fp64(d) for d in context.devices) and (acc == np.float64 or real == "double"):
        options.append("-DHAVE_FP64")
    if acc == np.float32:
        options.append("-DKAHAN")
    return cl.Program(context, source()).build(options=options)


def round_up(n: int, multiple: int) -> int:
    return -(-n // multiple) * multiple


class Kernels:
    """The kernels of one program on one queue, with the three launch shapes the families use.

    Scalars are passed as typed NumPy scalars by the callers (np.int32 for sizes, np.int64 for
    element counts, the real dtype for real scalars); arrays as pyopencl arrays (offset 0).
    """

    def __init__(self, queue, dtype, kahan: bool | None = None):
        self.queue = queue
        self.device = queue.device
        self.dtype = np.dtype(dtype)
        self.acc = accumulator(self.device, kahan)
        self.program = program(queue.context, self.dtype, self.acc)
        self._kernels: dict[str, cl.Kernel] = {}
        self._group_limits: dict[str, int] = {}   # kernel name -> its own CL_KERNEL_WORK_GROUP_SIZE
        self._partials: dict[tuple, tuple] = {}  # (groups, outputs) -> (host array, device buffer)
        self.cpu = is_cpu(self.device)
        self.max_group = min(LOCAL_CPU if self.cpu else LOCAL_1D, self.device.max_work_group_size)
        self.local_1d = 1 << (self.max_group.bit_length() - 1)      # a power of two

    def kernel(self, name: str) -> cl.Kernel:
        if name not in self._kernels:
            self._kernels[name] = cl.Kernel(self.program, name)
        return self._kernels[name]

    def group_limit(self, name: str) -> int:
        """The most work items a group of kernel ``name`` may hold: ``max_group`` and the kernel's own limit on this
        device (registers or local memory can make it lower), the latter asked once."""
        if name not in self._group_limits:
            self._group_limits[name] = self.kernel(name).get_work_group_info(
                cl.kernel_work_group_info.WORK_GROUP_SIZE, self.device)
        return min(self.max_group, self._group_limits[name])

    def launch(self, name: str, global_size, local_size, *args):
        return self.kernel(name)(self.queue, global_size, local_size, *_args(args))

    def grid3(self, name: str, shape, *args):
        """Launch over (B, H, W): work item (x, y, b); x and y rounded up to the group (kernels bounds-check)."""
        b, h, w = (int(s) for s in shape)
        if self.cpu:
            lx, ly = min(LOCAL_X_CPU, round_up(w, 8), self.max_group), 1
        else:
            lx = min(LOCAL_X, round_up(w, 8), self.max_group)
            ly = max(1, min(self.max_group // lx, _power_of_two_at_least(h)))
        return self.launch(name, (round_up(w, lx), round_up(h, ly), b), (lx, ly, 1), *args)

    def grid2(self, name: str, n: int, rows: int, *args):
        """Launch over (rows, n): work item (i, row), i rounded up (kernels bounds-check)."""
        lx = min(self.local_1d, round_up(n, 8))
        return self.launch(name, (round_up(n, lx), int(rows)), (lx, 1), *args)

    def grid1(self, name: str, n: int, *args):
        """Launch over n elements, rounded up to the 1-D group size (kernels bounds-check)."""
        return self.launch(name, (round_up(max(n, 1), self.local_1d),), (self.local_1d,), *args)

    def upload(self, host: np.ndarray):
        """A device copy of ``host`` in its own dtype (a term a kernel reads in another precision than the backend's,
        e.g. float64 where the backend works in float32)."""
        return cla.to_device(self.queue, np.ascontiguousarray(host))

    def row_groups(self, name: str, rows: int, n: int, *args, local: tuple = (), cap: int | None = None):
        """Launch ``rows`` work groups for a kernel whose group g loops over row g's n elements itself (barriers
        between its passes, group reductions in local memory): each the largest power of two within ``cap``, the
        device's and the kernel's limits and the first one ≥ n; after ``args``, a local buffer of each byte count in
        ``local``, then the reductions' scratch (one accumulator an item)."""
        largest = min(self.group_limit(name), cap or self.max_group)
        size = min(1 << (largest.bit_length() - 1), _power_of_two_at_least(n))
        buffers = [cl.LocalMemory(int(nbytes)) for nbytes in local] + [cl.LocalMemory(size * self.acc.itemsize)]
        return self.launch(name, (int(rows) * size,), (size,), *args, *buffers)

    def reduce(self, name: str, n: int, *args, outputs: int = 1) -> np.ndarray:
        """Run a partial-sum kernel (reduce.cl) and return its per-group partials on the host (ACC dtype):
        shape (G,), or (outputs, G) for a kernel with several outputs.

        CPUs: one contiguous chunk of ⌈n/G⌉ terms per work item; GPUs: terms strided by G (coalesced).
        """
        local = self.local_1d
        groups = max(1, min(-(-n // local), (2 if self.cpu else 8) * self.device.max_compute_units))
        items = groups * local
        span, step = (-(-n // items), 1) if self.cpu or items == 1 else (1, items)
        key = (groups, outputs)
        if key not in self._partials:
            self._partials[key] = (np.empty((outputs, groups), self.acc), cl.Buffer(
                self.queue.context, cl.mem_flags.READ_WRITE, outputs * groups * self.acc.itemsize))
        host, buffer = self._partials[key]
        scratch = cl.LocalMemory(local * self.acc.itemsize)
        self.launch(name, (items,), (local,), buffer, scratch, np.int64(n), np.int64(span), np.int64(step), *args)
        cl.enqueue_copy(self.queue, host, buffer)
        return host[0].copy() if outputs == 1 else host.copy()


def _power_of_two_at_least(n: int) -> int:
    return 1 << max(0, int(n) - 1).bit_length()


def _args(args) -> list:
    """pyopencl arrays -> their buffers; everything else as given (typed scalars)."""
    return [a.data if hasattr(a, "base_data") else a for a in args]
