#!/usr/bin/env python3
"""Benchmark every backend primitive and one whole FISTA iteration, OpenCL vs NumPy, against the memory's roof.

    python tools/bench_kernels.py [--size 320x448] [--bands 64] [--repeat 5] [--path auto] [--engine auto]
                                  [--dtype float32] [--device SUBSTRING] [--no-numpy] [--json PATH]

The problem is the sensor H×W with the paper's 2H×2W field and K bands. Each row is the
median of N timed runs after one warm-up, with queue.finish() before and after the timed
part; "GB/s" is the minimum bytes read + written by the primitive divided by that time.
The roofs, measured in the same run on one field cube: the host's STREAM-style copy (NumPy, one
slice per core) and the device's own buffer-to-buffer ``enqueue_copy``, each 2·bytes/time; "% roof" is a
row's GB/s as a fraction of the device's copy (NumPy's rows: of the host's).
"forward" and "adjoint_step" are A and the fused gradient step y − s·Aᵀr through the backend's
convolution (the host's chunked pocketfft pipeline on CPUs); "iteration" is one step of the solver's
own FISTA loop on its band-space problem (forward, residual, fused adjoint step, TV prox with
non-negativity, FISTA statistics, extrapolation); "subspace_tv" is the subspace prox at r = 3.
"""
from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from clsdcam.backends.numpy import NumpyBackend  # noqa: E402
from clsdcam.fista import Fista  # noqa: E402
from clsdcam.geometry import transfer_function  # noqa: E402
from clsdcam.model import ForwardModel  # noqa: E402
from clsdcam.priors import ProxAverage, TotalVariation  # noqa: E402
from clsdcam.problem import Problem  # noqa: E402
from clsdcam.settings import Settings  # noqa: E402


def parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", default="320x448", help="sensor HxW (field 2H x 2W)")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--path", default="auto", help="code path: auto, host (CPU devices) or device (kernels)")
    parser.add_argument("--engine", default="auto", help="FFT engine of the path: auto, host, reikna, vkfft")
    parser.add_argument("--dtype", default="float32")
    parser.add_argument("--device", default=None, help="OpenCL device name substring")
    parser.add_argument("--no-numpy", action="store_true", help="time the OpenCL backend only")
    parser.add_argument("--only", default=None, help="comma-separated row names to run")
    parser.add_argument("--json", type=Path, default=None, help="also write the results here")
    return parser.parse_args(argv)


class Case:
    """Host data and per-backend device buffers for one geometry."""

    def __init__(self, sensor, bands: int, dtype):
        rng = np.random.default_rng(0)
        self.sensor, self.bands = sensor, bands
        self.field = (2 * sensor[0], 2 * sensor[1])
        self.psf = rng.random(sensor)
        self.filters = rng.random((bands, *sensor))
        self.cube = rng.random((bands, *self.field)).astype(dtype)
        self.item = np.dtype(dtype).itemsize

    def sizes(self) -> dict:
        """Bytes of one field cube, spectrum, filter stack and sensor image."""
        k, (h, w), (hp, wp) = self.bands, self.sensor, self.field
        return {"F": k * hp * wp * self.item, "S": k * hp * (wp // 2 + 1) * 2 * self.item,
                "f": k * h * w * self.item, "s": h * w * self.item}


def rows(be, p: Case) -> dict:
    """name -> (callable running the primitive once on ``be``, bytes moved)."""
    n = p.sizes()
    model = ForwardModel(be, p.psf, p.filters)
    x, y, out = be.to_device(p.cube), be.to_device(p.cube[::-1].copy()), be.empty(model.cube_shape)
    spectrum = be.fft2(x)
    transfer = be.to_device(transfer_function(p.psf, model.geometry), complex_=True)
    filters = be.to_device(p.filters)
    window = be.to_device(p.cube[:, :p.sensor[0], :p.sensor[1]])
    b, r = be.empty(p.sensor), be.to_device(np.ones(p.sensor))
    mix = np.eye(p.bands) * 0.5 + 0.5 / p.bands
    basis = np.linalg.qr(np.random.default_rng(1).standard_normal((p.bands, 3)))[0]
    coefficients, projected = be.to_device(p.cube[:3]), be.empty((3,) + p.field)
    offset = model.offset
    step = iteration(be, model, p)
    return {
        "fft2": (lambda: be.fft2(x, out=spectrum), n["F"] + n["S"]),
        "ifft2": (lambda: be.ifft2(spectrum, p.field, out=out), n["S"] + n["F"]),
        "cmul": (lambda: be.cmul(spectrum, transfer, out=spectrum), 2 * n["S"]),
        "pad": (lambda: be.pad(window, p.field, offset, out=out), n["f"] + n["F"]),
        "crop": (lambda: be.crop(x, p.sensor, offset, out=window), 2 * n["f"]),
        "mask_sum": (lambda: be.mask_sum(filters, x, offset, out=b), 2 * n["f"] + n["s"]),
        "mask_spread": (lambda: be.mask_spread(filters, r, p.field, offset, out=out), n["f"] + n["s"] + n["F"]),
        "scale": (lambda: be.scale(0.5, x, out=out), 2 * n["F"]),
        "axpy": (lambda: be.axpy(-0.1, x, y, out=out), 3 * n["F"]),
        "extrapolate": (lambda: be.extrapolate(x, y, 0.3, out=out), 3 * n["F"]),
        "nonneg": (lambda: be.nonneg(x, out=out), 2 * n["F"]),
        "soft": (lambda: be.soft(x, 0.1, out=out), 2 * n["F"]),
        "haar_tv": (lambda: be.haar_tv(x, 1e-3, (1.0, 1.0, 1.0), out=out, nonneg=True), 2 * n["F"]),
        "subspace_tv": (lambda: be.subspace_tv(coefficients, basis, 1e-3, (1.0, 1.0, 1.0), out=projected),
                        2 * 3 * n["F"] // p.bands),
        "fista_stats": (lambda: be.fista_stats(x, y, out), 3 * n["F"]),
        "vdot": (lambda: be.vdot(x, y), 2 * n["F"]),
        "amax": (lambda: be.amax(x), n["F"]),
        "l1_norm": (lambda: be.l1_norm(x), n["F"]),
        "tv_norm": (lambda: be.tv_norm(x, (1.0, 1.0, 1.0)), n["F"]),
        "gram": (lambda: be.gram(x), n["F"]),
        "bandmix": (lambda: be.bandmix(x, mix, out=out), 2 * n["F"]),
        "forward": (lambda: model.forward(x, out=b), 0),
        "adjoint_step": (lambda: model.adjoint(r, out=out, y=y, step=0.1), 0),
        "iteration": (step, 0),
    }


def iteration(be, model, p: Case):
    """One step of the solver's FISTA loop on its band-space problem (TV prox, no objective checks)."""
    average = ProxAverage(be, [TotalVariation(be, 1e-3, Settings())], model.cube_shape)
    problem = Problem(model, be.to_device(np.ones(p.sensor)), average.prox, average.value, p.bands)
    loop = Fista(be, be.to_device(p.cube * 0.01), step=1e-3)
    return lambda: loop.run(problem.gradient_step, problem.prox, 1)


def median_seconds(run, finish, repeat: int) -> float:
    """Median wall time of ``repeat`` runs after one warm-up, synchronised by ``finish``."""
    run()
    finish()
    times = []
    for _ in range(repeat):
        finish()
        start = time.perf_counter()
        run()
        finish()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def host_copy_gbps(nbytes: int, repeat: int) -> float:
    """STREAM copy with NumPy: one slice of ``nbytes`` per core copied by a thread each (NumPy lets go of the GIL)."""
    from concurrent.futures import ThreadPoolExecutor

    workers = os.cpu_count() or 1
    src, dst = np.ones(nbytes // 8), np.empty(nbytes // 8)
    parts = np.array_split(np.arange(src.size), workers)
    bounds = [(part[0], part[-1] + 1) for part in parts if part.size]
    with ThreadPoolExecutor(workers) as pool:
        def copy():
            list(pool.map(lambda b: np.copyto(dst[b[0]:b[1]], src[b[0]:b[1]]), bounds))
        return 2 * src.nbytes / median_seconds(copy, lambda: None, repeat) / 1e9


def device_copy_gbps(be, nbytes: int, repeat: int) -> float:
    """The device's buffer-to-buffer ``enqueue_copy`` of ``nbytes``: 2·bytes / time."""
    src, dst = be.to_device(np.ones(nbytes // be.dtype.itemsize)), be.empty((nbytes // be.dtype.itemsize,))
    return 2 * src.nbytes / median_seconds(lambda: be.copy(src, out=dst), be.queue.finish, repeat) / 1e9


def bench(be, p: Case, repeat: int, only) -> dict:
    finish = be.queue.finish if hasattr(be, "queue") else (lambda: None)
    results = {}
    for name, (run, nbytes) in rows(be, p).items():
        if only and name not in only:
            continue
        seconds = median_seconds(run, finish, repeat)
        results[name] = {"ms": seconds * 1e3, "GBps": nbytes / seconds / 1e9 if nbytes else None}
        print(f"  {be.name:6s} {name:12s} {seconds * 1e3:9.2f} ms", file=sys.stderr, flush=True)
    return results


def environment(be) -> dict:
    def version(package):
        try:
            return importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {"device": be.device_name, "driver_version": be.device.driver_version, "opencl_version": be.device.version,
            "path": be.path, "fft_engine": be.fft_engine, "python": platform.python_version(),
            **{p: version(p) for p in ("numpy", "scipy", "pyopencl", "reikna", "pocl-binary-distribution", "pyvkfft")}}


def markdown(results: dict, meta: dict) -> str:
    cl, ref = results["opencl"], results.get("numpy", {})
    roof = meta["roof_GBps"]
    lines = [f"device: {meta['device']} (driver {meta['driver_version']}), {meta['path']} path, FFT engine "
             f"{meta['fft_engine']}; "
             f"problem {meta['problem']}; median of {meta['repeat']}",
             f"roofs: device enqueue_copy {roof['device_copy']:.1f} GB/s, host STREAM copy (NumPy, "
             f"{os.cpu_count()} threads) {roof['host_copy']:.1f} GB/s",
             "", "| primitive | OpenCL ms | OpenCL GB/s | % roof | NumPy ms | NumPy GB/s | % roof | speed-up |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, row in cl.items():
        other = ref.get(name)
        cells = [name, f"{row['ms']:.2f}", _gb(row), _share(row, roof["device_copy"]),
                 f"{other['ms']:.2f}" if other else "—", _gb(other), _share(other, roof["host_copy"]),
                 f"{other['ms'] / row['ms']:.2f}×" if other else "—"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _gb(row) -> str:
    return f"{row['GBps']:.1f}" if row and row["GBps"] else "—"


def _share(row, roof: float) -> str:
    """A row's GB/s as a percentage of ``roof``."""
    return f"{100 * row['GBps'] / roof:.0f} %" if row and row["GBps"] else "—"


def main(argv=None) -> int:
    args = parse_args(argv)
    from clsdcam.backends.opencl import OpenCLBackend

    sensor = tuple(int(v) for v in args.size.lower().split("x"))
    problem = Case(sensor, args.bands, np.dtype(args.dtype))
    only = set(args.only.split(",")) if args.only else None
    be = OpenCLBackend(args.dtype, device=args.device, fft=args.engine, path=args.path)
    cube = problem.sizes()["F"]
    meta = {**environment(be), "problem": f"sensor {sensor[0]}x{sensor[1]}, field {problem.field[0]}x{problem.field[1]}, "
                                         f"{args.bands} bands, {args.dtype}", "repeat": args.repeat,
            "roof_GBps": {"device_copy": device_copy_gbps(be, cube, args.repeat),
                          "host_copy": host_copy_gbps(cube, args.repeat)}}
    results = {"opencl": bench(be, problem, args.repeat, only)}
    if not args.no_numpy:
        results["numpy"] = bench(NumpyBackend(args.dtype), problem, args.repeat, only)
    print(markdown(results, meta))
    if args.json:
        args.json.write_text(json.dumps({"meta": meta, "results": results}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
