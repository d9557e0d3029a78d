#!/usr/bin/env python3
"""The demo's scene (``clsdcam demo``: the resolution target under red, green, blue and white light) solved by each
algorithm: PSNR, mean spectral angle and the bar detail each quadrant keeps, against iterations and seconds.

    python tools/bench_demo.py --iters 300 --marks 50,100,150,300 --configs fista,admm

Bar detail (:func:`clsdcam.metrics.bar_detail`): the band-summed image minus its 9-px local mean, correlated with the
truth's over each quadrant's lit box, quadrants in the order red, green, blue, white. Seconds are from the solver's
history (set-up not included), one configuration after the other in one process.
"""
from __future__ import annotations

import argparse
import json
import sys

from bench_accuracy import Where, add_backend_option, size_text
from clsdcam.cli.options import size
from clsdcam.metrics import bar_detail, psnr, spectral_angle
from clsdcam.sim import simulate
from clsdcam.sim.scenes import in_window, inner_shape, quadrant_masks
from clsdcam.solve.solver import Settings, Solver

CONFIGS = {"fista": {}, "fista --no-skip": {"skip": False}, "admm": {"algorithm": "admm"}}
QUADRANTS = ("red", "green", "blue", "white")


def measure(sim, fields: dict, marks) -> list[dict]:
    settings = Settings(iters=max(marks), **fields)
    result = Solver(sim.calibration, backend=Where.backend, settings=settings).solve(sim.measurement, snapshots=marks)
    masks = in_window(sim.truth.shape[1:], quadrant_masks(inner_shape(sim.truth.shape[1:])))
    return [{"iteration": k, "seconds": result.history[k - 1]["seconds"], "psnr": psnr(cube, sim.truth),
             "angle": spectral_angle(cube, sim.truth), "detail": bar_detail(cube, sim.truth, masks)}
            for k, cube in sorted(result.snapshots.items())]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=size(), default="320x448", metavar="HxW")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--marks", default="50,100,150,300")
    parser.add_argument("--configs", default="fista,admm", help=f"from {', '.join(CONFIGS)}")
    parser.add_argument("--json", default=None)
    add_backend_option(parser)
    args = parser.parse_args(argv)
    Where.use(args.backend)
    marks = sorted(int(m) for m in args.marks.split(","))
    sim = simulate("target", shape=args.size, n_bands=args.bands)
    print(f"target, {size_text(args.size)}×{args.bands}, backend {args.backend}")
    print("| configuration | iterations | s | PSNR dB | SA ° | bar detail " + " / ".join(QUADRANTS) + " |\n"
          "|---|---:|---:|---:|---:|---|")
    results = {}
    for name in args.configs.split(","):
        results[name] = measure(sim, CONFIGS[name], marks)
        for p in results[name]:
            print(f"| {name} | {p['iteration']} | {p['seconds']:.1f} | {p['psnr']:.2f} | {p['angle']:.2f} | "
                  + " / ".join(f"{d:.2f}" for d in p["detail"]) + " |", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"size": size_text(args.size), "bands": args.bands, "backend": args.backend, "runs": results}, f,
                      indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
