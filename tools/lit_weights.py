#!/usr/bin/env python3
"""The widely lit weight's V1 (``TotalVariation.auto_weight.lit_variance``) judged on a panel's widely lit scenes.

    python tools/lit_weights.py --size 128x160 --bands 64 --seed 7966048296623229867 --only 6,9,16,19 \
        --variances 3e-4,4e-4 --out lit-a
    python tools/lit_weights.py --join lit-a/lit.json lit-b/lit.json     # one table of several runs

On a widely lit scene (the default's probe reads p = ``mean_over_peak`` at or above ``widely_lit_above``) the
default's weight is τ = 0.06·σ̂·max(1, σ̂²/(q·V1)), q the measurement's mean over its peak
(:meth:`clsdcam.solve.priors.AutoWeight.for_noise`). Per scene of the panel (``tools/bench_panel.py``'s scenes,
rebuilt from the seed) the probe reads p, σ̂ and q. A scene that is not widely lit, or where every V1 gives the noise
rule's own weight (σ̂²/q under each), is listed and skipped. The others are solved by the
default at each V1 (``--variances``), by today's default (FISTA, 300 iterations) and at fixed multiples ×1, ×1.41,
×2, ×2.83 and ×4 of the noise rule's weight 0.06·σ̂, each to its own stop. Each rule's run is judged by two rules:

- the weight rule (``bench_panel.sweep_margins``, as ``--tv auto`` is judged): PSNR within 0.5 dB of the best run
  by PSNR, fixed weights and the rules' runs together, and the angle within 1° of that run's;
- rule 4 (``bench_converged.regression_margin``): not lower than today's default by more than 0.2 dB *and*
  higher in angle by more than 0.5° at once.

Writes ``lit.json`` after every scene and ``lit.md``, and prints the table with each rule's count of scenes passed.
``--join`` merges the runs of the same scene from several ``lit.json`` files, so a run of the earlier rule (σ̂ read
against a σ1: the runs named "σ1 …" of this tool before V1, at commit df55788) is judged beside V1's. With
``--predict`` it also judges V1 values that were not run, their final points interpolated between the fixed
multiples' (a screen for candidates: within 0.15 dB and 0.17° of V1 4e-4's solved runs on 17 fresh scenes).

    python tools/lit_weights.py --join lit-a/lit.json lit-b/lit.json --predict 3e-4,4e-4,5e-4
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_accuracy import panel_parser, report, save_json, size_text  # noqa: E402
from bench_converged import TODAY, regression_margin  # noqa: E402
from bench_panel import (AUTO, chosen_scenes, panel_scene, point, progress, run, scene_indices,  # noqa: E402
                         sweep_margins)
from weight_rejudge import chosen_now  # noqa: E402
from clsdcam.cli.options import size  # noqa: E402
from clsdcam.algorithms.admm import Admm  # noqa: E402
from clsdcam.solve.auto_weights import widely_lit  # noqa: E402
from clsdcam.solve.priors import TotalVariation  # noqa: E402

MULTIPLES = (1, 1.41, 2, 2.83, 4)       # of the noise rule's weight: √2 apart


RULES = ("σ1 ", "V1 ")                 # the rules' run names: the earlier σ1's (this tool at df55788) and V1's
PROBE = ("mean_over_peak", "noise_estimate", "measured_mean_over_peak")     # what the probe's attributes give


@contextmanager
def lit_variance(variance: float):
    """The default's ``--tv auto`` with V1 = ``variance``, restored after."""
    rule = TotalVariation.auto_weight
    TotalVariation.auto_weight = rule._replace(lit_variance=variance)
    try:
        yield
    finally:
        TotalVariation.auto_weight = rule


def lit_weights(probe: dict, variances) -> dict[float, float]:
    """V1 -> the widely lit weight it gives at the probe's noise σ̂ and measured mean q."""
    rule, noise, q = TotalVariation.auto_weight, probe["noise_estimate"], probe["measured_mean_over_peak"]
    return {v: rule._replace(lit_variance=v).for_noise(noise, lit_mean=q) for v in variances}


def skip_reason(probe: dict, variances) -> str | None:
    """Why a scene is not judged (not widely lit; every V1 gives the noise rule's own weight, σ̂²/q under each), or
    None."""
    if not widely_lit(probe, Admm.widely_lit_above):
        return "not widely lit"
    own = TotalVariation.auto_weight.for_noise(probe["noise_estimate"])
    return "the noise rule's weight" if set(lit_weights(probe, variances).values()) == {own} else None


def solve_scene(sim, noise: float, variances) -> dict:
    """Every run of one widely lit scene: each V1 (also among the fixed weights, as ``--tv τ (V1 v)``), today's
    default and the fixed multiples of the noise rule's weight."""
    runs = {}
    for v in variances:
        with lit_variance(v):
            runs[f"V1 {v:g}"] = own = run(sim, {}, AUTO)
        runs[f"--tv {own['tv_chosen']:.3g} (V1 {v:g})"] = own
    runs["today"] = run(sim, TODAY, [TODAY["iters"]])
    for m in MULTIPLES:
        tau = m * TotalVariation.auto_weight.per_noise * noise
        runs[f"--tv {tau:.3g} (×{m:g})"] = run(sim, {"tv": tau}, AUTO)
    return runs


def verdict(scene: dict, name: str) -> dict:
    """Run ``name``'s margins: the weight rule's (dB, °) and rule 4's (positive: it holds)."""
    own, today = scene["runs"][name]["points"][-1], scene["runs"]["today"]["points"][-1]
    return {"weight": min(sweep_margins(scene, name)), "regression": regression_margin(own, today)}


def judged_scene(index: int, plan: dict, shape, bands: int, variances) -> dict:
    """One panel scene: its probe, and its runs unless it is skipped (:func:`skip_reason`)."""
    sim = panel_scene(plan, shape, bands)
    attrs = chosen_now(sim)
    probe = {key: float(attrs[key]) for key in PROBE if key in attrs}
    scene = {**plan, "index": index, "probe": probe, "skipped": skip_reason(probe, variances)}
    if scene["skipped"] is None:
        scene["runs"] = solve_scene(sim, probe["noise_estimate"], variances)
    return scene


def cell(scene: dict, name: str) -> str:
    """A run's final point; a rule's run also with its weight and both margins (failing ones in bold)."""
    runs = scene["runs"]
    if not name.startswith(RULES):
        return point(runs[name])
    margins = verdict(scene, name)
    said = [f"{'weight' if key == 'weight' else 'rule 4'} {value:+.2f}" for key, value in margins.items()]
    said = [text if value >= 0 else f"**{text}**" for text, value in zip(said, margins.values())]
    return f"{point(runs[name])}, τ {runs[name]['tv_chosen']:.3g}, " + ", ".join(said)


def fixed_names(scene: dict) -> list[str]:
    """The fixed multiples' run names, lightest first."""
    return [name for name in scene["runs"] if name.startswith("--tv ") and "(×" in name]


def rule_names(scenes: list[dict]) -> list[str]:
    """The rules' run names of the judged scenes, in order of first appearance."""
    names = [name for s in scenes if s["skipped"] is None for name in s["runs"] if name.startswith(RULES)]
    return list(dict.fromkeys(names))


def q_text(probe: dict) -> str:
    """The probe's q for the table ("–" where an earlier rule's file did not read it)."""
    q = probe.get("measured_mean_over_peak")
    return "–" if q is None else f"{q:.3f}"


def markdown(results: list[dict]) -> str:
    """Every scene's row, then each rule's count of scenes passed (of the judged scenes it ran on)."""
    names = rule_names(results)
    lines = ["| seed:# | kind | p | σ̂ | q | today (300 it) | " + " | ".join(f"×{m:g}" for m in MULTIPLES) + " | "
             + " | ".join(names) + " |", "|---|---|---:|---:|---:|" + "---|" * (1 + len(MULTIPLES) + len(names))]
    for s in results:
        probe = s["probe"]
        head = (f"| {s['panel']}:{s['index']} | {s['kind']}, {s['level']} | {probe.get('mean_over_peak', 0):.3f} | "
                f"{probe['noise_estimate']:.4f} | {q_text(probe)} |")
        cells = [s["skipped"]] + [""] * (len(MULTIPLES) + len(names)) if s["skipped"] else \
            [cell(s, n) if n in s["runs"] else "" for n in ("today", *fixed_names(s), *names)]
        lines.append(f"{head} {' | '.join(cells)} |")
    lines.append("")
    for name in names:
        margins = [verdict(s, name) for s in results if s["skipped"] is None and name in s["runs"]]
        lines.append(f"{name}: the weight rule on {sum(m['weight'] >= 0 for m in margins)} of {len(margins)}, "
                     f"rule 4 on {sum(m['regression'] >= 0 for m in margins)} of {len(margins)}")
    return "\n".join(lines)


def variance_list(text: str) -> list[float]:
    """--variances' value, "a,b,…", as positive V1 values (an argparse type)."""
    try:
        variances = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        variances = []
    if not variances or min(variances) <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: V1 values are positive numbers, e.g. 3e-4,4e-4")
    return variances


def merged(scenes: list[dict]) -> list[dict]:
    """The scenes of several files, one per (panel, index, size, bands), with the runs and probe readings of each
    file's copy together (a scene skipped in one file and judged in another is judged)."""
    by_key: dict = {}
    for s in scenes:
        kept = by_key.setdefault((s["panel"], s["index"], s["size"], s["bands"]), {**s, "runs": {}})
        kept["runs"].update(s.get("runs", {}))
        kept["probe"] = {**kept["probe"], **s["probe"]}
        kept["skipped"] = None if kept["runs"] else s["skipped"]
    return list(by_key.values())


def joined(parser, paths) -> list[dict]:
    """The scenes of several ``lit.json`` files, merged (:func:`merged`), each with its file's size and bands."""
    try:
        runs = [json.loads(Path(path).read_text()) for path in paths]
    except (OSError, ValueError) as error:
        parser.error(f"cannot read {error}")
    if any(not isinstance(r, dict) or not {"scenes", "size", "bands"} <= set(r) for r in runs):
        parser.error("--join: the files must be this tool's lit.json files")
    return merged([{**s, "size": r["size"], "bands": r["bands"]} for r in runs for s in r["scenes"]])


def measured_mean(scene: dict) -> float:
    """q of a scene's measurement, mean(b)/max|b|: the probe's reading where it made it (V1's runs), else from the
    scene rebuilt from its seed (an earlier rule's file)."""
    if "measured_mean_over_peak" in scene["probe"]:
        return scene["probe"]["measured_mean_over_peak"]
    b = panel_scene(scene, size()(scene["size"]), scene["bands"]).measurement
    return float(b.mean(dtype=float)) / float(np.abs(b).max())


def predicted(scene: dict, variance: float) -> dict:
    """V1's run on a judged scene whose probe has q, predicted from its fixed multiples' final points: the weight V1
    gives (:func:`lit_weights`), PSNR and angle interpolated linearly in log τ between the fixed runs around it (held at
    the end ones beyond ×1–×4)."""
    tau = lit_weights(scene["probe"], [variance])[variance]
    fixed = sorted((scene["runs"][name]["tv_chosen"], scene["runs"][name]["points"][-1]) for name in fixed_names(scene))
    at = [math.log(t) for t, _ in fixed]
    final = {key: float(np.interp(math.log(tau), at, [p[key] for _, p in fixed])) for key in ("psnr", "angle")}
    return {"tv_chosen": tau, "points": [final]}


def with_predictions(scenes: list[dict], variances) -> list[dict]:
    """The judged scenes with fixed multiples gain their probe's q (:func:`measured_mean`; the table shows it) and a
    predicted run per V1 (:func:`predicted`), named "V1 v (predicted)"."""
    for s in (s for s in scenes if s["skipped"] is None and fixed_names(s)):
        s["probe"]["measured_mean_over_peak"] = measured_mean(s)
        s["runs"].update({f"V1 {v:g} (predicted)": predicted(s, v) for v in variances})
    return scenes


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "lit", named_scenes=False)
    parser.add_argument("--scenes", type=int, default=20, help="the panel's scenes (kinds in turn; default 20)")
    parser.add_argument("--seed", type=int, help="the panel to replay (required unless --join)")
    parser.add_argument("--only", type=scene_indices, metavar="I[,J...]", help="these scenes of the panel alone")
    parser.add_argument("--variances", type=variance_list, default="4e-4", help="V1 values to judge")
    parser.add_argument("--join", nargs="+", metavar="LIT_JSON", help="print one table of earlier runs' lit.json")
    parser.add_argument("--predict", type=variance_list, metavar="V1[,V2...]",
                        help="with --join: judge these V1 values on the joined runs, interpolated between the fixed "
                             "multiples instead of solved")
    args = parser.parse_args(argv)
    if args.predict and not args.join:
        parser.error("--predict judges the runs of --join: give the lit.json files")
    if args.join:
        print(markdown(with_predictions(joined(parser, args.join), args.predict or ())))
        return 0
    if args.seed is None:
        parser.error("--seed is required (or --join)")
    plans = chosen_scenes(parser, argparse.Namespace(**vars(args), kinds=None), args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"seed": args.seed, "size": size_text(args.size), "bands": args.bands, "variances": args.variances,
               "scenes": []}
    for index, plan in plans:
        results["scenes"].append(judged_scene(index, {**plan, "panel": args.seed}, args.size, args.bands,
                                              args.variances))
        progress(f"scene {index} ({plan['kind']}, {plan['level']}): {results['scenes'][-1]['skipped'] or 'judged'}")
        save_json(out, "lit", results)
    report(out, "lit", results, markdown(results["scenes"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
