#!/usr/bin/env python3
"""The package's ``--tv auto`` judged again on older ``tools/bench_panel.py`` sweeps, after its rule changed.

    python tools/weight_rejudge.py lines-a/panel.json lines-b/panel.json

A sweep's fixed weights are absolute, so they stay valid when the rule that chose the default's weight changes. Per
scene, a solve of AUTO_AT iterations of the default's algorithm reads the weight the rule chooses now (and how
point-like the iterate is there, ``mean_over_peak``: docs/convergence.md, "A lighter weight for point-like scenes in
good light"). A scene whose weight is the panel's keeps its sweep's verdict (as ``weight_factors.py`` gives it); the
others are solved again at the default, to its stop, and judged by the weight rule (``bench_panel.sweep_margins``:
PSNR within 0.5 dB of the best fixed weight, its angle within 1° of that run's), the new run counted among the fixed
weights. The panels (``--marks auto``, with a sweep) must share one seed, size and bands, which rebuild every scene
(``bench_panel.panel_scene``); several files are merged by scene (``weight_factors.merged``).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_panel import AUTO, KINDS, LEVELS, panel_scene, point, run, sweep_margins  # noqa: E402
from weight_factors import at_stop, merged, sweep_multiples  # noqa: E402
from clsdcam.cli.options import size  # noqa: E402
from clsdcam.solve.auto_weights import AUTO_AT  # noqa: E402
from clsdcam.solve.solver import Settings, Solver  # noqa: E402

SAME = 1e-3         # weights closer than this (relative) are the same: the panels keep 3-4 digits of some figures


def chosen_now(sim) -> dict:
    """The attributes of AUTO_AT iterations of the default's algorithm (``--iters auto`` picks it): ``tv_chosen``,
    ``noise_estimate`` and, where the algorithm reads it, ``mean_over_peak``."""
    settings = Settings(iters=AUTO_AT, algorithm=Settings().algorithm)
    return Solver(sim.calibration, settings=settings).solve(sim.measurement).attrs


def judge(scene: dict, shape, bands: int) -> dict:
    """The default's weight now, its run and verdict on one panel scene (the scene gains the run as "now")."""
    then = sweep_margins(scene, "default")      # before the new run joins the fixed weights
    sim = panel_scene(scene, shape, bands)
    default, attrs = scene["runs"]["default"], chosen_now(sim)
    tau = float(attrs["tv_chosen"])
    if abs(tau / default["tv_chosen"] - 1) < SAME:
        scene["runs"]["now"], margins = default, then
    else:
        scene["runs"]["now"] = scene["runs"][f"--tv {tau:.3g} (now)"] = run(sim, {}, AUTO)
        margins = sweep_margins(scene, "now")
    return {"index": scene["index"], "likeness": attrs.get("mean_over_peak"), "tau": tau, "margins": margins,
            "passes": min(margins) >= 0, "then": min(then) >= 0}


def row(scene: dict, verdict: dict) -> str:
    db, deg = verdict["margins"]
    margin = f"{db:+.2f} dB / {deg:+.2f}°"
    likeness = "–" if verdict["likeness"] is None else f"{verdict['likeness']:.4f}"
    weights = f"{scene['runs']['default']['tv_chosen']:.3g} → {verdict['tau']:.3g}"
    return (f"| {scene['index']} | {scene['kind']} | {scene['level']} | {likeness} | {weights} | "
            f"{point(scene['runs']['default'])} | {at_stop(scene['runs']['now'])} | "
            + (margin if verdict["passes"] else f"**{margin}**") + " |")


def checked(scene: dict) -> dict:
    """The scene, if it holds what a re-judgement reads: a known kind and level, a seed, the default's weight (> 0)
    and a sweep whose runs name their weights; else ValueError."""
    if scene["kind"] not in KINDS or scene["level"] not in LEVELS or not isinstance(scene["seed"], int):
        raise ValueError(f"scene {scene['index']}: not a panel scene")
    if not float(scene["runs"]["default"]["tv_chosen"]) > 0:
        raise ValueError(f"scene {scene['index']}: the default's weight is not > 0")
    if not sweep_multiples(scene):
        raise ValueError(f"scene {scene['index']}: no weight sweep (bench_panel.py --sweep N with N ≥ 1)")
    return scene


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("panels", nargs="+", help="bench_panel.py panel.json files with a sweep (--marks auto)")
    args = parser.parse_args(argv)
    try:
        panels = [json.loads(Path(f).read_text()) for f in args.panels]
        settings = {(p["seed"], p["size"], p["bands"], p["marks"] == AUTO, p["backend"]) for p in panels}
        scenes = {i: checked(scene) for i, scene in merged(panels).items()}
        shape = size()(panels[0]["size"])
    except (OSError, ValueError, KeyError, TypeError, argparse.ArgumentTypeError) as error:
        parser.error(f"cannot read the panels: {error}")
    (_, _, bands, to_stop, backend), *others = settings
    if others or not to_stop or backend != "numpy" or not scenes:
        parser.error("the panels must share one seed, size and bands, each run to its own stop (--marks auto) on "
                     "NumPy, where this tool solves")
    lines = ["| # | kind | noise | mean/peak at 30 | τ then → now | default then | default now | weight margin |",
             "|---:|---|---|---:|---|---|---|---|"]
    verdicts = []
    for scene in scenes.values():
        verdicts.append(judge(scene, shape, bands))
        lines.append(row(scene, verdicts[-1]))
    count = sum(v["passes"] for v in verdicts)
    print("\n".join(lines) + f"\n\nthe default now passes {count} of {len(verdicts)}; "
          f"the panel's default, {sum(v['then'] for v in verdicts)} of {len(verdicts)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
