#!/usr/bin/env python3
"""Where the default's automatic stop lands against the answer its own trajectory converges to: rule 2 of
docs/convergence.md in substance, without the 3000-iteration references (whose FISTA and ADMM may themselves be
short of the answer on slow scenes).

    python tools/bench_answer.py --size 96x112 --bands 32 --scenes 12 --kinds points,sources --seed S --iters 6000

Per scene, the default's solve (ADMM, ``--tv auto`` and its probe at iteration AUTO_AT) runs ``--iters`` iterations
with no stop, its cube scored every 25 (where the stop's windows close: 55, 80, …) and at the cap (every kept cube
is held until the end, 240 of them at 6000 iterations). The *answer* is the last cube scored (5980 of 6000): its PSNR
and mean spectral angle, and how far they moved over the last 1000 iterations (a check that it is one). The stop's
estimate (:class:`clsdcam.solve.convergence.DistanceEstimate`, started afresh at AUTO_AT as the default's is, and
at RECOUNT_AT where its recount changed the road) is replayed on the run, at most AUTO_CAP iterations:

* at the tolerances ``--converge auto`` takes from the run's probe and, after RECOUNT_AT, its recount
  (:func:`clsdcam.solve.auto_weights.probed_tolerance`): where the default stops;
* at each of ``--tolerances``;
* "needs": the widest tolerance of the grid 0.05·2^(−k/8) whose stop is within.

A stop is *within* where it is at most 0.2 dB below the answer's PSNR and at most 0.5° above its angle. Writes
``answer.json``, ``answer.md`` and ``answer.png`` (each scene's PSNR short of its answer against iterations, the
default's stop marked).
"""
from __future__ import annotations

import sys
from pathlib import Path

from bench_accuracy import Where, add_backend_option, panel_parser, report, size_text
from bench_converged import curve, timed_solve, within
from bench_panel import add_kinds_option, chosen_scenes, panel_scene, scene_done, scene_indices
from bench_stop import replay, save_grid, scene_grid
from clsdcam.algorithms.admm.algorithm import POINT_LIKE_BELOW
from clsdcam.solve.auto_weights import AUTO_AT, RECOUNT_AT, probe_reading, probed_tolerance, recount_reroutes
from clsdcam.solve.convergence import WINDOW
from clsdcam.solve.settings import AUTO_CAP, CONVERGE, CONVERGE_WIDE

GRID = [0.05 * 2 ** (-k / 8) for k in range(80)]      # "needs": 0.05 down to about 5e-5
SETTLED_OVER = 1000                                   # the answer's drift is read over its last this many iterations


def default_run(sim, iters: int) -> tuple[dict, list[dict]]:
    """The default's trajectory without a stop: its attributes, and its marks every WINDOW iterations from
    AUTO_AT + WINDOW (where the stop's windows close) and at AUTO_CAP, each with PSNR, angle and the stop's estimate
    there (at the cap, the last closed window's)."""
    marks = sorted({*range(AUTO_AT + WINDOW, iters + 1, WINDOW), *([AUTO_CAP] if AUTO_CAP <= iters else [])})
    result, _ = timed_solve(sim, {"iters": iters, "algorithm": "admm"}, marks)
    changes = [r["change"] for r in result.history]
    starts = [AUTO_AT] + ([RECOUNT_AT] if recount_reroutes(result.attrs, POINT_LIKE_BELOW) else [])   # its estimate's
    estimates = {start: replay(changes[start:], WINDOW) for start in starts}
    points = curve(sim, result)
    for point in points:
        start = max(s for s in starts if s < point["iteration"])
        point["estimate"] = estimates[start][point["iteration"] - start - 1]
    return result.attrs, points


def stop(points: list[dict], answer: dict, tolerance: float, recounted: float | None = None) -> dict:
    """Where the replayed stop at ``tolerance`` ends (its first mark below it, else the cap's), how far short of
    ``answer`` it is there, and whether that is within; marks after RECOUNT_AT read ``recounted`` where it is given
    (the default's stop reads its mark at RECOUNT_AT before the recount acts)."""
    def reading(point: dict) -> float:
        return tolerance if recounted is None or point["iteration"] <= RECOUNT_AT else recounted

    capped = [p for p in points if p["iteration"] <= AUTO_CAP]
    end = next((p for p in capped if p["estimate"] < reading(p)), capped[-1])
    return {"tolerance": reading(end), "iteration": end["iteration"], "converged": end["estimate"] < reading(end),
            "short_db": answer["psnr"] - end["psnr"], "over_deg": end["angle"] - answer["angle"],
            "within": within(end, answer)}


def run_scene(plan: dict, args) -> dict:
    sim = panel_scene(plan, args.size, args.bands)
    attrs, points = default_run(sim, args.iters)
    answer, before = points[-1], next(p for p in points if p["iteration"] >= points[-1]["iteration"] - SETTLED_OVER)
    point_like, few_points, lighter = probe_reading(attrs, POINT_LIKE_BELOW)
    default = [probed_tolerance(attrs, POINT_LIKE_BELOW, CONVERGE, CONVERGE_WIDE, recounted)
               for recounted in (False, True)]
    return {**plan, "tv": attrs["tv_chosen"], "lit_voxels": attrs["lit_voxels"],
            "lit_per_pixel": attrs["lit_per_pixel"], "point_like": point_like, "few_points": few_points,
            "lighter": lighter, "noise": attrs["noise_estimate"],
            "answer": {"psnr": answer["psnr"], "angle": answer["angle"], "drift_db": answer["psnr"] - before["psnr"],
                       "drift_deg": answer["angle"] - before["angle"]},
            "default": stop(points, answer, *default), "stops": [stop(points, answer, t) for t in args.tolerances],
            "needs": next((s for s in (stop(points, answer, t) for t in GRID) if s["within"]), None),
            "marks": points}


def run_and_say(index: int, plan: dict, args) -> dict:
    """Scene ``index`` of the panel, run and scored; its progress line said."""
    scene = {"index": index, **run_scene(plan, args)}
    scene_done(index, plan, args.scenes)
    return scene


def stop_cell(found: dict | None) -> str:
    if found is None:
        return "none in the grid"
    end = f"{found['iteration']}" + ("" if found["converged"] else " (cap)" if found["iteration"] == AUTO_CAP
                                     else " (the run's end)")
    return (f"{end}: {0.0 - found['short_db']:+.2f} dB / {found['over_deg']:+.2f}°"
            + ("" if found["within"] else " **out**"))


def markdown(results: dict) -> str:
    tolerances = results["tolerances"]
    head = [f"Seed {results['seed']}, {results['size']}×{results['bands']}: the default's trajectory run "
            f"{results['iters']} iterations; the answer is its last cube. Cells: where the stop ends (cap "
            f"{AUTO_CAP}), and its PSNR / angle against the answer's (within: ≥ −0.2 dB and ≤ +0.5°).", "",
            "| # | kind | n (a pixel) | answer | its drift over the last 1000 | default's stop | "
            + " | ".join(f"at {t:g}" for t in tolerances) + " | needs |",
            "|---:|---|---:|---|---|---|" + "---|" * len(tolerances) + "---|"]
    rows = []
    for s in results["scenes"]:
        a, needs = s["answer"], s["needs"]
        rows.append(f"| {s['index']} | {s['kind']}, {s['level']} | {s['lit_voxels']:.0f} ({s['lit_per_pixel']:.3g}) | "
                    f"{a['psnr']:.2f} dB / {a['angle']:.2f}° | {a['drift_db']:+.2f} dB / {a['drift_deg']:+.2f}° | "
                    f"{s['default']['tolerance']:.2g} → {stop_cell(s['default'])} | "
                    + " | ".join(stop_cell(found) for found in s["stops"])
                    + f" | {'–' if needs is None else format(needs['tolerance'], '.2g')} |")
    within = sum(s["default"]["within"] for s in results["scenes"])
    iterations = sum(s["default"]["iteration"] for s in results["scenes"])
    return "\n".join(head + rows + ["", f"The default's stop is within on {within} of {len(results['scenes'])} "
                                        f"scenes, in {iterations} iterations in all."])


def plot(results: dict, path: Path, per_row: int = 4):
    """Every scene's PSNR short of its answer against iterations (log), the default's stop dashed."""
    scenes = results["scenes"]
    fig, axes = scene_grid(len(scenes), per_row)
    for ax, scene in zip(axes, scenes):
        marks = scene["marks"]
        short = [max(scene["answer"]["psnr"] - m["psnr"], 1e-3) for m in marks]
        ax.semilogy([m["iteration"] for m in marks], short, "k")
        ax.axhline(0.2, color="0.6", lw=0.8)
        ax.axvline(scene["default"]["iteration"], color="C3", ls="--")
        ax.set(title=f"{scene['index']}: {scene['kind']}, {scene['level']}", xlabel="iteration",
               ylabel="dB short of the answer")
    save_grid(fig, results, "the default's trajectory against its answer (grey: 0.2 dB; dashed: where the default "
                            "stops)", path)


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "answer", named_scenes=False)
    parser.set_defaults(size=(96, 112), bands=32)
    parser.add_argument("--scenes", type=int, default=12, help="random scenes (kinds in turn; default 12)")
    add_kinds_option(parser)
    parser.add_argument("--seed", type=int, required=True, help="the panel")
    parser.add_argument("--only", type=scene_indices, metavar="I[,J...]", help="these scenes of the panel alone")
    parser.add_argument("--iters", type=int, default=6000, help="the trajectory's iterations (default 6000)")
    parser.add_argument("--tolerances", type=lambda text: [float(t) for t in text.split(",")],
                        default="0.05,0.01,0.002", help="stop tolerances to replay beside the default's")
    add_backend_option(parser)
    args = parser.parse_args(argv)
    if args.iters < AUTO_AT + WINDOW + SETTLED_OVER:
        parser.error(f"--iters {args.iters}: at least {AUTO_AT + WINDOW + SETTLED_OVER} to read the answer's drift")
    Where.use(args.backend)
    chosen = chosen_scenes(parser, args, args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"seed": args.seed, "size": size_text(args.size), "bands": args.bands, "iters": args.iters,
               "tolerances": args.tolerances, "scenes": [run_and_say(i, plan, args) for i, plan in chosen]}
    report(out, "answer", results, markdown(results))
    plot(results, out / "answer.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
