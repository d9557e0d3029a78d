#!/usr/bin/env python3
"""Seconds per iteration at full size: every configuration in one run, repeats interleaved, medians.

    python tools/bench_iteration.py --size 320x448 --bands 64 --repeat 3 --json iteration.json

Rows: the authors' published algorithm (tools/authors_baseline.py), clsdcam on NumPy and on OpenCL
as the full solver (``--no-skip``: the paper's 2H × 2W field, every band), as the default (band space on the
paper's field, exact skips only), with the support-sized field (``--support-field``), with ``--subspace
--support-field`` (the rank its checks pick on the resolution target), and in spectral subspaces of forced ranks
on the support field; and the FFT floor as the issue defines it, the
4·K real 2-D transforms an iteration needs (2 rfft2 + 2 irfft2 of K bands, pocketfft on all cores,
the faster of one batched call and cache-sized chunks, each the mean of 5 calls), at the paper's
field and at the support field. A clsdcam row is the time between two iterations of a solve,
over 50 steady-state iterations (so it includes its objective checks and, in a subspace, its basis
checks every 25 iterations); set-up is not in it.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.fft

sys.path.insert(0, str(Path(__file__).resolve().parent))

from authors_baseline import AuthorsSolver  # noqa: E402
from report import emit  # noqa: E402

from clsdcam.backends.host_convolution import CHUNK_BYTES  # noqa: E402
from clsdcam.solve.space_policy import WARMUP  # noqa: E402
from clsdcam.sim import simulate  # noqa: E402
from clsdcam.solve.solver import Settings, Solver  # noqa: E402

WINDOW = 50     # steady-state iterations timed per solve: 5 objective checks and, in a subspace, 2 basis checks
AUTHORS = "authors (complex128, as published)"
PAPER, OWN = "paper field", "support field"
SPEED = {"support_field": True}      # the speed options' field, under every subspace row
FLOOR_CALLS = 5  # FFT-floor calls averaged per strategy and round


def configurations(bands: int, ranks, backends) -> dict:
    """name -> (backend, Settings fields, first timed iteration)."""
    configs = {}
    for backend in backends:
        configs[f"{backend} full solver (--no-skip)"] = (backend, {"skip": False}, 1)
        configs[f"{backend} default (paper field, {bands} bands)"] = (backend, {}, 1)
        if backend == "numpy":
            configs[f"{backend} --algorithm admm (paper field, {bands} bands)"] = (backend, {"algorithm": "admm"}, 1)
        configs[f"{backend} --support-field ({bands} bands)"] = (backend, SPEED, 1)
        configs[f"{backend} --subspace --support-field (automatic rank)"] = (backend, SPEED | {"subspace": True},
                                                                             WARMUP + 1)
        for rank in ranks:
            configs[f"{backend} subspace r = {rank}"] = (backend, SPEED | {"rank": rank}, WARMUP + 1)
    return configs


def clsdcam_timer(sim, backend: str, fields: dict, first: int):
    """A function timing one solve's steady-state seconds per iteration (the solver is built once)."""
    solver = Solver(sim.calibration, backend=backend, settings=Settings(iters=first + WINDOW, **fields))

    def seconds_per_iteration() -> float:
        seconds = [r["seconds"] for r in solver.solve(sim.measurement).history]
        return (seconds[first + WINDOW - 1] - seconds[first - 1]) / WINDOW

    return solver, seconds_per_iteration


def authors_timer(sim):
    """Seconds of the authors' second iteration (the first allocates)."""
    authors = AuthorsSolver(sim.calibration.psf, sim.calibration.filters)

    def seconds_per_iteration() -> float:
        marks = [time.perf_counter()] + [time.perf_counter() for _ in authors.run(sim.measurement, 2)]
        return marks[2] - marks[1]

    return seconds_per_iteration


def floor_timer(bands: int, field):
    """A function timing 2 rfft2 + 2 irfft2 of a (K, Hp, Wp) float32 cube: the faster of batched and chunked calls."""
    cube = np.random.default_rng(0).random((bands,) + tuple(field), dtype=np.float32)
    spectrum = scipy.fft.rfft2(cube, workers=-1)
    per = max(1, CHUNK_BYTES // (spectrum[0].nbytes))

    def batched():
        scipy.fft.rfft2(cube, workers=-1)
        scipy.fft.irfft2(spectrum, s=field, workers=-1)

    def chunked():
        for k in range(0, bands, per):
            scipy.fft.rfft2(cube[k:k + per], workers=-1)
            scipy.fft.irfft2(spectrum[k:k + per], s=field, workers=-1)

    return lambda: 2 * min(_seconds(batched), _seconds(chunked))


def _seconds(run, calls: int = FLOOR_CALLS) -> float:
    """Mean seconds of ``calls`` runs (a clsdcam row is a mean too, so the ratio compares like with like)."""
    start = time.perf_counter()
    for _ in range(calls):
        run()
    return (time.perf_counter() - start) / calls


def measure(args) -> dict:
    shape = tuple(int(v) for v in args.size.split("x"))
    sim = simulate(scene="target", shape=shape, n_bands=args.bands, seed=0)
    backends = [b for b in args.backends.split(",") if b]
    timers, fields, devices = {}, {}, set()
    for name, (backend, settings, first) in configurations(args.bands, args.ranks, backends).items():
        solver, timers[name] = clsdcam_timer(sim, backend, settings, first)
        fields[name] = list(solver.geometry.field)
        devices.add(f"{backend}: {solver.backend.device_name} (FFT {solver.backend.fft_engine})")
    if not args.no_authors:
        timers[AUTHORS] = authors_timer(sim)
    own_field = next(tuple(f) for n, f in fields.items() if "--support-field" in n)
    timers[PAPER] = floor_timer(args.bands, tuple(2 * s for s in shape))
    timers[OWN] = floor_timer(args.bands, own_field)
    samples = {name: [] for name in timers}
    for repeat in range(args.repeat):           # interleaved: every configuration once per round
        for name, timer in timers.items():
            samples[name].append(timer())
        print(f"round {repeat + 1}/{args.repeat} done", file=sys.stderr)
    seconds = {name: float(np.median(v)) for name, v in samples.items()}
    floors = {name: seconds.pop(name) for name in (PAPER, OWN)}
    return {"size": shape, "bands": args.bands, "repeat": args.repeat, "fields": fields, "devices": sorted(devices),
            "seconds": seconds, "samples": samples, "fft_floor": floors}


def table(result: dict) -> str:
    seconds, floors = result["seconds"], result["fft_floor"]
    authors = seconds.get(AUTHORS)
    lines = [f"| per iteration, {result['bands']}×{result['size'][0]}×{result['size'][1]} | field | seconds "
             f"(median, min–max of {result['repeat']}) | vs authors | vs FFT floor, paper field | vs FFT floor, support field |",
             "|---|---|---:|---:|---:|---:|"]
    for name, sec in seconds.items():
        field = "×".join(map(str, result["fields"].get(name, ()))) or "paper"
        versus = f"{authors / sec:.1f}×" if authors else "—"
        floor_ratios = "— | —" if name == AUTHORS else f"{sec / floors[PAPER]:.2f} | {sec / floors[OWN]:.2f}"
        lines.append(f"| {name} | {field} | {sec:.4f} ({_spread(result['samples'][name])}) | {versus} | {floor_ratios} |")
    lines += [f"| FFT floor, {name} (4·K transforms) | | {sec:.4f} ({_spread(result['samples'][name])}) | | | |"
              for name, sec in floors.items()]
    return "\n".join(lines) + "\n\ndevices: " + "; ".join(result["devices"]) + ratio_lines(seconds)


def _spread(samples) -> str:
    return f"{min(samples):.4f}–{max(samples):.4f}"


def ratio_lines(seconds: dict) -> str:
    """OpenCL / NumPy for each mode measured on both."""
    out = []
    for name, sec in seconds.items():
        twin = name.replace("numpy", "opencl", 1)
        if name.startswith("numpy") and twin in seconds:
            out.append(f"opencl / numpy, {name[6:]}: {seconds[twin] / sec:.2f}")
    return "\n" + "\n".join(out) if out else ""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="320x448")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--ranks", type=lambda t: [int(v) for v in t.split(",")], default=[3, 8])
    parser.add_argument("--backends", default="numpy,opencl")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-authors", action="store_true", help="leave out the authors' algorithm (~10 s/iteration at full size)")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    result = measure(args)
    return emit(result, table(result), args.json)


if __name__ == "__main__":
    sys.exit(main())
