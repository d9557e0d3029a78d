#!/usr/bin/env python3
"""What a data-driven weight rule could see: the sweep of fixed TV weights on panel scenes, scored by the truth
(PSNR, spectral angle) and by the two oracle risks that principled rules estimate.

    python tools/weight_oracles.py --seed 3717452930663257581 --only 5,6,7,8,9 --size 128x160 --out oracles

For each fixed weight τ (``--sweep`` points a decade either side of the one ``--tv auto`` chose), after
``--iters`` iterations of the default solver, with e = v̂ − v the error over the whole field:

* predicted risk ‖A·e‖² / ‖A·v‖²: what the discrepancy principle, SURE on the measurement and GCV estimate from
  the data alone;
* projected risk ‖P·e‖² / ‖P·v‖², P = Aᵀ(AAᵀ)⁻¹A the projection onto A's row space (``--cg`` conjugate-gradient
  steps on AAᵀ): what projected SURE estimates (Vonesch, Ramani and Unser 2008; Eldar 2009).

The risks are computed with the truth known (for the projected one a lower bound when the conjugate gradients
stop before ``CG_TOL``). A rule is at best as good as the oracle it estimates: where an oracle's best weight is
not the truth's best (by PSNR), no estimate of that oracle picks the truth's best either. The scenes are the panel's
(``tools/bench_panel.py``: the same seed and index give the same scene). Writes ``oracles.json`` and prints one
table per scene, each score's best weight starred.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from bench_accuracy import panel_parser, save_json
from bench_panel import panel_kinds, panel_scene, scene_indices, scene_plan, sweep_weights
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.metrics import psnr, spectral_angle
from clsdcam.camera.model import ForwardModel
from clsdcam.solve.auto_weights import AUTO_AT
from clsdcam.solve.solver import Settings, Solver

CG_TOL = 1e-8        # relative residual at which the conjugate gradients stop early
SCORES = {"psnr": max, "angle": min, "predicted": min, "projected": min}   # each score's best


def solve(sim, tv, iters: int):
    """The default solver's result at a fixed weight (``tv`` may be "auto"), with its whole field."""
    return Solver(sim.calibration, settings=Settings(iters=iters, tv=tv, full_field=True)).solve(sim.measurement)


def risks(model: ForwardModel, field: np.ndarray, cg_steps: int) -> dict:
    """‖A·x‖² and ‖P·x‖² = (Ax)ᵀ(AAᵀ)⁻¹(Ax) of a field x (an error, or the truth they are relative to)."""
    y = model.forward(field)
    return {"predicted": float(np.vdot(y, y)), "projected": float(np.vdot(y, normal_solve(model, y, cg_steps)))}


def normal_solve(model: ForwardModel, y: np.ndarray, steps: int, tol: float = CG_TOL) -> np.ndarray:
    """z ≈ (AAᵀ)⁻¹y by at most ``steps`` conjugate-gradient steps from 0, fewer once ‖r‖ ≤ tol·‖y‖ (yᵀz grows
    monotonically to yᵀ(AAᵀ)⁻¹y: a truncated solve gives a lower bound)."""
    z, r = np.zeros_like(y), y.copy()
    p, rr = r.copy(), float(np.vdot(r, r))
    stop = tol ** 2 * rr
    for _ in range(steps):
        if rr <= stop:
            break
        ap = model.forward(model.adjoint(p))
        alpha = rr / float(np.vdot(p, ap))
        z += alpha * p
        r -= alpha * ap
        rr, previous = float(np.vdot(r, r)), rr
        p = r + (rr / previous) * p
    return z


def scene_sweep(sim, points: int, iters: int, cg_steps: int) -> dict:
    """The automatic weight (chosen by iteration AUTO_AT, so the solve stops there), then every fixed weight's truth
    scores and oracle risks, each relative to the truth's own."""
    auto = solve(sim, "auto", min(iters, AUTO_AT + 1))
    model = ForwardModel(NumpyBackend("float64"), sim.calibration.psf, sim.calibration.filters)
    truth = model.embed(sim.truth)
    reference = risks(model, truth, cg_steps)
    rows = []
    for tau in sweep_weights(auto.attrs["tv_chosen"], points):
        result = solve(sim, tau, iters)
        error = risks(model, result.full_field.astype(np.float64) - truth, cg_steps)
        rows.append({"tv": tau, "psnr": psnr(result.cube, sim.truth), "angle": spectral_angle(result.cube, sim.truth),
                     **{key: error[key] / reference[key] for key in reference}})
    return {"tv_chosen": auto.attrs["tv_chosen"], "rows": rows}


def table(scene: dict) -> str:
    rows = scene["rows"]
    best = {key: pick(range(len(rows)), key=lambda i: rows[i][key]) for key, pick in SCORES.items()}
    lines = [f"scene {scene['index']} ({scene['kind']}, {scene['level']}), --tv auto chose {scene['tv_chosen']:.3g}:",
             "| τ | PSNR dB | SA ° | predicted risk | projected risk |", "|---:|---:|---:|---:|---:|"]
    for i, row in enumerate(rows):
        cells = [f"{row[key]:.2f}" if key in ("psnr", "angle") else f"{row[key]:.3e}" for key in SCORES]
        lines.append(f"| {row['tv']:.3g} | " + " | ".join(c + ("*" if best[key] == i else "")
                                                        for c, key in zip(cells, SCORES)) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "oracles", named_scenes=False)
    parser.set_defaults(size=(128, 160))
    parser.add_argument("--seed", type=int, required=True, help="the panel's seed")
    parser.add_argument("--only", type=scene_indices, required=True, help="the panel's scene indices, e.g. 5,6,9")
    parser.add_argument("--iters", type=int, default=300)
    parser.add_argument("--sweep", type=int, default=5, help="fixed weights a decade either side")
    parser.add_argument("--cg", type=int, default=100, help="conjugate-gradient steps per projection")
    args = parser.parse_args(argv)
    indices = args.only
    plans = scene_plan(max(indices) + 1, args.seed, panel_kinds())
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"seed": args.seed, "iters": args.iters, "cg": args.cg, "scenes": []}
    for index in indices:
        plan = plans[index]
        scene = {"index": index, **plan, **scene_sweep(panel_scene(plan, args.size, args.bands), args.sweep,
                                                         args.iters, args.cg)}
        results["scenes"].append(scene)
        save_json(out, "oracles", results)
        print(table(scene) + "\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
