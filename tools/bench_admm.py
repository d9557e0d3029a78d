#!/usr/bin/env python3
"""ADMM's penalties swept on one scene, beside FISTA ``--no-skip`` on the same scene: PSNR and mean spectral angle at
marks, so the relative penalties (``clsdcam.algorithms.admm``: DATA, TV, NONNEG) are chosen by error, not guessed.

    python tools/bench_admm.py --kind piecewise --seed 1 --size 64x96 --bands 16 --iters 100 \\
        --data 0.003,0.01,0.03 --tv 1e-3,1e-2 --nonneg 1e-3,1e-2

Every combination of the three lists is one ADMM run (the module's values are restored after); the scene is a random
scene of ``--kind`` (:mod:`clsdcam.sim.kinds`) drawn from ``--seed``, or the demo's ``target``. Prints one row per run
with PSNR / angle at each mark and writes them to ``--json`` when given. Choose on one scene, then judge the choice
on fresh ones (``tools/bench_panel.py --also 'algorithm admm'``).
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
import time

from bench_accuracy import scene_points, size_text, solve
from clsdcam.algorithms.admm import algorithm as admm
from clsdcam.cli.options import size
from clsdcam.sim import band_wavelengths, simulate
from clsdcam.sim.kinds import make_kind


def values(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v]


def scene(kind: str, seed: int, shape, bands: int):
    cube = None if kind == "target" else make_kind(kind, shape, band_wavelengths(bands), seed)
    return simulate(scene=kind if cube is None else f"kind:{kind}", shape=shape, n_bands=bands, seed=seed, cube=cube)


def run(sim, fields: dict, marks) -> dict:
    start = time.perf_counter()
    snapshots, attrs = solve(sim.calibration, sim.measurement, fields, marks)
    return {"points": scene_points("", sim, snapshots), "tv_chosen": attrs["tv_chosen"],
            "seconds": time.perf_counter() - start}


def row(name: str, result: dict) -> str:
    cells = " | ".join(f"{p['psnr']:.2f} / {p['angle']:.2f}" for p in result["points"])
    return f"| {name} | {cells} | {result['seconds']:.1f} |"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kind", default="piecewise", help="a kind of clsdcam.sim.kinds, or target")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--size", type=size(), default="64x96", metavar="HxW")
    parser.add_argument("--bands", type=int, default=16)
    parser.add_argument("--iters", type=int, default=100)
    parser.add_argument("--marks", default="10,30,50,100")
    parser.add_argument("--data", type=values, default=[admm.DATA])
    parser.add_argument("--tv", type=values, default=[admm.TV])
    parser.add_argument("--nonneg", type=values, default=[admm.NONNEG])
    parser.add_argument("--relaxation", type=values, default=[admm.RELAXATION], help="over-relaxation α values")
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    marks = sorted({int(m) for m in args.marks.split(",") if int(m) <= args.iters} | {args.iters})
    sim = scene(args.kind, args.seed, args.size, args.bands)
    print(f"{args.kind}, seed {args.seed}, {size_text(args.size)}×{args.bands}: PSNR (dB) / mean spectral angle (°)")
    print("| run | " + " | ".join(f"{m}" for m in marks) + " | s |\n|---|" + "---|" * (len(marks) + 1))
    results = {"fista --no-skip": run(sim, {"skip": False}, marks)}
    print(row("fista --no-skip", results["fista --no-skip"]), flush=True)
    saved = (admm.DATA, admm.TV, admm.NONNEG, admm.RELAXATION)
    try:
        for data, tv, nonneg, alpha in itertools.product(args.data, args.tv, args.nonneg, args.relaxation):
            admm.DATA, admm.TV, admm.NONNEG, admm.RELAXATION = data, tv, nonneg, alpha
            name = f"admm DATA={data:g} TV={tv:g} NONNEG={nonneg:g} α={alpha:g}"
            results[name] = run(sim, {"algorithm": "admm"}, marks)
            print(row(name, results[name]), flush=True)
    finally:
        admm.DATA, admm.TV, admm.NONNEG, admm.RELAXATION = saved
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"kind": args.kind, "seed": args.seed, "marks": marks, "runs": results}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
