#!/usr/bin/env python3
"""The widely lit weight's σ1 (``TotalVariation.auto_weight.lit_noise``) judged on a panel's widely lit scenes.

    python tools/lit_weights.py --size 128x160 --bands 64 --seed 7966048296623229867 --only 6,9,16,19 \
        --sigmas 0.0045,0.0055 --out lit-a
    python tools/lit_weights.py --join lit-a/lit.json lit-b/lit.json     # one table of several runs

On a widely lit scene (the default's probe reads p = ``mean_over_peak`` at or above ``widely_lit_above``) the
default's weight is τ = 0.06·σ̂·max(1, σ̂/σ1) (:meth:`clsdcam.solve.priors.AutoWeight.for_noise`). Per scene of the
panel (``tools/bench_panel.py``'s scenes, rebuilt from the seed) the probe reads p and σ̂. A scene that is not widely
lit, or where every σ1 gives the same weight (σ̂ under the smallest, or every weight at the cap), is listed and
skipped. The others are solved by the default at each σ1 (``--sigmas``), by today's default (FISTA, 300
iterations) and at fixed multiples ×1, ×1.41, ×2, ×2.83 and ×4 of the noise rule's weight 0.06·σ̂, each to its own
stop. Each σ1 is judged by two rules:

- the weight rule (``bench_panel.sweep_margins``, as ``--tv auto`` is judged): PSNR within 0.5 dB of the best run
  by PSNR, fixed weights and the σ1 runs together, and the angle within 1° of that run's;
- rule 4 (``bench_converged.regression_margin``): not lower than today's default by more than 0.2 dB *and*
  higher in angle by more than 0.5° at once.

Writes ``lit.json`` after every scene and ``lit.md``, and prints the table with each σ1's count of scenes passed.
"""
from __future__ import annotations

import argparse
import json
import sys
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_accuracy import panel_parser, report, save_json, size_text  # noqa: E402
from bench_converged import TODAY, regression_margin  # noqa: E402
from bench_panel import (AUTO, chosen_scenes, panel_scene, point, progress, run, scene_indices,  # noqa: E402
                         sweep_margins)
from weight_rejudge import chosen_now  # noqa: E402
from clsdcam.algorithms.admm import Admm  # noqa: E402
from clsdcam.solve.auto_weights import widely_lit  # noqa: E402
from clsdcam.solve.priors import TotalVariation  # noqa: E402

MULTIPLES = (1, 1.41, 2, 2.83, 4)       # of the noise rule's weight: √2 apart


@contextmanager
def lit_noise(sigma: float):
    """The default's ``--tv auto`` with σ1 = ``sigma``, restored after."""
    rule = TotalVariation.auto_weight
    TotalVariation.auto_weight = rule._replace(lit_noise=sigma)
    try:
        yield
    finally:
        TotalVariation.auto_weight = rule


def lit_weights(noise: float, sigmas) -> dict[float, float]:
    """σ1 -> the widely lit weight it gives at noise σ̂."""
    rule = TotalVariation.auto_weight
    return {s: rule._replace(lit_noise=s).for_noise(noise, widely_lit=True) for s in sigmas}


def skip_reason(probe: dict, sigmas) -> str | None:
    """Why a scene is not judged (not widely lit; every σ1 the same weight), or None."""
    if not widely_lit(probe, Admm.widely_lit_above):
        return "not widely lit"
    return "the same weight" if len(set(lit_weights(probe["noise_estimate"], sigmas).values())) == 1 else None


def solve_scene(sim, noise: float, sigmas) -> dict:
    """Every run of one widely lit scene: each σ1 (also among the fixed weights, as ``--tv τ (σ1 s)``), today's
    default and the fixed multiples of the noise rule's weight."""
    runs = {}
    for s in sigmas:
        with lit_noise(s):
            runs[f"σ1 {s:g}"] = own = run(sim, {}, AUTO)
        runs[f"--tv {own['tv_chosen']:.3g} (σ1 {s:g})"] = own
    runs["today"] = run(sim, TODAY, [TODAY["iters"]])
    for m in MULTIPLES:
        tau = m * TotalVariation.auto_weight.per_noise * noise
        runs[f"--tv {tau:.3g} (×{m:g})"] = run(sim, {"tv": tau}, AUTO)
    return runs


def verdict(scene: dict, name: str) -> dict:
    """Run ``name``'s margins: the weight rule's (dB, °) and rule 4's (positive: it holds)."""
    own, today = scene["runs"][name]["points"][-1], scene["runs"]["today"]["points"][-1]
    return {"weight": min(sweep_margins(scene, name)), "regression": regression_margin(own, today)}


def judged_scene(index: int, plan: dict, shape, bands: int, sigmas) -> dict:
    """One panel scene: its probe, and its runs unless it is skipped (:func:`skip_reason`)."""
    sim = panel_scene(plan, shape, bands)
    attrs = chosen_now(sim)
    probe = {key: float(attrs[key]) for key in ("mean_over_peak", "noise_estimate") if key in attrs}
    scene = {**plan, "index": index, "probe": probe, "skipped": skip_reason(probe, sigmas)}
    if scene["skipped"] is None:
        scene["runs"] = solve_scene(sim, probe["noise_estimate"], sigmas)
    return scene


def cell(scene: dict, name: str) -> str:
    """A run's final point; a σ1 run's also with its weight and both margins (failing ones in bold)."""
    runs = scene["runs"]
    if not name.startswith("σ1"):
        return point(runs[name])
    margins = verdict(scene, name)
    said = [f"{'weight' if key == 'weight' else 'rule 4'} {value:+.2f}" for key, value in margins.items()]
    said = [text if value >= 0 else f"**{text}**" for text, value in zip(said, margins.values())]
    return f"{point(runs[name])}, τ {runs[name]['tv_chosen']:.3g}, " + ", ".join(said)


def fixed_names(scene: dict) -> list[str]:
    """The fixed multiples' run names, lightest first."""
    return [name for name in scene["runs"] if name.startswith("--tv ") and "(×" in name]


def markdown(results: list[dict], sigmas) -> str:
    """Every scene's row, then each σ1's count of scenes passed."""
    names = [f"σ1 {s:g}" for s in sigmas]
    lines = ["| seed:# | kind | p | σ̂ | today (300 it) | " + " | ".join(f"×{m:g}" for m in MULTIPLES) + " | "
             + " | ".join(names) + " |", "|---|---|---:|---:|" + "---|" * (1 + len(MULTIPLES) + len(names))]
    judged = [s for s in results if s["skipped"] is None]
    for s in results:
        probe = s["probe"]
        head = (f"| {s['panel']}:{s['index']} | {s['kind']}, {s['level']} | {probe.get('mean_over_peak', 0):.3f} | "
                f"{probe['noise_estimate']:.4f} |")
        cells = [s["skipped"]] + [""] * (len(MULTIPLES) + len(names)) if s["skipped"] else \
            [cell(s, n) for n in ("today", *fixed_names(s), *names)]
        lines.append(f"{head} {' | '.join(cells)} |")
    lines.append("")
    for name in names:
        margins = [verdict(s, name) for s in judged]
        lines.append(f"{name}: the weight rule on {sum(m['weight'] >= 0 for m in margins)} of {len(judged)}, "
                     f"rule 4 on {sum(m['regression'] >= 0 for m in margins)} of {len(judged)}")
    return "\n".join(lines)


def sigma_list(text: str) -> list[float]:
    """--sigmas' value, "a,b,…", as positive σ1 values (an argparse type)."""
    try:
        sigmas = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        sigmas = []
    if not sigmas or min(sigmas) <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: σ1 values are positive numbers, e.g. 0.0045,0.0055")
    return sigmas


def joined(parser, paths) -> tuple[list[dict], list[float]]:
    """The scenes and σ1 values of several ``lit.json`` files (they must share the σ1 values)."""
    try:
        runs = [json.loads(Path(path).read_text()) for path in paths]
    except (OSError, ValueError) as error:
        parser.error(f"cannot read {error}")
    if any(r.get("sigmas") != runs[0].get("sigmas") or "scenes" not in r for r in runs):
        parser.error("--join: the files must be lit.json files of the same --sigmas")
    return [s for r in runs for s in r["scenes"]], runs[0]["sigmas"]


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "lit", named_scenes=False)
    parser.add_argument("--scenes", type=int, default=20, help="the panel's scenes (kinds in turn; default 20)")
    parser.add_argument("--seed", type=int, help="the panel to replay (required unless --join)")
    parser.add_argument("--only", type=scene_indices, metavar="I[,J...]", help="these scenes of the panel alone")
    parser.add_argument("--sigmas", type=sigma_list, default="0.0045,0.0055", help="σ1 values to judge")
    parser.add_argument("--join", nargs="+", metavar="LIT_JSON", help="print one table of earlier runs' lit.json")
    args = parser.parse_args(argv)
    if args.join:
        print(markdown(*joined(parser, args.join)))
        return 0
    if args.seed is None:
        parser.error("--seed is required (or --join)")
    plans = chosen_scenes(parser, argparse.Namespace(**vars(args), kinds=None), args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"seed": args.seed, "size": size_text(args.size), "bands": args.bands, "sigmas": args.sigmas,
               "scenes": []}
    for index, plan in plans:
        results["scenes"].append(judged_scene(index, {**plan, "panel": args.seed}, args.size, args.bands, args.sigmas))
        progress(f"scene {index} ({plan['kind']}, {plan['level']}): {results['scenes'][-1]['skipped'] or 'judged'}")
        save_json(out, "lit", results)
    report(out, "lit", results, markdown(results["scenes"], args.sigmas))
    return 0


if __name__ == "__main__":
    sys.exit(main())
