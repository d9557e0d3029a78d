#!/usr/bin/env python3
"""pocketfft's ``irfft2`` against the package's inverse in two passes (``clsdcam.backends.irfft2``), on one field.

    python tools/bench_inverse.py --size 256x320 --bands 64 --repeat 8
    python tools/bench_inverse.py --solve-size 128x160 --bands 64 --repeat 10     # in ADMM's c-step and FISTA's adjoint

Each way transforms the same (K, Hp, Wp//2 + 1) complex64 half spectrum back, in chunks of bands as ADMM's c-step
and FISTA's adjoint take them (``host_convolution.CHUNK_BYTES`` of spectrum a chunk), on ``--workers`` threads;
the rounds alternate the ways, and each way's median of ``--repeat`` rounds is printed with its ratio to
``irfft2``'s and the largest difference from it. ``in place``: on a spectrum the caller no longer needs
(``overwrite_x=True`` to pocketfft's own, ``overwrite=True`` to the package's, as the solvers call it), timed without
the copy from the kept spectrum that each round makes for it first (printed apart). Timings drift ±30 % on a shared
machine: read the ratios.

``--solve-size HxW`` times where the solvers use it instead, on the LED grid at that sensor size: ADMM's c-step
(from its state after three iterations, repeated on it) and FISTA's adjoint Aᵀr (a random residual), each with its
inverses as pocketfft's ``irfft2`` called as each called it before the package had its own (the adjoint telling it
that it may overwrite its input, the c-step not) and as the package's, the two alternating in one process, medians
of ``--repeat`` rounds.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from unittest import mock

import numpy as np
import scipy.fft

from clsdcam.algorithms.admm import host_steps
from clsdcam.algorithms.admm.algorithm import Admm
from clsdcam.backends import host_convolution, irfft2
from clsdcam.backends.host_convolution import CHUNK_BYTES, HostConvolution
from clsdcam.sim import simulate
from clsdcam.solve.solver import Settings, Solver


def ways(spectrum: np.ndarray, scratch: np.ndarray, field, workers: int) -> dict:
    """name -> a function transforming ``spectrum`` back chunk by chunk into a new real cube."""
    per = max(1, CHUNK_BYTES // spectrum[0].nbytes)
    out = np.empty(spectrum.shape[:1] + tuple(field), np.float32)

    def chunked(inverse, source):
        def run():
            for k in range(0, len(spectrum), per):
                out[k:k + per] = inverse(source[k:k + per])
            return out
        return run

    return {"irfft2": chunked(lambda s: scipy.fft.irfft2(s, s=field, workers=workers), spectrum),
            "irfft2, in place": chunked(lambda s: scipy.fft.irfft2(s, s=field, workers=workers, overwrite_x=True),
                                        scratch),
            "two passes": chunked(lambda s: irfft2(s, field, workers), spectrum),
            "two passes, in place": chunked(lambda s: irfft2(s, field, workers, overwrite=True), scratch)}


BEFORE = {   # pocketfft's own irfft2 in the package's helper's place, called as each caller called it before
    host_steps: lambda spectrum, shape, workers=1, overwrite=False: scipy.fft.irfft2(spectrum, s=shape,
                                                                                     workers=workers),
    host_convolution: lambda spectrum, shape, workers=1, overwrite=False: scipy.fft.irfft2(
        spectrum, s=shape, workers=workers, overwrite_x=overwrite),
}


def admm_after(sim, iterations: int = 3):
    """ADMM's steps and state after ``iterations`` of a solve of ``sim``."""
    kept = {}
    iterate = Admm.iterate

    def keep(self, problem):
        record = iterate(self, problem)
        kept["steps"], kept["state"] = self.splitting, self.state
        return record

    with mock.patch.object(Admm, "iterate", keep):
        Solver(sim.calibration, settings=Settings(iters=iterations, algorithm="admm")).solve(sim.measurement)
    return kept["steps"], kept["state"]


def in_solve(size, bands: int, rounds: int) -> dict:
    """Seconds (medians) of ADMM's c-step and FISTA's adjoint with pocketfft's irfft2 and with the package's."""
    sim = simulate(scene="leds", shape=size, n_bands=bands, seed=0)
    steps, state = admm_after(sim)
    adjoint = HostConvolution(steps.terms.transfer, steps.terms.filters, steps.field_shape, steps.dtype,
                             steps.workers)
    residual = np.random.default_rng(0).standard_normal(steps.sensor_shape).astype(steps.dtype)
    gradient = np.empty(steps.shape, steps.dtype)
    parts = {"ADMM's c-step": lambda: steps.c_step(state),
             "FISTA's adjoint": lambda: adjoint.adjoint(residual, gradient)}
    seconds = {(part, way): [] for part in parts for way in ("irfft2", "two passes, in place")}
    for _ in range(rounds):
        for part, run in parts.items():
            for way in ("irfft2", "two passes, in place"):
                before = way == "irfft2"
                with mock.patch.object(host_steps, "irfft2", BEFORE[host_steps] if before else irfft2), \
                        mock.patch.object(host_convolution, "irfft2", BEFORE[host_convolution] if before else irfft2):
                    start = time.perf_counter()
                    run()
                    seconds[part, way].append(time.perf_counter() - start)
    return {part: {way: float(np.median(seconds[part, way])) for way in ("irfft2", "two passes, in place")}
            for part in parts}


def alone(field, bands: int, workers: int, rounds: int) -> dict:
    """Each way of :func:`ways` on one random field's half spectrum, alternating: medians (and the in-place ways'
    copy), ratios to ``irfft2``'s, and each way's largest difference from it."""
    spectrum = scipy.fft.rfft2(np.random.default_rng(0).random((bands,) + field, dtype=np.float32))
    scratch = np.empty_like(spectrum)
    runs = ways(spectrum, scratch, field, workers)
    seconds = {name: [] for name in [*runs, "copy"]}
    results = {}
    for _ in range(rounds):
        for name, run in runs.items():
            if name.endswith("in place"):
                start = time.perf_counter()
                np.copyto(scratch, spectrum)
                seconds["copy"].append(time.perf_counter() - start)
            start = time.perf_counter()
            cube = run()
            seconds[name].append(time.perf_counter() - start)
            results[name] = cube.copy()
    medians = {name: float(np.median(s)) for name, s in seconds.items()}
    return {"median_seconds": medians, "ratio": {name: medians[name] / medians["irfft2"] for name in runs},
            "largest_difference": {name: float(np.abs(r - results["irfft2"]).max()) for name, r in results.items()}}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="256x320", help="the field Hp×Wp (default: a 128×160 sensor's)")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=8)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--solve-size", default=None, metavar="HxW",
                        help="time ADMM's c-step and FISTA's adjoint at this sensor size instead")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    if args.solve_size:
        size = tuple(int(n) for n in args.solve_size.split("x"))
        report = {"solve_size": args.solve_size, "bands": args.bands, "median_seconds": in_solve(size, args.bands,
                                                                                                 args.repeat)}
        for part, medians in report["median_seconds"].items():
            old, new = medians["irfft2"], medians["two passes, in place"]
            print(f"{part}: {1e3 * old:.1f} ms with irfft2, {1e3 * new:.1f} ms with two passes in place "
                  f"({new / old:.2f}×)")
        return save(report, args.json)
    field = tuple(int(n) for n in args.size.split("x"))
    report = {"size": args.size, "bands": args.bands, "workers": args.workers,
              **alone(field, args.bands, args.workers, args.repeat)}
    for name, ratio in report["ratio"].items():
        print(f"{name:22s} {1e3 * report['median_seconds'][name]:7.1f} ms  {ratio:.2f}×  "
              f"largest difference {report['largest_difference'][name]:.1e}")
    print(f"{'(the copy, taken off)':22s} {1e3 * report['median_seconds']['copy']:7.1f} ms")
    return save(report, args.json)


def save(report: dict, path: str | None) -> int:
    if path:
        with open(path, "w", encoding="utf-8") as f:
            json.dump(report, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
