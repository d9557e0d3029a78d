#!/usr/bin/env python3
"""Which factor on ``--tv auto``'s weight a weight sweep supports, read from ``tools/bench_panel.py`` results.

    python tools/weight_factors.py sweep-auto/panel.json sweep-auto-a/panel.json --low-light 3.16

The panels must have a sweep (``--sweep N``; any marks, and with ``--marks auto`` each run is judged at its own
stop). Several files are merged by scene index (a later file's scene replaces an earlier one's), so a panel run in
parts with ``--only`` is read whole. The first table is every scene's check of the chosen weight: the default and
``--no-skip`` at their last mark (iterations in brackets), the sweep's best weight as a multiple of the chosen
one, and the rule's margins. In the second, for each of the sweep's multiples m of the chosen weight τ
(``bench_panel.sweep_weights``), a row gives the scenes on which the fixed weight m·τ passes the weight rule
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
from bench_panel import best_fixed, point, sweep_margins, sweep_weights  # noqa: E402


def merged_scenes(paths) -> dict[int, dict]:
    """Scene index -> scene of every panel file, in index order (a later file's scene replaces an earlier one's)."""
    return merged([json.loads(Path(path).read_text()) for path in paths])


def merged(panels) -> dict[int, dict]:
    """Scene index -> scene of every panel (loaded), in index order (a later panel's scene replaces an earlier one's)."""
    scenes = {scene["index"]: scene for panel in panels for scene in panel["scenes"]}
    return dict(sorted(scenes.items()))


def sweep_multiples(scene: dict) -> dict[str, str]:
    """The sweep's runs by their multiple of the chosen weight ("0.32" -> "--tv …"), from their order (the sweep's
    weights are ``bench_panel.sweep_weights`` of the chosen one)."""
    names = sorted((n for n in scene["runs"] if n.startswith("--tv ")), key=lambda n: float(n[5:]))
    return {f"{m:.2g}": name for m, name in zip(sweep_weights(1.0, len(names)), names)}


def passes(scene: dict, name: str) -> bool:
    return min(sweep_margins(scene, name)) >= 0


def at_stop(run: dict) -> str:
    """A run's last point with its iteration: "25.01 dB / 9.60° (405)"."""
    return f"{point(run)} ({run['points'][-1]['iteration']})"


def scene_table(scenes: dict[int, dict]) -> str:
    """Every scene's check of the chosen weight against the sweep's best, failing margins in bold."""
    lines = ["| # | kind | noise | τ chosen | default | `--no-skip` | best fixed weight | weight margin |",
             "|---:|---|---|---:|---|---|---|---|"]
    for i, s in scenes.items():
        default, (best, run) = s["runs"]["default"], best_fixed(s)
        multiple = {name: m for m, name in sweep_multiples(s).items()}[best]
        db, deg = sweep_margins(s)
        margin = f"{db:+.2f} dB / {deg:+.2f}°"
        lines.append(f"| {i} | {s['kind']} | {s['level']} | {default['tv_chosen']:.3g} | {at_stop(default)} | "
                     f"{at_stop(s['runs']['--no-skip'])} | ×{multiple}: {at_stop(run)} | "
                     + (margin if min(db, deg) >= 0 else f"**{margin}**") + " |")
    return "\n".join(lines)


def verdict_row(rule: str, scenes: dict[int, dict], run_of) -> tuple[str, list[int], list[int]]:
    """(rule, passing scenes, failing scenes) when each scene is judged at its run ``run_of(index, scene)``."""
    verdicts = {i: passes(s, run_of(i, s)) for i, s in scenes.items()}
    return rule, [i for i, ok in verdicts.items() if ok], [i for i, ok in verdicts.items() if not ok]


def factor_rows(scenes: dict[int, dict], low_light: float | None) -> list[tuple[str, list[int], list[int]]]:
    """(rule, passing scenes, failing scenes) for each multiple, then the rule by light level if asked."""
    multiples = {i: sweep_multiples(s) for i, s in scenes.items()}
    rows = [verdict_row(f"×{m}", scenes, lambda i, s, m=m: multiples[i][m]) for m in multiples[min(scenes)]]
    if low_light is not None:
        low = min(multiples[min(scenes)], key=lambda m: abs(np.log(float(m) / low_light)))
        rows.append(verdict_row(f"×1 in standard light, ×{low} in low light", scenes,
                                lambda i, s: multiples[i]["1" if s["level"] == "standard" else low]))
    return rows


def factor_table(rows) -> str:
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
    print(scene_table(scenes) + "\n\n" + factor_table(factor_rows(scenes, args.low_light)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
