#!/usr/bin/env python3
"""The automatic stop's estimate against the true distance: how far ADMM's iterate really is from the model's answer
where ``--iters auto`` would stop it, on the panel's scenes (:mod:`bench_converged`'s, with its cached references).

    python tools/bench_stop.py --size 64x80 --bands 32 --scenes 10 --seed S --weight-from today --out stop

Per scene, at its weight τ: ADMM runs ``--iters`` iterations at τ, its cube kept every ``--every``. Each kept cube
x_k is scored against the truth (within the rules of bench_converged against its reference, or not) and against
x*, the ADMM reference's final cube: the true relative distance ‖x_k − x*‖/‖x*‖. Two estimates of that distance,
both the geometric tail of :class:`clsdcam.solve.convergence.DistanceEstimate` over windows of W = 25 iterations,
are replayed on the run:

* **steps** (the stop's): each window's summed relative steps Σ‖x_{i+1} − x_i‖/‖x_{i+1}‖;
* **net**: each window's net move ‖x_end − x_start‖/‖x_end‖ (what a stop would get for one cube more).

Both carry the estimate's two guards (its first readings withheld, and its fallback on windows twice as long: for
**net**, two consecutive net moves added, not the net move over 2W).

The table gives, per scene, the mark from which the run stays within the rules and its true distance there, the
reference's own error ‖x* − truth‖/‖x*‖ and that distance over the error (what the rules need, in units of the
reconstruction's error); and per estimate and ``--tolerances`` value, the iteration where that estimate first
falls below it, the true distance then, and whether the run is within the rules from there on. Writes
``stop.json``, ``stop.md`` and ``stop.png`` (the true distance and both estimates against iterations, one panel a
scene). The run is at a fixed τ from its first iteration (the default's own run chooses τ at iteration 30 and
forgets its windows there); at iteration 30 it is told what the default's probe found (a point-like scene, a few
points), and at 180 what its recount found (lit spots, or a few points to lighten:
``bench_converged.told_point_like``), so its penalties are the default's.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from bench_accuracy import Where, add_backend_option, panel_parser, report, size_text
from bench_converged import (REFERENCE_ALGORITHMS, add_panel_options, reference, reference_cube, reference_run,
                             scene_weight, settled_within, timed_solve, told_point_like, within)
from bench_panel import chosen_scenes, panel_scene, scene_done
from clsdcam.metrics import psnr, spectral_angle
from clsdcam.render import new_figure
from clsdcam.solve.convergence import WINDOW, DistanceEstimate

ESTIMATES = ("steps", "net")


def relative(a: np.ndarray, b: np.ndarray) -> float:
    """‖a − b‖/‖b‖ in float64."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def replay(values, window: int) -> list[float]:
    """The estimate after each value fed to a :class:`DistanceEstimate` of ``window`` (inf until it has one)."""
    estimate = DistanceEstimate(window)
    out = []
    for value in values:
        estimate.add(value)
        out.append(estimate.distance)
    return out


def traced_run(sim, tau: float, iters: int, every: int, xstar: np.ndarray, ref: dict) -> list[dict]:
    """ADMM at ``tau`` for ``iters``: per kept cube (every ``every``) its iteration, true distance to ``xstar``,
    whether it is within the rules of ``ref``, and both estimates (NaN between window ends)."""
    result, _ = timed_solve(sim, {"tv": tau, "iters": iters, "algorithm": "admm"}, range(every, iters + 1, every))
    steps = replay([r["change"] for r in result.history], WINDOW)
    ends = [k for k in sorted(result.snapshots) if k % WINDOW == 0]
    moves = [relative(result.snapshots[k], result.snapshots[k - WINDOW]) for k in ends[1:]]
    net = dict(zip(ends[1:], replay(moves, 1)))
    marks = []
    for k, cube in sorted(result.snapshots.items()):
        mark = {"iteration": k, "psnr": psnr(cube, sim.truth), "angle": spectral_angle(cube, sim.truth),
                "distance": relative(cube, xstar), "steps": steps[k - 1] if k % WINDOW == 0 else float("nan"),
                "net": net.get(k, float("nan"))}
        marks.append({**mark, "within": within(mark, ref)})
    return marks


def settled(marks: list[dict], ref: dict) -> dict | None:
    """The first mark from which every mark is within the rules (:func:`bench_converged.settled_within`), or None."""
    iteration = settled_within(marks, ref)
    return next((m for m in marks if m["iteration"] == iteration), None)


def stop(marks: list[dict], name: str, tolerance: float) -> dict | None:
    """Where estimate ``name`` first falls below ``tolerance``: the mark, and whether every mark from it is within."""
    for i, mark in enumerate(marks):
        if mark[name] < tolerance:
            return {**mark, "stays_within": all(n["within"] for n in marks[i:])}
    return None


def scene_answer(plan: dict, args, cache: Path) -> tuple:
    """A panel scene at its weight: (its simulation, τ, what the default's probe read, the reference, x* = the ADMM
    reference's final cube), the references run where ``cache`` lacks them."""
    sim = panel_scene(plan, args.size, args.bands)
    tau, probe = scene_weight(sim, args.weight_from)
    ref = reference({a: reference_run(sim, plan, tau, a, args.reference_iters, cache)
                     for a in REFERENCE_ALGORITHMS})
    return sim, tau, probe, ref, reference_cube(sim, plan, tau, "admm", args.reference_iters, cache)


def run_scene(plan: dict, args, cache: Path) -> dict:
    sim, tau, probe, ref, xstar = scene_answer(plan, args, cache)
    with told_point_like(**probe):
        marks = traced_run(sim, tau, args.iters, args.every, xstar, ref)
    return {**plan, "tv": tau, "reference": ref, "error": relative(sim.truth, xstar), "marks": marks,
            "settled": settled(marks, ref),
            "stops": {name: [stop(marks, name, t) for t in args.tolerances] for name in ESTIMATES}}


def stop_cell(found: dict | None) -> str:
    if found is None:
        return "–"
    return f"{found['iteration']}: {found['distance']:.3f} {'within' if found['stays_within'] else 'OUT'}"


def markdown(results: dict) -> str:
    tolerances = results["tolerances"]
    head = [f"Seed {results['seed']}, {results['size']}×{results['bands']}, ADMM {results['iters']} iterations at "
            f"the weight {results['weight_from']}'s `--tv auto` chose; references {results['reference_iters']} "
            "iterations. Cells: the iteration where the estimate first falls below the tolerance, the true relative "
            "distance to the reference cube there, and whether the run is within the rules from there on.", "",
            "| # | kind | stays within from | true distance there | reference's error | distance over error | "
            + " | ".join(f"{name} at {t:g}" for name in ESTIMATES for t in tolerances) + " |",
            "|---:|---|---|---|---:|---:|" + "---|" * (len(ESTIMATES) * len(tolerances))]
    rows = []
    for s in results["scenes"]:
        first = s["settled"]
        needed = first["distance"] if first else float("nan")
        cells = [stop_cell(found) for name in ESTIMATES for found in s["stops"][name]]
        rows.append(f"| {s['index']} | {s['kind']}, {s['level']} | {first['iteration'] if first else '–'} | "
                    f"{needed:.3f} | {s['error']:.3f} | {needed / s['error']:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(head + rows)


def scene_grid(count: int, per_row: int):
    """A figure of ``count`` panels of 3.2×2.8 inches, ``per_row`` to a row, and their axes (the grid's spare ones
    hidden)."""
    columns, rows = min(count, per_row), -(-count // per_row)
    fig = new_figure(figsize=(3.2 * columns, 2.8 * rows))
    axes = np.array(fig.subplots(rows, columns, squeeze=False)).ravel()
    for ax in axes[count:]:
        ax.set_visible(False)
    return fig, axes[:count]


def save_grid(fig, results: dict, what: str, path: Path):
    """A :func:`scene_grid` figure titled with its panel (seed, size) and ``what`` it shows, saved to ``path``."""
    fig.suptitle(f"Seed {results['seed']}, {results['size']}×{results['bands']}: {what}", fontsize=10)
    fig.savefig(path, dpi=90)


def plot(results: dict, path: Path, per_row: int = 5):
    """Every scene's true distance and both estimates against iterations (log), the settled mark dashed."""
    scenes = results["scenes"]
    fig, axes = scene_grid(len(scenes), per_row)
    for ax, scene in zip(axes, scenes):
        marks = scene["marks"]
        ax.semilogy([m["iteration"] for m in marks], [m["distance"] for m in marks], "k", label="true distance")
        for name in ESTIMATES:
            points = [(m["iteration"], m[name]) for m in marks if np.isfinite(m[name])]
            if points:
                ax.semilogy(*zip(*points), ".-", ms=3, label=f"{name} estimate")
        if scene["settled"]:
            ax.axvline(scene["settled"]["iteration"], color="0.5", ls="--", label="within the rules from")
        ax.set(title=f"{scene['index']}: {scene['kind']}, {scene['level']}", xlabel="iteration",
               ylabel="relative distance")
    axes[0].legend(fontsize=7, framealpha=0.5)
    save_grid(fig, results, "the stop's estimates against the true distance to the reference", path)


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "stop", named_scenes=False)
    parser.set_defaults(size=(64, 80), bands=32)
    add_panel_options(parser, scenes=10, reference_iters=1500, weight_from="today", seed_required=True)
    parser.add_argument("--iters", type=int, default=600, help="the traced run's iterations (default 600)")
    parser.add_argument("--every", type=int, default=5, help="keep a cube every this many (divides 25; default 5)")
    parser.add_argument("--tolerances", default="0.07,0.05,0.03", help="the estimates' stopping tolerances")
    add_backend_option(parser)
    args = parser.parse_args(argv)
    if WINDOW % args.every:
        parser.error(f"--every {args.every} must divide the stop's window ({WINDOW})")
    Where.use(args.backend)
    args.tolerances = [float(t) for t in args.tolerances.split(",")]
    chosen = chosen_scenes(parser, args, args.seed)
    out, cache = Path(args.out), Path(args.cache)
    out.mkdir(parents=True, exist_ok=True)
    cache.mkdir(parents=True, exist_ok=True)
    results = {"seed": args.seed, "size": size_text(args.size), "bands": args.bands, "iters": args.iters,
               "reference_iters": args.reference_iters, "weight_from": args.weight_from,
               "tolerances": args.tolerances, "scenes": []}
    for i, plan in chosen:
        results["scenes"].append({"index": i, **run_scene(plan, args, cache)})
        scene_done(i, plan, args.scenes)
    report(out, "stop", results, markdown(results))
    plot(results, out / "stop.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
