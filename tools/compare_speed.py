#!/usr/bin/env python3
"""One solve's seconds on this checkout against another, in alternating pairs: the speed-up of a change as a
ratio measured in one run (the machine's speed drifts ±30 % between runs; a pair's two solves see the same drift).

    python tools/compare_speed.py OLD_CHECKOUT --scene leds --size 320x448 --bands 64 --iters 60 --pairs 4
    python tools/compare_speed.py OLD_CHECKOUT --rank 8 --iters 150
    python tools/compare_speed.py OLD_CHECKOUT --algorithm admm --iters 40

Each solve is a fresh process (``PYTHONPATH`` = the checkout) that simulates the scene, builds the solver (NumPy)
and times ``Solver.solve`` alone; set-up is not in the figure. The first pair warms the file cache and is not
counted. Reported: each pair's seconds and ratio (this checkout / the other), and the median ratio. Pair it with
``tools/compare_recon.py`` to show the cubes did not change.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent.parent


def solve_seconds(args) -> float:
    """The child: one solve of the simulated scene, its seconds."""
    from clsdcam.sim import simulate
    from clsdcam.solve.solver import Settings, Solver

    shape = tuple(int(v) for v in args.size.split("x"))
    sim = simulate(scene=args.scene, shape=shape, n_bands=args.bands, seed=args.seed)
    settings = Settings(iters=args.iters, rank=args.rank, algorithm=args.algorithm)
    solver = Solver(sim.calibration, backend="numpy", settings=settings)
    start = time.perf_counter()
    solver.solve(sim.measurement)
    return time.perf_counter() - start


def child_argv(args) -> list[str]:
    """The solve's options, for the child."""
    return ["--scene", args.scene, "--size", args.size, "--bands", str(args.bands), "--seed", str(args.seed),
            "--rank", str(args.rank), "--algorithm", args.algorithm, "--iters", str(args.iters)]


def run_child(checkout: Path, argv: list[str]) -> float:
    env = dict(os.environ, PYTHONPATH=str(checkout))
    done = subprocess.run([sys.executable, __file__, "--child", *argv], env=env, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"compare_speed: the solve on {checkout} failed:\n{done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])["seconds"]


def compare(args) -> dict:
    """Pairs of solves, this checkout first in odd pairs and second in even ones (neither always warms the other)."""
    old = Path(args.old).resolve()
    if not (old / "clsdcam" / "__init__.py").is_file():
        raise SystemExit(f"compare_speed: {old} holds no clsdcam checkout")
    argv, pairs = child_argv(args), []
    for index in range(args.pairs + 1):
        if index % 2:
            new_s, old_s = run_child(HERE, argv), run_child(old, argv)
        else:
            old_s, new_s = run_child(old, argv), run_child(HERE, argv)
        if index:
            pairs.append((new_s, old_s))
        print(f"pair {index}{' (warm-up)' if not index else ''}: {new_s:.2f} s against {old_s:.2f} s",
              file=sys.stderr)
    ratios = [new / old_s for new, old_s in pairs]
    return {"old": str(old), "pairs": pairs, "ratios": ratios, "median_ratio": float(np.median(ratios))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", nargs="?", help="the other checkout (its root, holding clsdcam/)")
    parser.add_argument("--scene", default="leds")
    parser.add_argument("--size", default="320x448")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rank", type=int, default=0, help="a fixed subspace rank (0: the default's band space)")
    parser.add_argument("--algorithm", default="fista", help="fista or admm")
    parser.add_argument("--iters", type=int, default=60)
    parser.add_argument("--pairs", type=int, default=4)
    parser.add_argument("--json")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps({"seconds": solve_seconds(args)}))
        return 0
    if args.old is None:
        parser.error("the other checkout is required")
    result = compare(args)
    print("| pair | this checkout, s | other, s | ratio |\n|---:|---:|---:|---:|")
    for index, ((new, old), ratio) in enumerate(zip(result["pairs"], result["ratios"]), 1):
        print(f"| {index} | {new:.2f} | {old:.2f} | {ratio:.3f} |")
    print(f"\nmedian ratio (this checkout / {result['old']}): {result['median_ratio']:.3f}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
