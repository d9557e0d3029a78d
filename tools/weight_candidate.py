#!/usr/bin/env python3
"""A lighter ``--tv auto`` weight for point-like scenes in good light, judged against ``tools/bench_panel.py`` sweeps.

    python tools/weight_candidate.py lines-a/panel.json lines-b/panel.json --sigma0 0.009 --point-like 0.0025

The candidate (docs/convergence.md, "A lighter weight for point-like scenes in good light"): a scene is point-like
when the default solve's iterate at iteration 30 (where ``--tv auto`` reads the noise σ̂) has a mean below
``--point-like`` times its peak; there the weight is m·τ with m = min(1, σ̂/σ0), a weight that falls as σ̂² below σ0;
elsewhere m = 1, the rule as it is. A scene with m = 1 keeps its sweep's verdict on the default (as
``weight_factors.py`` gives it); the others are solved at m·τ to the default stop and judged by the weight rule
(``bench_panel.sweep_margins``: PSNR within 0.5 dB of the best fixed weight, its angle within 1° of that run's),
the candidate's run counted among the fixed weights. The panels (``--marks auto``, with a sweep) must share one
seed, size and bands, which rebuild every scene (``bench_panel.panel_scene``); several files are merged by scene
(``weight_factors.merged``).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_panel import AUTO, panel_scene, point, run, sweep_margins  # noqa: E402
from weight_factors import at_stop, merged, sweep_multiples  # noqa: E402
from clsdcam.cli.options import number, size  # noqa: E402
from clsdcam.solve.auto_weights import AUTO_AT  # noqa: E402
from clsdcam.solve.solver import Settings, Solver  # noqa: E402


def positive(text: str) -> float:
    value = number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be > 0")
    return value


def mean_over_peak(sim) -> float:
    """How point-like the scene's iterate is where the rule reads the noise: mean/max of the cube after AUTO_AT
    iterations of the default solve's algorithm (``--iters auto`` picks it; a few lit pixels in a few bands give
    0.0005–0.0013 on the panels' lines scenes, the others 0.005–0.2)."""
    settings = Settings(iters=AUTO_AT, algorithm=Settings().algorithm)
    cube = np.asarray(Solver(sim.calibration, settings=settings).solve(sim.measurement).cube)
    return float(cube.mean() / cube.max())


def multiple(noise: float, likeness: float, sigma0: float, threshold: float) -> float:
    """m = min(1, σ̂/σ0) on a point-like scene (mean/peak below ``threshold``), else 1."""
    return min(1.0, noise / sigma0) if likeness < threshold else 1.0


def judge(scene: dict, shape, bands: int, sigma0: float, threshold: float) -> dict:
    """The candidate's multiple, run and verdict on one panel scene (the scene gains the run as "candidate")."""
    today = sweep_margins(scene, "default")      # before the candidate joins the fixed weights
    sim = panel_scene(scene, shape, bands)
    default, likeness = scene["runs"]["default"], mean_over_peak(sim)
    m = multiple(default["noise_estimate"], likeness, sigma0, threshold)
    if m == 1.0:
        scene["runs"]["candidate"], margins = default, today
    else:
        tau = m * default["tv_chosen"]
        scene["runs"]["candidate"] = scene["runs"][f"--tv {tau:.3g} (candidate)"] = run(sim, {"tv": tau}, AUTO)
        margins = sweep_margins(scene, "candidate")
    return {"index": scene["index"], "likeness": likeness, "multiple": m, "margins": margins,
            "passes": min(margins) >= 0, "today": min(today) >= 0}


def row(scene: dict, verdict: dict) -> str:
    db, deg = verdict["margins"]
    margin = f"{db:+.2f} dB / {deg:+.2f}°"
    return (f"| {scene['index']} | {scene['kind']} | {scene['level']} | {verdict['likeness']:.4f} | "
            f"×{verdict['multiple']:.2f} | {point(scene['runs']['default'])} | {at_stop(scene['runs']['candidate'])} | "
            + (margin if verdict["passes"] else f"**{margin}**") + " |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("panels", nargs="+", help="bench_panel.py panel.json files with a sweep (--marks auto)")
    parser.add_argument("--sigma0", type=positive, default=0.009,
                        help="σ̂ below which a point-like scene's weight falls")
    parser.add_argument("--point-like", type=float, default=0.0025, metavar="R",
                        help="mean/peak of the 30-iteration iterate below which a scene is point-like")
    args = parser.parse_args(argv)
    try:
        panels = [json.loads(Path(f).read_text()) for f in args.panels]
        settings = {(p["seed"], p["size"], p["bands"], p["marks"]) for p in panels}
        scenes = merged(panels)
    except (OSError, ValueError, KeyError, TypeError) as error:
        parser.error(f"cannot read the panels: {error}")
    if len(settings) != 1 or next(iter(settings))[3] != AUTO:
        parser.error("the panels must share one seed, size and bands, each run to its own stop (--marks auto)")
    if not scenes or any(not sweep_multiples(s) for s in scenes.values()):
        parser.error("every scene needs a weight sweep (bench_panel.py --sweep N with N ≥ 1)")
    (_, shape, bands, _), = settings
    lines = ["| # | kind | noise | mean/peak at 30 | multiple | default | candidate | weight margin |",
             "|---:|---|---|---:|---:|---|---|---|"]
    verdicts = []
    for scene in scenes.values():
        verdicts.append(judge(scene, size()(shape), bands, args.sigma0, args.point_like))
        lines.append(row(scene, verdicts[-1]))
    count = sum(v["passes"] for v in verdicts)
    print("\n".join(lines) + f"\n\ncandidate passes {count} of {len(verdicts)}; "
          f"the rule as it is, {sum(v['today'] for v in verdicts)} of {len(verdicts)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
