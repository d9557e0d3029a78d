#!/usr/bin/env python3
"""Run time against error: every configuration on every simulated scene, side by side with the
authors' published algorithm (tools/authors_baseline.py), all in one run.

    python tools/bench_recon.py --size 64x96 --bands 16 --iters 300 --out bench-recon

For each scene and configuration it records, at log-spaced iterations: wall time, objective,
PSNR and mean spectral angle against the truth, and the relative error against a converged
float64 clsdcam solution (``--reference-iters``). Writes ``results.json``, ``results.md`` and
``error_vs_time.png`` (log axes) in ``--out``; prints the markdown table, including how much
sooner each configuration reaches the PSNR the authors' algorithm has after its last iteration.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from authors_baseline import AuthorsSolver  # noqa: E402

from clsdcam.metrics import psnr, relative_error, spectral_angle  # noqa: E402
from clsdcam.sim import simulate  # noqa: E402
from clsdcam.solver import Settings, Solver  # noqa: E402

CONFIGS = {  # name -> (backend, dtype)
    "numpy float32": ("numpy", "float32"),
    "opencl float32": ("opencl", "float32"),
    "numpy float64": ("numpy", "float64"),
}


def marks(iters: int) -> list[int]:
    """About 12 log-spaced iterations from 1 to ``iters``."""
    return sorted({int(round(v)) for v in np.geomspace(1, iters, 12)})


def point(k, seconds, cube, truth, reference) -> dict:
    return {"iteration": k, "seconds": seconds, "psnr": psnr(cube, truth), "angle": spectral_angle(cube, truth),
            "error": relative_error(cube, reference)}


def run_clsdcam(sim, backend, dtype, iters, reference) -> dict:
    solver = Solver(sim.calibration, backend=backend, settings=Settings(iters=iters, dtype=dtype))
    result = solver.solve(sim.measurement, snapshots=marks(iters))
    seconds = [r["seconds"] for r in result.history]
    curve = [point(k, seconds[k - 1], cube, sim.truth, reference) for k, cube in sorted(result.snapshots.items())]
    return {"curve": curve, "per_iteration": seconds[-1] / len(seconds), "fft": solver.backend.fft_engine}


def run_authors(sim, iters, reference) -> dict:
    solver = AuthorsSolver(sim.calibration.psf, sim.calibration.filters)
    wanted, curve, start = set(marks(iters)), [], time.perf_counter()
    for k, cube in solver.run(sim.measurement, iters):
        if k in wanted:
            curve.append(point(k, time.perf_counter() - start, cube, sim.truth, reference))
    return {"curve": curve, "per_iteration": curve[-1]["seconds"] / iters, "fft": "numpy complex128"}


def time_to_reach(curve, target_psnr):
    """Seconds until the curve first reaches ``target_psnr`` (None if it never does)."""
    return next((p["seconds"] for p in curve if p["psnr"] >= target_psnr), None)


def table(results) -> str:
    lines = ["| scene | configuration | s/iteration | final PSNR dB | final SA ° | rel. error | "
             "time to the authors' final PSNR | speed-up |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for scene, configs in results.items():
        authors = configs["authors"]["curve"][-1]
        for name, run in configs.items():
            last = run["curve"][-1]
            reach = time_to_reach(run["curve"], authors["psnr"])
            speedup = f"{authors['seconds'] / reach:.0f}×" if reach else "—"
            lines.append(f"| {scene} | {name} | {run['per_iteration']:.4f} | {last['psnr']:.2f} | {last['angle']:.1f} "
                         f"| {last['error']:.3f} | {f'{reach:.2f} s' if reach else 'not reached'} | {speedup} |")
    return "\n".join(lines)


def plot(results, path: Path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.5 * len(results), 3.6))
    FigureCanvasAgg(fig)
    for i, (scene, configs) in enumerate(results.items()):
        ax = fig.add_subplot(1, len(results), i + 1)
        for name, run in configs.items():
            ax.loglog([p["seconds"] for p in run["curve"]], [p["error"] for p in run["curve"]], marker=".", label=name)
        ax.set(title=scene, xlabel="seconds", ylabel="relative error vs converged float64")
        ax.grid(True, which="both", alpha=0.3)
    fig.axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def iteration_timing(shape, bands: int, repeat: int) -> str:
    """Median seconds per iteration at ``shape``×``bands``: authors, NumPy, OpenCL, and the FFT floor
    (2 rfft2 + 2 irfft2 of the K-band field, pocketfft, all cores) — one run, so ratios are fair."""
    import scipy.fft

    sim = simulate(scene="target", shape=shape, n_bands=bands, seed=0)
    authors = AuthorsSolver(sim.calibration.psf, sim.calibration.filters)
    rows = {"authors (complex128, as published)": _median_seconds(
        lambda: list(authors.run(sim.measurement, 3)), repeat) / 3}
    for name, (backend, dtype) in CONFIGS.items():  # whole solves of 10 iterations: set-up included
        solver = Solver(sim.calibration, backend=backend, settings=Settings(iters=10, dtype=dtype))
        rows[f"clsdcam {name}"] = _median_seconds(lambda: solver.solve(sim.measurement), repeat) / 10
    field = np.zeros((bands, 2 * shape[0], 2 * shape[1]), np.float32)
    spectrum = scipy.fft.rfft2(field, workers=-1)
    rows["FFT floor (float32, 4 transforms of K bands)"] = 2 * _median_seconds(
        lambda: (scipy.fft.rfft2(field, workers=-1), scipy.fft.irfft2(spectrum, s=field.shape[1:], workers=-1)), repeat)
    authors = rows["authors (complex128, as published)"]
    lines = [f"| per iteration, {bands}×{shape[0]}×{shape[1]} | seconds | vs authors |", "|---|---:|---:|"]
    lines += [f"| {name} | {sec:.3f} | {authors / sec:.1f}× |" for name, sec in rows.items()]
    return "\n".join(lines)


def _median_seconds(run, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="leds,target,piecewise,realcube")
    parser.add_argument("--size", default="64x96")
    parser.add_argument("--bands", type=int, default=16)
    parser.add_argument("--iters", type=int, default=300)
    parser.add_argument("--reference-iters", type=int, default=3000)
    parser.add_argument("--configs", default=",".join(CONFIGS), help=f"from: {', '.join(CONFIGS)}")
    parser.add_argument("--out", default="bench-recon")
    parser.add_argument("--timing-size", default=None, metavar="HxW",
                        help="instead: seconds per iteration at this size (e.g. 320x448) and --bands, all solvers")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    if args.timing_size:
        print(iteration_timing(tuple(int(v) for v in args.timing_size.split("x")), args.bands, args.repeat))
        return 0
    shape = tuple(int(v) for v in args.size.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for scene in args.scenes.split(","):
        sim = simulate(scene=scene, shape=shape, n_bands=args.bands, seed=0)
        reference = Solver(sim.calibration, settings=Settings(iters=args.reference_iters, dtype="float64")).solve(
            sim.measurement).cube
        results[scene] = {name: run_clsdcam(sim, *CONFIGS[name], args.iters, reference)
                          for name in args.configs.split(",")}
        results[scene]["authors"] = run_authors(sim, args.iters, reference)
        print(f"{scene}: done", file=sys.stderr)
    text = table(results)
    print(text)
    (out / "results.md").write_text(text + "\n")
    (out / "results.json").write_text(json.dumps(results, indent=1))
    plot(results, out / "error_vs_time.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
