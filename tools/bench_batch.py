#!/usr/bin/env python3
"""Batch throughput and warm starts.

    python tools/bench_batch.py throughput --size 320x448 --bands 64 --frames 4 --iters 10 --workers 1,2
    python tools/bench_batch.py warm --size 64x96 --bands 32 --frames 6 --iters 200

``throughput``: frames/s of ``clsdcam batch`` (embedded LocalCluster) for each worker count, in one
run, on a simulated video (``--scene``). ``warm``: for each frame after the first, the iterations a
warm-started solve (from the previous frame's cube) needs to reach the PSNR a cold start has after
``--iters``, starting from the previous cube as is and from the motion-predicted one that
``clsdcam batch`` uses (``clsdcam.batch.predict``); prints a markdown table (and ``--json``).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from clsdcam.batch import BatchSpec, predict, run_batch
from clsdcam.calibration import Preprocessing, preprocess
from clsdcam.metrics import psnr
from clsdcam.sim.video import simulate_video, write_video
from clsdcam.solver import Settings, Solver

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
        with h5py.File(workdir / f"out-{workers}.h5", "r") as f:
            solve = float(np.mean(f["seconds"][...]))
        rows[workers] = {"frames_per_s": args.frames / (time.perf_counter() - start), "solve_s_per_frame": solve}
    one = rows[args.workers[0]]["frames_per_s"]
    print(f"| workers | frames/s end to end ({args.bands}×{args.shape[0]}×{args.shape[1]}, {args.frames} frames, "
          f"{args.iters} iterations; cluster start and model builds included) | vs {args.workers[0]} "
          f"| solve s/frame (mean) |")
    print("|---:|---:|---:|---:|")
    for workers, r in rows.items():
        print(f"| {workers} | {r['frames_per_s']:.3f} | {r['frames_per_s'] / one:.2f}× | {r['solve_s_per_frame']:.2f} |")
    return {str(k): v for k, v in rows.items()}


def warm(args, workdir: Path) -> dict:
    calibration, frames, truth = simulate_video(args.scene, args.frames, args.shape, args.bands, seed=0)
    calibration, _ = preprocess(calibration, frames[0], Preprocessing())
    solver = Solver(calibration, settings=Settings(iters=args.iters))
    checks = range(EVERY, args.iters + 1, EVERY)
    first = solver.solve(frames[0]).cube
    chains = {"previous": (None, first), "predicted": (None, first)}  # (x̂_{t−2}, x̂_{t−1}) of each warm start
    rows = []
    for t in range(1, args.frames):
        target = psnr(solver.solve(frames[t]).cube, truth[t])
        row = {"frame": t, "cold_iterations": args.iters, "cold_psnr": target}
        for name, (before, previous) in chains.items():
            x0 = previous if name == "previous" else predict(before, previous)  # predict: what clsdcam batch does
            result = solver.solve(frames[t], x0=x0, snapshots=checks)
            row[name] = next((k for k, c in sorted(result.snapshots.items()) if psnr(c, truth[t]) >= target), None)
            chains[name] = (previous, result.cube)
        rows.append(row)
    print("| frame | cold: iterations | cold PSNR dB | warm from x̂(t−1): iterations to that PSNR "
          "| warm, motion-predicted (batch): iterations |")
    print("|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['frame']} | {r['cold_iterations']} | {r['cold_psnr']:.2f} | {r['previous'] or 'not reached'} "
              f"| {r['predicted'] or 'not reached'} |")
    summary = {}
    for name in chains:  # frames where the warm start never reached the cold PSNR count as args.iters
        summary[name] = float(np.mean([r[name] or args.iters for r in rows]) / args.iters)
        print(f"\nmean warm/cold iteration ratio, {name}: {summary[name]:.3f}", end="")
    print()
    return {"rows": rows, "ratio": summary}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("throughput", "warm"))
    parser.add_argument("--scene", default="leds", help="leds (drifting 1 px/frame) or target (0.5 px/frame)")
    parser.add_argument("--size", default=None, help="HxW (default: 320x448 for throughput, 64x96 for warm)")
    parser.add_argument("--bands", type=int, default=None, help="default: 64 for throughput, 32 for warm")
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--iters", type=int, default=200)
    parser.add_argument("--workers", default="1,2")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    full = args.what == "throughput"
    args.shape = tuple(int(v) for v in (args.size or ("320x448" if full else "64x96")).split("x"))
    args.bands = args.bands or (64 if full else 32)
    args.workers = [int(w) for w in args.workers.split(",")]
    with tempfile.TemporaryDirectory() as workdir:
        result = (throughput if args.what == "throughput" else warm)(args, Path(workdir))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
