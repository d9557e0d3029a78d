#!/usr/bin/env python3
"""Sweep the TV weight on a simulated scene: PSNR and mean spectral angle at a few iteration counts.

    python tools/sweep_tv.py --size 128x160 --bands 64 --scene target --iters 300 --tv 1e-4,3e-4,1e-3,3e-3,1e-2

Prints one markdown row per weight (this is how DEFAULT_TV was chosen; see the README).
"""
from __future__ import annotations

import argparse
import time

from clsdcam.metrics import psnr, spectral_angle
from clsdcam.sim import simulate
from clsdcam.solve.solver import Settings, Solver

MARKS = (50, 100, 200, 300, 500, 1000)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="128x160")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--scene", default="target")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--iters", type=int, default=300)
    parser.add_argument("--tv", default="1e-4,3e-4,1e-3,3e-3,1e-2")
    parser.add_argument("--backend", default="numpy")
    args = parser.parse_args(argv)
    shape = tuple(int(v) for v in args.size.split("x"))
    sim = simulate(scene=args.scene, shape=shape, n_bands=args.bands, seed=args.seed)
    marks = [m for m in MARKS if m <= args.iters]
    print(f"scene {args.scene} {args.bands}×{shape[0]}×{shape[1]}, seed {args.seed}, backend {args.backend}")
    print("| tv | s/iteration | " + " | ".join(f"{m} it: PSNR dB / SA °" for m in marks) + " |")
    print("|---|---:|" + "---|" * len(marks))
    for tv in (float(t) for t in args.tv.split(",")):
        solver = Solver(sim.calibration, backend=args.backend, settings=Settings(iters=args.iters, tv=tv))
        start = time.perf_counter()
        result = solver.solve(sim.measurement, snapshots=marks)
        per_iteration = (time.perf_counter() - start) / args.iters
        cells = [f"{psnr(c, sim.truth):.2f} / {spectral_angle(c, sim.truth):.1f}" for _, c in sorted(result.snapshots.items())]
        print(f"| {tv:g} | {per_iteration:.3f} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
