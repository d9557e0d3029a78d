#!/usr/bin/env python3
"""Which factor on ``--tv auto``'s weight a weight sweep supports, read from ``tools/bench_panel.py`` results.

    python tools/weight_factors.py sweep-auto/panel.json sweep-auto-a/panel.json --low-light 3.16

The panels must have a sweep (``--sweep N``; any marks, and with ``--marks auto`` each run is judged at its own
stop). Several files are merged by scene index (a later file's scene replaces an earlier one's), so a panel run in
parts with ``--only`` is read whole. For each of the sweep's multiples m of the chosen weight τ (10^(-1 … 1) in
the sweep's steps), a table row gives the scenes on which the fixed weight m·τ passes the weight rule
(``bench_panel.sweep_margins``: within 0.5 dB of the sweep's best weight by PSNR, and its angle within 1° of that
run's), as the rule judges the default. ``--low-light M`` adds a rule by light level: m = 1 in standard light and
M in low light, as a weight that grows as σ² rather than σ would be (σ̂ is 2.5–3.4× higher in the panels' low
light). Nothing is run: this reads what the sweep measured.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_panel import sweep_margins  # noqa: E402


def merged_scenes(paths) -> dict[int, dict]:
    """Scene index -> scene of every panel file, in index order (a later file's scene replaces an earlier one's)."""
    scenes = {}
    for path in paths:
        for scene in json.loads(Path(path).read_text())["scenes"]:
            scenes[scene["index"]] = scene
    return dict(sorted(scenes.items()))


def sweep_multiples(scene: dict) -> dict[str, str]:
    """The sweep's runs by their multiple of the chosen weight ("0.32" -> "--tv …"), from their order: the sweep
    spans 10^-1 … 10^1 of the chosen weight in equal log steps (``bench_panel.sweep_weights``)."""
    names = sorted((n for n in scene["runs"] if n.startswith("--tv ")), key=lambda n: float(n[5:]))
    exponents = np.linspace(-1.0, 1.0, len(names))
    return {f"{10.0 ** e:.2g}": name for e, name in zip(exponents, names)}


def passes(scene: dict, name: str) -> bool:
    return min(sweep_margins(scene, name)) >= 0


def factor_rows(scenes: dict[int, dict], low_light: float | None) -> list[tuple[str, list[int], list[int]]]:
    """(rule, passing scenes, failing scenes) for each multiple, then the rule by light level if asked."""
    multiples = {i: sweep_multiples(s) for i, s in scenes.items()}
    rows = []
    for m in multiples[min(scenes)]:
        verdicts = {i: passes(s, multiples[i][m]) for i, s in scenes.items()}
        rows.append((f"×{m}", [i for i, ok in verdicts.items() if ok], [i for i, ok in verdicts.items() if not ok]))
    if low_light is not None:
        low = min(multiples[min(scenes)], key=lambda m: abs(np.log(float(m) / low_light)))
        chosen = {i: multiples[i]["1" if s["level"] == "standard" else low] for i, s in scenes.items()}
        verdicts = {i: passes(s, chosen[i]) for i, s in scenes.items()}
        rows.append((f"×1 in standard light, ×{low} in low light", [i for i, ok in verdicts.items() if ok],
                     [i for i, ok in verdicts.items() if not ok]))
    return rows


def markdown(rows) -> str:
    lines = ["| weight | passes | fails on scenes |", "|---|---:|---|"]
    for rule, good, bad in rows:
        lines.append(f"| {rule} | {len(good)} of {len(good) + len(bad)} | {', '.join(map(str, bad)) or '–'} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("panels", nargs="+", help="bench_panel.py panel.json files with a sweep")
    parser.add_argument("--low-light", type=float, default=None, metavar="M",
                        help="also judge m = 1 in standard light and the sweep's multiple nearest M in low light")
    args = parser.parse_args(argv)
    try:
        scenes = merged_scenes(args.panels)
    except (OSError, ValueError, KeyError) as error:
        parser.error(f"cannot read the panels: {error}")
    if not scenes or any(not sweep_multiples(s) for s in scenes.values()):
        parser.error("every scene needs a weight sweep (bench_panel.py --sweep N with N ≥ 1)")
    print(markdown(factor_rows(scenes, args.low_light)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
