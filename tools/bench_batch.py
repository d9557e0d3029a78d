#!/usr/bin/env python3
"""Batch throughput and warm starts.

    python tools/bench_batch.py throughput --size 320x448 --bands 64 --frames 17 --iters 10 --workers 0,1,2 --repeat 3
    python tools/bench_batch.py stream --frames 17 --iters 10 --reference-iters 0

``throughput``: frames/s of ``clsdcam batch`` for each worker count (0: in this process; else an
embedded LocalCluster, processes × threads as the batch chooses them), on a simulated video
(``--scene``); the counts run in turn ``--repeat`` times (medians: a busy machine slows them alike),
with the CPU seconds (user, system) of this process and its worker processes. ``stream``: one
warm-started stream's steady state (see :func:`stream`). Both print a markdown table (and ``--json``).
"""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from clsdcam.batch import BatchSpec, run_batch
from clsdcam.batch.spec import COLD_ITERS
from clsdcam.batch.stream import Carried, next_solve
from clsdcam.camera.calibration import Preprocessing, preprocess
from clsdcam.metrics import psnr
from clsdcam.sim.video import simulate_video, write_video
from clsdcam.solve.solver import Settings, Solver


def throughput(args, workdir: Path) -> dict:
    calibration, frames, truth = simulate_video(args.scene, args.frames, args.shape, args.bands, seed=0)
    paths = write_video(workdir, calibration, frames, truth)
    spec = BatchSpec(frames=(str(paths["frames"]),), calibration=str(paths["calibration"]),
                     settings=Settings(iters=args.iters))
    runs = {workers: [] for workers in args.workers}
    for _ in range(args.repeat):
        for workers in args.workers:
            runs[workers].append(_timed_batch(spec, workdir / f"out-{workers}.h5", workers))
            print(f"--workers {workers}: {runs[workers][-1]}", file=sys.stderr, flush=True)
    rows = {workers: {key: statistics.median(run[key] for run in done) if key != "layout" else done[0][key]
                      for key in done[0]} for workers, done in runs.items()}
    _print_throughput(args, rows)
    return {str(k): {**v, "runs": runs[k]} for k, v in rows.items()}


def _timed_batch(spec, output: Path, workers: int) -> dict:
    """One batch from scratch: wall seconds, CPU seconds (user, system: this process and the worker processes it
    started and reaped), the mean solve seconds per frame, and where it ran."""
    before = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    start = time.perf_counter()
    summary = run_batch(spec, output, workers=workers, overwrite=True)
    wall = time.perf_counter() - start
    after = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    with h5py.File(output, "r") as f:
        solve, iterations = float(np.mean(f["seconds"][...])), int(np.sum(f["iterations"][...]))
    return {"seconds": wall, "frames_per_s": summary.n_frames / wall, "solve_s_per_frame": solve,
            "iterations": iterations,
            "user_s": sum(a.ru_utime - b.ru_utime for a, b in zip(after, before)),
            "system_s": sum(a.ru_stime - b.ru_stime for a, b in zip(after, before)), "layout": summary.layout}


def _print_throughput(args, rows: dict):
    first = args.workers[0]
    print(f"{args.bands}×{args.shape[0]}×{args.shape[1]}, {args.frames} frames, --iters {args.iters}; medians of "
          f"{args.repeat} (cluster start and model builds included)")
    print(f"| --workers | ran on | s | frames/s | vs --workers {first} | CPU user s | CPU system s | iterations, all "
          "frames | solve s/frame |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for workers, r in rows.items():
        print(f"| {workers} | {r['layout']} | {r['seconds']:.1f} | {r['frames_per_s']:.3f} | "
              f"{r['frames_per_s'] / rows[first]['frames_per_s']:.2f}× | {r['user_s']:.0f} | {r['system_s']:.1f} | "
              f"{r['iterations']:.0f} | {r['solve_s_per_frame']:.2f} |")


def stream(args, workdir: Path) -> dict:
    """Steady-state frames/s of one warm-started stream (what a batch chunk does: clsdcam.batch.stream.next_solve)
    after its first frame, set-up and first frame timed apart; each frame's PSNR against its truth and against
    a cold ``--reference-iters`` solve of the same frame."""
    calibration, frames, truth = simulate_video(args.scene, args.frames, args.shape, args.bands, seed=0,
                                                drift=args.drift)
    calibration, _ = preprocess(calibration, frames[0], Preprocessing())
    start = time.perf_counter()
    solver = Solver(calibration, backend=args.backend, settings=Settings(iters=args.iters, algorithm=args.algorithm))
    setup = time.perf_counter() - start
    rows, carried = [], Carried()
    for t, frame in enumerate(frames):
        if args.fresh_duals and carried.state is not None:
            carried.state.carry = None          # what a warm start from the cube alone would do
        start = time.perf_counter()
        result = next_solve(solver, frame, carried, (args.cold_iters, args.iters))
        seconds = time.perf_counter() - start
        carried = carried.after(result)
        rows.append({"frame": t, "warm": t > 0, "iterations": result.iterations, "stop": result.stop_reason,
                     "seconds": seconds, "psnr": psnr(result.cube, truth[t])})
    for row in rows if args.reference_iters else ():
        row["cold_psnr"] = psnr(solver.solve(frames[row["frame"]], iters=args.reference_iters).cube, truth[row["frame"]])
    steady = rows[1:]
    summary = {"setup_s": setup, "first_frame_s": rows[0]["seconds"],
               "frames_per_s": len(steady) / sum(r["seconds"] for r in steady),
               "mean_psnr": float(np.mean([r["psnr"] for r in steady])),
               "mean_cold_psnr": float(np.mean([r["cold_psnr"] for r in steady])) if args.reference_iters else None}
    _print_stream(args, rows, summary)
    return {"rows": rows, "summary": summary}


def _print_stream(args, rows, summary):
    cold = [f"cold {args.reference_iters} it. PSNR dB"] if args.reference_iters else []
    fresh = " (fresh duals)" if args.fresh_duals else ""
    print(f"stream: {args.scene} {args.bands}×{args.shape[0]}×{args.shape[1]}, drift {args.drift} px/frame, "
          f"{args.backend}, {args.algorithm}{fresh}; frame 0 cold ({args.cold_iters} it.), then warm (≤ {args.iters} "
          "it.)")
    print("| " + " | ".join(["frame", "iterations (stop)", "s", "PSNR dB", *cold]) + " |")
    print("|" + "---:|" * (4 + len(cold)))
    for r in rows:
        cells = [str(r["frame"]), f"{r['iterations']} ({r['stop']})", f"{r['seconds']:.2f}", f"{r['psnr']:.2f}"]
        cells += [f"{r['cold_psnr']:.2f}"] if cold else []
        print("| " + " | ".join(cells) + " |")
    print(f"\nset-up {summary['setup_s']:.1f} s, first frame {summary['first_frame_s']:.1f} s; steady state "
          f"{summary['frames_per_s']:.2f} frames/s over {len(rows) - 1} frames; mean PSNR {summary['mean_psnr']:.2f} dB"
          + (f" (cold {args.reference_iters} it.: {summary['mean_cold_psnr']:.2f} dB)" if args.reference_iters else ""))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("throughput", "stream"))
    parser.add_argument("--scene", default="leds", help="leds (drifting 1 px/frame) or target (0.5 px/frame)")
    parser.add_argument("--size", default="320x448", help="HxW")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--frames", type=int, default=17, help="frames (stream: the first one, then the steady state)")
    parser.add_argument("--iters", type=int, default=10, help="iterations per frame (stream: per warm frame)")
    parser.add_argument("--cold-iters", type=int, default=COLD_ITERS, help="stream: the first frame's iterations")
    parser.add_argument("--reference-iters", type=int, default=100,
                        help="stream: each frame also solved cold with this many iterations (0: not)")
    parser.add_argument("--drift", default="0.3,0.6", help="stream: the scene's drift, DY,DX px per frame")
    parser.add_argument("--backend", default="numpy", help="stream: numpy or opencl")
    parser.add_argument("--algorithm", default="fista", help="stream: the solver's algorithm (fista or admm)")
    parser.add_argument("--fresh-duals", action="store_true",
                        help="stream: drop what the algorithm carries between frames (ADMM: its duals)")
    parser.add_argument("--workers", default="0,1,2", help="throughput: worker counts, one batch each")
    parser.add_argument("--repeat", type=int, default=1, help="throughput: rounds over the worker counts (medians)")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    args.shape = tuple(int(v) for v in args.size.split("x"))
    args.drift = tuple(float(v) for v in args.drift.split(","))
    args.workers = [int(w) for w in args.workers.split(",")]
    with tempfile.TemporaryDirectory() as workdir:
        result = (throughput if args.what == "throughput" else stream)(args, Path(workdir))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
