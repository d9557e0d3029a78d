#!/usr/bin/env python3
"""Batch throughput and warm starts.

    python tools/bench_batch.py throughput --size 320x448 --bands 64 --frames 4 --iters 10 --workers 1,2
    python tools/bench_batch.py warm --size 64x96 --bands 32 --frames 6 --iters 200

``throughput``: frames/s of ``clsdcam batch`` (embedded LocalCluster) for each worker count, in one
run, on a simulated video (``--scene``). ``warm``: for each frame after the first, the iterations a
warm-started solve (from the previous frame's cube) needs to reach the PSNR a cold start has after
``--iters``; prints a markdown table (and ``--json``).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from clsdcam.batch import BatchSpec, run_batch
from clsdcam.calibration import Preprocessing, preprocess
from clsdcam.metrics import psnr
from clsdcam.solver import Settings, Solver
from clsdcam.video import simulate_video, write_video

EVERY = 5  # warm-start PSNR is checked every EVERY iterations


def throughput(args, workdir: Path) -> dict:
    calibration, frames, truth = simulate_video(args.scene, args.frames, args.shape, args.bands, seed=0)
    paths = write_video(workdir, calibration, frames, truth)
    spec = BatchSpec(frames=(str(paths["frames"]),), calibration=str(paths["calibration"]),
                     settings=Settings(iters=args.iters))
    rows = {}
    for workers in args.workers:
        start = time.perf_counter()
        run_batch(spec, workdir / f"out-{workers}.h5", workers=workers, overwrite=True)
        rows[workers] = args.frames / (time.perf_counter() - start)
    print(f"| workers | frames/s ({args.bands}×{args.shape[0]}×{args.shape[1]}, {args.iters} iterations) | vs 1 |")
    print("|---:|---:|---:|")
    for workers, rate in rows.items():
        print(f"| {workers} | {rate:.3f} | {rate / rows[args.workers[0]]:.2f}× |")
    return {str(k): v for k, v in rows.items()}


def warm(args, workdir: Path) -> dict:
    calibration, frames, truth = simulate_video(args.scene, args.frames, args.shape, args.bands, seed=0)
    calibration, _ = preprocess(calibration, frames[0], Preprocessing())
    solver = Solver(calibration, settings=Settings(iters=args.iters))
    previous, rows = solver.solve(frames[0]).cube, []  # as clsdcam batch does: the previous sensor-window cube
    for t in range(1, args.frames):
        target = psnr(solver.solve(frames[t]).cube, truth[t])
        warm_result = solver.solve(frames[t], x0=previous, snapshots=range(EVERY, args.iters + 1, EVERY))
        reached = next((k for k, cube in sorted(warm_result.snapshots.items()) if psnr(cube, truth[t]) >= target), None)
        rows.append({"frame": t, "cold_iterations": args.iters, "cold_psnr": target, "warm_iterations": reached})
        previous = warm_result.cube
    print(f"| frame | cold: iterations | cold PSNR dB | warm: iterations to the same PSNR |")
    print("|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['frame']} | {r['cold_iterations']} | {r['cold_psnr']:.2f} | {r['warm_iterations'] or 'not reached'} |")
    done = [r["warm_iterations"] for r in rows if r["warm_iterations"]]
    if done:
        print(f"\nmedian warm/cold iteration ratio: {np.median(done) / args.iters:.3f}")
    return {"rows": rows}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("throughput", "warm"))
    parser.add_argument("--scene", default="leds", help="leds (drifting 1 px/frame) or target (0.5 px/frame)")
    parser.add_argument("--size", default="64x96")
    parser.add_argument("--bands", type=int, default=32)
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--iters", type=int, default=200)
    parser.add_argument("--workers", default="1,2")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    args.shape = tuple(int(v) for v in args.size.split("x"))
    args.workers = [int(w) for w in args.workers.split(",")]
    with tempfile.TemporaryDirectory() as workdir:
        result = (throughput if args.what == "throughput" else warm)(args, Path(workdir))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
