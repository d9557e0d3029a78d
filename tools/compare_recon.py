#!/usr/bin/env python3
"""Reconstructions before and after a change: record cubes, rank histories and stop reasons, then compare two
recordings (relative L2 per cube; iterations, stop reason, rank history, final step, chosen weight and skip report
equal).

    python tools/compare_recon.py record before.npz            # on the old code (PYTHONPATH=its checkout)
    python tools/compare_recon.py record after.npz
    python tools/compare_recon.py compare before.npz after.npz  # exit 1 when a cube differs beyond --tol

Runs: the accuracy panel's six scenes at ``--size`` (128×160×64) with the default, ``--no-skip``,
``--subspace``, ``--rank 8`` and ``--algorithm admm``, ``--iters`` (300) iterations each; the LED grid at ``--full-size`` (320×448)
with the default and ``--no-skip``; a warm-started stream (the LED grid drifting, ``--frames`` frames, default
and ``--subspace``, as a batch chunk runs it: ``clsdcam.batch.stream.next_solve``).
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

SCENES = ("target", "leds", "piecewise", "realcube", "sources", "lines")
CONFIGS = {"default": {}, "no-skip": {"skip": False}, "subspace": {"subspace": True}, "rank8": {"rank": 8},
           "admm": {"algorithm": "admm"}}
FULL_CONFIGS = ("default", "no-skip")
STREAM_CONFIGS = ("default", "subspace")


def digest(result) -> dict:
    """What must not change besides the cube: iterations, stop reason, ranks, steps, weights, skip lines."""
    attrs = result.attrs
    return {"iterations": result.iterations, "stop": result.stop_reason,
            "ranks": [r["rank"] for r in result.history], "final_step": attrs["final_step"],
            "tv_chosen": attrs.get("tv_chosen"), "skips": attrs["skips"]}


def solve_scene(scene, shape, bands, iters, configs, cubes, meta, tag):
    from clsdcam.sim import simulate
    from clsdcam.solve.solver import Settings, Solver

    sim = simulate(scene=scene, shape=shape, n_bands=bands, seed=0)
    for name in configs:
        result = Solver(sim.calibration, settings=Settings(iters=iters, **CONFIGS[name])).solve(sim.measurement)
        key = f"{tag}/{scene}/{name}"
        cubes[key], meta[key] = result.cube, digest(result)
        print(f"  {key}: {result.iterations} it., {result.stop_reason}", file=sys.stderr, flush=True)


def solve_stream(shape, bands, frames, iters, cubes, meta):
    from clsdcam.batch.stream import Carried, next_solve
    from clsdcam.camera.calibration import Preprocessing, preprocess
    from clsdcam.batch.spec import COLD_ITERS
    from clsdcam.sim.video import simulate_video
    from clsdcam.solve.solver import Settings, Solver

    calibration, video, _ = simulate_video("leds", frames, shape, bands, seed=0, drift=(0.3, 0.6))
    calibration, _ = preprocess(calibration, video[0], Preprocessing())
    for name in STREAM_CONFIGS:
        solver, carried = Solver(calibration, settings=Settings(iters=iters, **CONFIGS[name])), Carried()
        for t, frame in enumerate(video):
            result = next_solve(solver, frame, carried, (COLD_ITERS, iters))
            carried = carried.after(result)
            key = f"stream/{name}/{t}"
            cubes[key], meta[key] = result.cube, digest(result)
            print(f"  {key}: {result.iterations} it., {result.stop_reason}", file=sys.stderr, flush=True)


def record(args) -> int:
    cubes, meta = {}, {}
    for scene in args.scenes.split(","):
        solve_scene(scene, args.size, args.bands, args.iters, CONFIGS, cubes, meta, "panel")
    if args.full_size:
        solve_scene("leds", args.full_size, args.bands, args.iters, FULL_CONFIGS, cubes, meta, "full")
    solve_stream(args.size, args.bands, args.frames, 10, cubes, meta)
    np.savez_compressed(args.path, meta=json.dumps(meta), **{k.replace("/", "|"): v for k, v in cubes.items()})
    return 0


def load(path):
    with np.load(path) as data:
        return json.loads(str(data["meta"])), {k.replace("|", "/"): data[k] for k in data.files if k != "meta"}


def compare(args) -> int:
    (meta_a, cubes_a), (meta_b, cubes_b) = load(args.a), load(args.b)
    failed = 0
    for key in sorted(set(cubes_a) | set(cubes_b)):
        if key not in cubes_a or key not in cubes_b:
            print(f"{key}: only in one recording")
            failed += 1
            continue
        a, b = cubes_a[key].astype(np.float64), cubes_b[key].astype(np.float64)
        rel = np.linalg.norm(a - b) / max(np.linalg.norm(a), 1e-300)
        same = {field: meta_a[key][field] == meta_b[key][field] for field in meta_a[key]}
        ok = rel <= args.tol and all(same.values())
        failed += not ok
        print(f"{key}: relative L2 {rel:.2e}{' (bit-identical)' if rel == 0 else ''}; "
              f"{meta_b[key]['iterations']} it. {meta_b[key]['stop']}; "
              f"{'same' if all(same.values()) else 'differs: ' + ','.join(f for f, v in same.items() if not v)}"
              f"{'' if ok else '  <-- FAIL'}")
    print(f"{len(cubes_a)} runs compared, {failed} failed (tolerance {args.tol:g})")
    return 1 if failed else 0


def main(argv=None) -> int:
    from clsdcam.cli.options import size

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("path")
    rec.add_argument("--size", type=size(), default="128x160")
    rec.add_argument("--full-size", type=lambda text: size()(text) if text else None, default="320x448",
                     help="the LED grid's size ('' for none)")
    rec.add_argument("--scenes", default=",".join(SCENES))
    rec.add_argument("--bands", type=int, default=64)
    rec.add_argument("--iters", type=int, default=300)
    rec.add_argument("--frames", type=int, default=5)
    cmp_ = sub.add_parser("compare")
    cmp_.add_argument("a")
    cmp_.add_argument("b")
    cmp_.add_argument("--tol", type=float, default=1e-5, help="relative L2 a cube may differ by (the issue's 1e-5; "
                      "0 for bit-identical)")
    args = parser.parse_args(argv)
    return record(args) if args.what == "record" else compare(args)


if __name__ == "__main__":
    sys.exit(main())
