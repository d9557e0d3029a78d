#!/usr/bin/env python3
"""Benchmark every backend primitive and one whole FISTA iteration, OpenCL vs NumPy, against the memory's roof.

    python tools/bench_kernels.py [--size 320x448] [--bands 64] [--repeat 5] [--path auto] [--engine auto]
                                  [--dtype float32] [--device SUBSTRING] [--no-numpy] [--json PATH]

The problem is the sensor H×W with the paper's 2H×2W field and K bands. The primitives' rows are their
benchmark cases in ``clsdcam/backends/cases.py`` (the table the parity tests and ``clsdcam check`` read), their
arrays moved to the backend once and their output reused. Each row is the median of N timed runs after one
warm-up, with queue.finish() before and after the timed part; "GB/s" is the minimum bytes read + written by the
primitive (the case's ``moved``) divided by that time.
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
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from clsdcam.backends.cases import Inputs, benchmarks  # noqa: E402
from clsdcam.backends.numpy import NumpyBackend  # noqa: E402
from clsdcam.camera.model import ForwardModel  # noqa: E402


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


class Bench:
    """The primitive cases' inputs at one size (``cases.Inputs``: the sensor at the centre of a 2H × 2W field) and a
    PSF for the model's rows."""

    def __init__(self, sensor, bands: int, dtype):
        self.sensor, self.bands = tuple(sensor), bands
        self.field = (2 * self.sensor[0], 2 * self.sensor[1])
        self.inputs = Inputs(bands, self.sensor, self.field, dtype)
        self.psf = np.random.default_rng(0).random(self.sensor)
        self.cube = self.inputs["field"]

    def field_bytes(self) -> int:
        return self.inputs.nbytes("field")


MODEL_ROWS = ("forward", "adjoint_step", "iteration")


def rows(be, p: Bench) -> dict:
    """name -> (a function making the row's run-once callable on ``be``, bytes moved; 0: not counted): each
    primitive's benchmark case, then the model's rows."""
    made = {case.name: (partial(case.timed, be, p.inputs), case.moved(p.inputs)) for case in benchmarks()}
    return {**made, **{name: (partial(model_row, be, p, name), 0) for name in MODEL_ROWS}}


def model_row(be, p: Bench, name: str):
    """The run-once callable of a model row: A ("forward"), the fused gradient step y − s·Aᵀr ("adjoint_step") or
    one FISTA iteration."""
    model = ForwardModel(be, p.psf, p.inputs["filters"])
    if name == "iteration":
        return iteration(be, model, p)
    x, r = be.to_device(p.cube), be.to_device(np.ones(p.sensor))
    if name == "forward":
        b = be.empty(p.sensor)
        return lambda: model.forward(x, out=b)
    y, out = be.to_device(p.cube[::-1].copy()), be.empty(model.cube_shape)
    return lambda: model.adjoint(r, out=out, y=y, step=0.1)


def iteration(be, model, p: Bench):
    """One iteration of the solver's loop (the driver running FISTA) on its band-space problem (TV prox, no
    objective checks)."""
    from clsdcam.algorithms.fista import Fista
    from clsdcam.solve.driver import Driver, Rules
    from clsdcam.solve.priors import ProxAverage, TotalVariation
    from clsdcam.solve.problem import Problem
    from clsdcam.solve.settings import Settings

    average = ProxAverage(be, [TotalVariation(be, 1e-3, Settings())], model.cube_shape)
    problem = Problem(model, be.to_device(np.ones(p.sensor)), average.prox, average.value, p.bands)
    driver = Driver(Fista(be, be.to_device(p.cube * 0.01), 1e-3, Rules()))
    return lambda: driver.run(problem, 1)


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


def bench(be, p: Bench, repeat: int, only) -> dict:
    finish = be.queue.finish if hasattr(be, "queue") else (lambda: None)
    results = {}
    for name, (make, nbytes) in rows(be, p).items():
        if only and name not in only:
            continue
        seconds = median_seconds(make(), finish, repeat)
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
    problem = Bench(sensor, args.bands, np.dtype(args.dtype))
    only = set(args.only.split(",")) if args.only else None
    be = OpenCLBackend(args.dtype, device=args.device, fft=args.engine, path=args.path)
    cube = problem.field_bytes()
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
