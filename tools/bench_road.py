#!/usr/bin/env python3
"""Where the road left lies: what of ADMM's iterate still differs from the model's answer at a few marks, on the
panel's scenes (:mod:`bench_converged`'s, with its cached references), and where the light sits.

    python tools/bench_road.py --size 128x160 --bands 64 --scenes 20 --seed S --only 1,4 --marks 50,110,300

Per scene, at its weight τ and with the default's penalties (as :mod:`bench_stop`): ADMM runs to each mark (one
solve a mark, its whole field kept), and its window x_k is set against x*, the ADMM reference's final cube, and the
truth t. The difference e = x_k − x* is split into three orthogonal parts: the *smooth achromatic* part (the
mean over λ of each pixel, low-passed below ``CUTOFF`` cycles a pixel over the window, DC included), the rest of the
achromatic part, and the *chromatic* part (what is left: spectra whose mean is zero). Each part P gets

* its share of ‖e‖², and
* its share of the PSNR gap's squared error, ‖x_k − t‖² − ‖x* − t‖² = Σ_P (‖Pe‖² + 2⟨Pe, P(x* − t)⟩),

so both columns add up to 1. Beside them: the cosine between e's smooth achromatic part and the answer's own
(x* − t)'s (near 1: the iterate errs further the way the answer errs), and the light (the sum of the cube) in the
sensor window and in the field's margin around it, against the truth's. Writes ``road.json`` and ``road.md``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from bench_accuracy import Where, add_backend_option, panel_parser, report, size_text, timed_run
from bench_converged import add_panel_options, told_point_like
from bench_panel import chosen_scenes, scene_done
from bench_stop import scene_answer
from clsdcam.metrics import psnr

CUTOFF = 1 / 32         # cycles a pixel: below it, the smooth achromatic part (with DC)
PARTS = ("smooth achromatic", "other achromatic", "chromatic")


def parts(e: np.ndarray) -> dict[str, np.ndarray]:
    """``e`` (K, H, W) as the sum of its three orthogonal parts (the module docstring), float64."""
    e = np.asarray(e, np.float64)
    achromatic = np.broadcast_to(e.mean(axis=0), e.shape)
    rows, columns = np.fft.fftfreq(e.shape[1])[:, None], np.fft.fftfreq(e.shape[2])[None, :]
    low = np.hypot(rows, columns) < CUTOFF
    smooth = np.broadcast_to(np.real(np.fft.ifft2(np.fft.fft2(achromatic[0]) * low)), e.shape)
    return {"smooth achromatic": smooth, "other achromatic": achromatic - smooth, "chromatic": e - achromatic}


def ratio(a: float, b: float) -> float:
    """a/b, NaN where b is 0 (an iterate on the answer has no road left to share out)."""
    return a / b if b else float("nan")


def anatomy(x: np.ndarray, xstar: np.ndarray, truth: np.ndarray) -> dict:
    """The distance ‖x − x*‖/‖x*‖, the PSNR gap, each part's share of ‖e‖² and of the gap's squared error, and the
    cosine of the smooth achromatic parts of e and x* − t."""
    x, xstar, truth = (np.asarray(a, np.float64) for a in (x, xstar, truth))
    e_parts, error_parts = parts(x - xstar), parts(xstar - truth)
    energy = float(np.sum((x - xstar) ** 2))
    excess = float(np.sum((x - truth) ** 2) - np.sum((xstar - truth) ** 2))
    smooth, answer = e_parts["smooth achromatic"][0].ravel(), error_parts["smooth achromatic"][0].ravel()
    return {"distance": float(np.sqrt(energy) / np.linalg.norm(xstar)),
            "psnr_gap": psnr(xstar, truth) - psnr(x, truth),
            "energy": {n: ratio(float(np.sum(p ** 2)), energy) for n, p in e_parts.items()},
            "gap": {n: ratio(float(np.sum(p ** 2) + 2 * np.sum(p * error_parts[n])), excess)
                    for n, p in e_parts.items()},
            "cosine": ratio(float(smooth @ answer), float(np.linalg.norm(smooth) * np.linalg.norm(answer)))}


def light(field: np.ndarray, offset, sensor) -> dict:
    """The sum of a field cube in the sensor window and in the margin around it."""
    (oy, ox), (h, w) = offset, sensor
    window = float(np.sum(field[:, oy:oy + h, ox:ox + w], dtype=np.float64))
    return {"window": window, "margin": float(np.sum(field, dtype=np.float64)) - window}


def mark(sim, tau: float, iters: int, xstar: np.ndarray) -> dict:
    """ADMM at ``tau`` to ``iters``: the anatomy of its window and the light in its field."""
    result, _ = timed_run(sim.calibration, sim.measurement,
                          {"tv": tau, "iters": iters, "algorithm": "admm", "full_field": True})
    field = result.full_field
    geometry = result.attrs["window_offset"], result.cube.shape[1:]
    return {"iteration": iters, **anatomy(result.cube, xstar, sim.truth), "light": light(field, *geometry)}


def run_scene(plan: dict, args, cache: Path) -> dict:
    sim, tau, probe, ref, xstar = scene_answer(plan, args, cache)
    with told_point_like(**probe):
        marks = [mark(sim, tau, k, xstar) for k in args.marks]
    return {**plan, "tv": tau, "reference": ref, "truth_light": float(np.sum(sim.truth, dtype=np.float64)),
            "answer_light": float(np.sum(xstar, dtype=np.float64)), "marks": marks}


def markdown(results: dict) -> str:
    head = [f"Seed {results['seed']}, {results['size']}×{results['bands']}, ADMM at the weight "
            f"{results['weight_from']}'s `--tv auto` chose, against its {results['reference_iters']}-iteration "
            "answer x*. Shares: of ‖x_k − x*‖² / of the PSNR gap's squared error; light in thousands.", "",
            "| # | kind | k | ‖x_k − x*‖/‖x*‖ | PSNR gap | " + " | ".join(PARTS)
            + " | cosine of the smooth achromatic parts of e and x* − t | window light | margin light"
            + " | truth's (x*'s) |",
            "|---:|---|---:|---:|---:|" + "---:|" * (len(PARTS) + 4)]
    rows = []
    for s in results["scenes"]:
        for m in s["marks"]:
            shares = " | ".join(f"{m['energy'][n]:.2f} / {m['gap'][n]:+.2f}" for n in PARTS)
            rows.append(f"| {s['index']} | {s['kind']}, {s['level']} | {m['iteration']} | {m['distance']:.3f} | "
                        f"{m['psnr_gap']:.2f} dB | {shares} | {m['cosine']:+.2f} | "
                        f"{m['light']['window'] / 1e3:.1f} | {m['light']['margin'] / 1e3:.1f} | "
                        f"{s['truth_light'] / 1e3:.1f} ({s['answer_light'] / 1e3:.1f}) |")
    return "\n".join(head + rows)


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "road", named_scenes=False)
    parser.set_defaults(size=(64, 80), bands=32)
    add_panel_options(parser, scenes=10, reference_iters=1500, weight_from="default", seed_required=True)
    parser.add_argument("--marks", default="50,110,300", help="the iterations to look at (default 50,110,300)")
    add_backend_option(parser)
    args = parser.parse_args(argv)
    Where.use(args.backend)
    args.marks = sorted({int(k) for k in args.marks.split(",")})
    chosen = chosen_scenes(parser, args, args.seed)
    out, cache = Path(args.out), Path(args.cache)
    out.mkdir(parents=True, exist_ok=True)
    cache.mkdir(parents=True, exist_ok=True)
    results = {"seed": args.seed, "size": size_text(args.size), "bands": args.bands, "marks": args.marks,
               "reference_iters": args.reference_iters, "weight_from": args.weight_from, "scenes": []}
    for i, plan in chosen:
        results["scenes"].append({"index": i, **run_scene(plan, args, cache)})
        scene_done(i, plan, args.scenes)
    report(out, "road", results, markdown(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
