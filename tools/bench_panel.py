#!/usr/bin/env python3
"""Randomised accuracy panel: the default solver against the full solver (``--no-skip``) and against a sweep of
fixed TV weights, on random scenes of every kind (:mod:`clsdcam.sim.kinds`) at two noise levels.

    python tools/bench_panel.py --size 128x160 --bands 64 --scenes 20 --marks 50,100,300 --out panel

Every run draws fresh seeds (``--seed`` replays one: it is printed and recorded), so the panel cannot be tuned
on: each scene is a new layout (but the fixed one of ``--kinds sources``), new spectra, a new PSF and filter array
(the simulator's, from the scene's seed) and new noise. Scene i is of kind ``KINDS[i mod 5]`` at noise level
``LEVELS[(i div 5) mod 2]`` (with ``--kinds``, of those kinds in turn; the simulator's scenes of a few points,
``POINT_SCENES``, may be among them).

The rules, at every mark (accuracy.md's, permanent): the default's PSNR ≥ ``--no-skip``'s − 0.2 dB and its mean
spectral angle ≤ ``--no-skip``'s + 0.5°. The weight's rule, at the last mark: the default's PSNR ≥ the best fixed
weight's − 0.5 dB and its angle ≤ that run's + 1°, the fixed weights spanning a decade either side of the one
the default chose (``--sweep`` points, log-spaced). Per kind the table gives the worst and the median margin
(positive: the rule holds by that much). Writes ``panel.json`` after every scene, ``panel.md``, ``panel.png``
(every rule's margins, every scene, one colour a kind) and ``curves.png`` (every scene's PSNR and angle at the
marks, one line a configuration). ``--also support-field`` (or ``subspace``) judges that
speed option by the same rule on every scene, ``--also 'algorithm admm'`` the other algorithm, at the same marks and
at a third of them (its PSNR at mark m/3 against ``--no-skip``'s at m, for the marks that have their third);
``--only I,J`` replays some scenes of a panel. ``--marks auto`` runs every configuration, the sweep's weights
included, to the default stop (``--iters auto``) and judges each at its own final cube: the weight's rule at
convergence, where the stop, not a mark, ends each run. Without real cubes in ``../shared/data`` the ``real`` kind
is left out (said on stderr). With fixed marks every run but ``--also 'algorithm admm'`` is FISTA (the solver's
``--algorithm auto`` picks it for a fixed iteration count), so ``--marks 300`` is today's default (FISTA, 300
iterations) on the scenes of a ``--marks auto`` panel of the same seed: the weight judged before and after the
converged default, paired. Each run keeps its ``algorithm``.
"""
from __future__ import annotations

import argparse
import sys
from functools import partial
from pathlib import Path

import numpy as np

from bench_accuracy import (ANGLE_MARGIN_DEG, PSNR_MARGIN_DB, Where, add_backend_option, panel_parser, report, save_json,
                            scene_points, size_text, solve)
from clsdcam.render import new_figure
from clsdcam.sim import band_wavelengths, shared_data_dir, simulate
from clsdcam.sim.kinds import KINDS, make_kind, real_cubes
from clsdcam.solve.settings import AUTO

LEVELS = {"standard": {"noise_var": 1e-5, "photons": 2e4}, "low light": {"noise_var": 1e-4, "photons": 2e3}}
SWEEP_PSNR_DB, SWEEP_ANGLE_DEG = 0.5, 1.0
POINT_SCENES = ("points", "sources")   # the simulator's scenes of a few points (clsdcam.sim.scenes), for --kinds
ALSO = {"support-field": {"support_field": True}, "subspace": {"subspace": True},   # what --also judges
        "algorithm admm": {"algorithm": "admm"}}


def scene_name(plan: dict) -> str:
    """A panel scene's kind and noise level, as the progress lines name it: "sparse, low light"."""
    return f"{plan['kind']}, {plan['level']}"


def progress(text: str) -> None:
    """One line of a long run's progress on stderr (a full-size scene's solves take an hour on a laptop's CPU)."""
    print(f"  {text}", file=sys.stderr, flush=True)


def scene_done(index: int, plan: dict, scenes: int) -> None:
    progress(f"scene {index + 1}/{scenes} ({scene_name(plan)}) done")


def scene_plan(count: int, seed: int, kinds=tuple(KINDS)) -> list[dict]:
    """Scene i: its kind (``kinds`` in turn), noise level and own seed (from ``seed``'s SeedSequence)."""
    levels = list(LEVELS)
    seeds = np.random.SeedSequence(seed).generate_state(count)
    return [{"kind": kinds[i % len(kinds)], "level": levels[(i // len(kinds)) % len(levels)], "seed": int(s)}
            for i, s in enumerate(seeds)]


def panel_kinds() -> list[str]:
    """The kinds a panel draws in turn: every kind, less ``real`` when no real cube is at hand (said on stderr)."""
    kinds = [kind for kind in KINDS if kind != "real" or real_cubes(shared_data_dir())]
    if "real" in KINDS and "real" not in kinds:
        print("kind 'real' left out: no real cube in ../shared/data (or $CLSDCAM_DATA)", file=sys.stderr)
    return kinds


def sweep_weights(chosen: float, points: int) -> list[float]:
    """``points`` fixed weights log-spaced over a decade either side of ``chosen``."""
    return [float(chosen * 10.0 ** e) for e in np.linspace(-1.0, 1.0, points)]


def scene_indices(text: str) -> list[int]:
    """--only's value, "I,J,…", as scene indices in the order given (an argparse type: anything else is the
    parser's one-line error)."""
    try:
        indices = [int(i) for i in text.split(",") if i.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: scene indices are whole numbers, e.g. 5,6,9") from None
    if not indices or min(indices) < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: scene indices are whole numbers from 0, e.g. 5,6,9")
    return indices


def chosen_scenes(parser, args, seed: int) -> list[tuple[int, dict]]:
    """The panel's (index, plan) pairs that --only keeps (all without it), of --kinds (:func:`add_kinds_option`) in
    turn; an index outside the panel is the parser's error."""
    only = set(args.only or ())
    if not all(i < args.scenes for i in only):
        parser.error(f"--only {','.join(map(str, args.only))}: the panel has scenes 0 … {args.scenes - 1}")
    plans = scene_plan(args.scenes, seed, args.kinds or panel_kinds())
    return [(i, plan) for i, plan in enumerate(plans) if not only or i in only]


def add_kinds_option(parser) -> None:
    """--kinds: the kinds a panel draws in turn (:func:`kind_list`; default :func:`panel_kinds`)."""
    parser.add_argument("--kinds", type=kind_list, metavar="K[,L...]",
                        help="the kinds drawn in turn (default: every kind of clsdcam.sim.kinds; also "
                             f"{', '.join(POINT_SCENES)}, the simulator's scenes of a few points)")


def kind_list(text: str) -> list[str]:
    """--kinds' value, "K,L,…", as kinds a panel draws in turn: of :data:`KINDS` and :data:`POINT_SCENES` (an
    argparse type: anything else is the parser's one-line error)."""
    kinds = [kind.strip() for kind in text.split(",") if kind.strip()]
    unknown = [kind for kind in kinds if kind not in KINDS and kind not in POINT_SCENES]
    if not kinds or unknown:
        raise argparse.ArgumentTypeError(f"{text!r}: kinds are {', '.join((*KINDS, *POINT_SCENES))}")
    return kinds


def panel_scene(plan: dict, shape, bands: int):
    """The simulation of one planned scene: its kind's cube (or the simulator's scene of that name), the
    simulator's camera and noise, all from its seed."""
    seed, noise = plan["seed"] % 2 ** 31, LEVELS[plan["level"]]
    if plan["kind"] in POINT_SCENES:
        return simulate(scene=plan["kind"], shape=shape, n_bands=bands, seed=seed, **noise)
    cube = make_kind(plan["kind"], shape, band_wavelengths(bands), plan["seed"])
    return simulate(scene=f"kind:{plan['kind']}", shape=shape, n_bands=bands, seed=seed, cube=cube, **noise)


def run_scene(plan: dict, shape, bands: int, marks, points: int, also=()) -> dict:
    sim = panel_scene(plan, shape, bands)
    runs = {}
    for name, fields in {"default": {}, "--no-skip": {"skip": False}, **{f"--{a}": ALSO[a] for a in also}}.items():
        runs[name] = run(sim, fields, marks)
    for tau in sweep_weights(runs["default"]["tv_chosen"], points) if points else ():
        runs[f"--tv {tau:.3g}"] = run(sim, {"tv": tau}, marks if marks == AUTO else marks[-1:])
    return {**plan, "runs": runs}


def run(sim, fields: dict, marks) -> dict:
    snapshots, attrs = solve(sim.calibration, sim.measurement, fields, marks)
    return {"points": scene_points("", sim, snapshots), **attrs}


def rule_margins(scene: dict, name: str = "default") -> tuple[float, float]:
    """(PSNR margin dB, angle margin °) of run ``name`` (the default) against --no-skip: the smallest over the marks."""
    pairs = list(zip(scene["runs"][name]["points"], scene["runs"]["--no-skip"]["points"]))
    return (min(d["psnr"] - f["psnr"] + PSNR_MARGIN_DB for d, f in pairs),
            min(f["angle"] - d["angle"] + ANGLE_MARGIN_DEG for d, f in pairs))


def third_margins(scene: dict, name: str) -> tuple[float, float] | None:
    """(PSNR margin dB, angle margin °) of run ``name`` at mark m/3 against --no-skip at mark m, the smallest over the
    marks whose third is a mark too; None when none is."""
    own = {p["iteration"]: p for p in scene["runs"][name]["points"]}
    pairs = [(own[f["iteration"] // 3], f) for f in scene["runs"]["--no-skip"]["points"]
             if f["iteration"] % 3 == 0 and f["iteration"] // 3 in own]
    if not pairs:
        return None
    return (min(d["psnr"] - f["psnr"] + PSNR_MARGIN_DB for d, f in pairs),
            min(f["angle"] - d["angle"] + ANGLE_MARGIN_DEG for d, f in pairs))


def best_fixed(scene: dict) -> tuple[str, dict] | None:
    """(name, run) of the sweep's best fixed weight by PSNR at the last mark; None without a sweep."""
    fixed = [(name, r) for name, r in scene["runs"].items() if name.startswith("--tv ")]
    return max(fixed, key=lambda item: item[1]["points"][-1]["psnr"]) if fixed else None


def sweep_margins(scene: dict, name: str = "default") -> tuple[float, float] | None:
    """(PSNR margin dB, angle margin °) of run ``name``'s weight (the default's) against the sweep's best fixed
    weight (by PSNR) at the last mark; None without a sweep."""
    found = best_fixed(scene)
    if found is None:
        return None
    best, own = found[1], scene["runs"][name]["points"][-1]
    return (own["psnr"] - best["points"][-1]["psnr"] + SWEEP_PSNR_DB,
            best["points"][-1]["angle"] - own["angle"] + SWEEP_ANGLE_DEG)


def kind_margins(results: dict, kind: str, margins) -> list[tuple[float, float]]:
    """``margins(scene)`` of every scene of ``kind`` that has them."""
    return [m for s in results["scenes"] if s["kind"] == kind for m in [margins(s)] if m is not None]


def kind_rows(results: dict, margins, label: str) -> list[str]:
    """Per kind: scenes, the worst and the median of both margins, and whether every scene passes."""
    rows = [f"| kind | scenes | {label}: worst / median PSNR margin | worst / median angle margin | every scene |",
            "|---|---:|---|---|---|"]
    for kind in KINDS:
        found = kind_margins(results, kind, margins)
        if found:
            psnrs, angles = np.array(found).T
            rows.append(f"| {kind} | {len(found)} | {psnrs.min():+.2f} / {np.median(psnrs):+.2f} dB | "
                        f"{angles.min():+.2f} / {np.median(angles):+.2f}° | "
                        f"{'passes' if min(psnrs.min(), angles.min()) >= 0 else 'FAILS'} |")
    return rows


def scene_rows(results: dict) -> list[str]:
    rows = ["| # | kind | noise | seed | τ chosen | default, last mark | --no-skip | best fixed τ: PSNR / SA | "
            "rank |", "|---:|---|---|---|---:|---|---|---|---:|"]
    for s in results["scenes"]:
        i, (d, f) = s["index"], (s["runs"][n] for n in ("default", "--no-skip"))
        best = best_fixed(s)
        rows.append(f"| {i} | {s['kind']} | {s['level']} | {s['seed']} | {d['tv_chosen']:.3g} | {point(d)} | "
                    f"{point(f)} | " + (f"{best[0][5:]}: {point(best[1])}" if best else "–") +
                    f" | {d.get('final_rank', '')} |")
    return rows


def point(run: dict) -> str:
    last = run["points"][-1]
    return f"{last['psnr']:.2f} dB / {last['angle']:.2f}°"


def markdown(results: dict) -> str:
    lines = [f"Seed {results['seed']}, {results['size']}×{results['bands']}, marks {results['marks']}.", "",
             "The default against `--no-skip` at every mark (margins ≥ 0 pass: PSNR ≥ full − 0.2 dB, "
             "SA ≤ full + 0.5°):", ""] + kind_rows(results, rule_margins, "rule")
    for name in results.get("also", ()):
        lines += ["", f"`--{name}` against `--no-skip`, the same rule:", ""] + \
            kind_rows(results, partial(rule_margins, name=f"--{name}"), "rule")
        if any(third_margins(s, f"--{name}") for s in results["scenes"]):
            lines += ["", f"`--{name}` at a third of `--no-skip`'s iterations (mark m/3 against m), the same rule:",
                      ""] + kind_rows(results, partial(third_margins, name=f"--{name}"), "rule")
    if any(sweep_margins(s) for s in results["scenes"]):
        lines += ["", "The chosen weight against the sweep's best fixed weight at the last mark (margins ≥ 0 pass: "
                  "PSNR ≥ best − 0.5 dB, SA ≤ its + 1°):", ""] + kind_rows(results, sweep_margins, "weight")
    return "\n".join(lines + ["", "Every scene:", ""] + scene_rows(results))


def margin_panels(results: dict) -> list[tuple[str, object]]:
    """(title, margins) of every rule the panel judged: the default's, each ``--also`` option's, the sweep's."""
    panels = [("default against --no-skip, worst mark", rule_margins)]
    panels += [(f"--{name} against --no-skip, worst mark", partial(rule_margins, name=f"--{name}"))
               for name in results.get("also", ())]
    if any(sweep_margins(s) for s in results["scenes"]):
        panels.append(("chosen weight against the best fixed weight", sweep_margins))
    return panels


def plot(results: dict, path: Path):
    """``panel.png``: every scene's two margins (PSNR, angle) for each rule the panel judged, one colour a kind; a
    scene passes a rule when its point lies in the upper right quadrant."""
    panels = margin_panels(results)
    fig = new_figure(figsize=(5 * len(panels), 4.5))
    for ax, (title, margins) in zip(np.atleast_1d(fig.subplots(1, len(panels))), panels):
        for kind in KINDS:
            found = kind_margins(results, kind, margins)
            if found:
                ax.scatter(*np.array(found).T, label=kind, alpha=0.8)
        ax.axhline(0, color="k", lw=0.8)
        ax.axvline(0, color="k", lw=0.8)
        ax.set(title=title, xlabel="PSNR margin (dB)", ylabel="spectral angle margin (°)")
    fig.axes[0].legend(fontsize=8)
    fig.suptitle(f"Randomised panel, seed {results['seed']}, {results['size']}×{results['bands']}: "
                 "margins ≥ 0 pass", fontsize=10)
    fig.savefig(path, dpi=100)


def plot_curves(results: dict, path: Path, per_row: int = 5):
    """``curves.png``: every scene's PSNR (upper plot) and mean spectral angle (lower) at the marks, one line per
    configuration judged (the sweep's fixed weights left out)."""
    scenes = results["scenes"]
    columns, rows = min(len(scenes), per_row), -(-len(scenes) // per_row)
    fig = new_figure(figsize=(3 * columns, 4.4 * rows))
    axes = np.array(fig.subplots(2 * rows, columns, squeeze=False))
    for i, scene in enumerate(scenes):
        top, bottom = axes[2 * (i // per_row), i % per_row], axes[2 * (i // per_row) + 1, i % per_row]
        for name, run in scene["runs"].items():
            if name.startswith("--tv "):
                continue
            marks = [p["iteration"] for p in run["points"]]
            style = dict(label=name, marker="o", ms=3, ls="--" if name == "default" else "-",
                         zorder=3 if name == "default" else 2)      # over --no-skip's line when they agree
            top.plot(marks, [p["psnr"] for p in run["points"]], **style)
            bottom.plot(marks, [p["angle"] for p in run["points"]], **style)
        top.set(title=f"{scene['index']}: {scene['kind']}, {scene['level']}", ylabel="PSNR (dB)")
        bottom.set(xlabel="iterations", ylabel="mean spectral angle (°)")
        for ax in (top, bottom):
            ax.set_xscale("log")
            if results["marks"] != AUTO:
                ax.set_xticks(results["marks"], [str(m) for m in results["marks"]], fontsize=7)
                ax.minorticks_off()
    for i in range(len(scenes), rows * columns):
        axes[2 * (i // per_row), i % per_row].set_visible(False)
        axes[2 * (i // per_row) + 1, i % per_row].set_visible(False)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Randomised panel, seed {results['seed']}, {results['size']}×{results['bands']}: error at the marks",
                 fontsize=10)
    fig.savefig(path, dpi=90)


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "panel", named_scenes=False)
    parser.set_defaults(size=(128, 160))
    parser.add_argument("--scenes", type=int, default=20, help="random scenes (kinds in turn; default 20)")
    add_kinds_option(parser)
    parser.add_argument("--marks", default="50,100,300",
                        help="the iterations judged (auto: every run to the default stop, judged at its final cube)")
    parser.add_argument("--sweep", type=int, default=5, help="fixed weights a decade either side (0: no sweep)")
    parser.add_argument("--seed", type=int, default=None, help="replay a panel (default: fresh entropy)")
    parser.add_argument("--only", type=scene_indices, metavar="I[,J...]", help="these scenes of the panel alone")
    parser.add_argument("--also", action="append", choices=list(ALSO), default=[],
                        help="also judge this speed option by the rule, on every scene (repeatable)")
    add_backend_option(parser)
    args = parser.parse_args(argv)
    Where.use(args.backend)
    seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2 ** 63)
    chosen = chosen_scenes(parser, args, seed)
    marks = AUTO if args.marks == AUTO else sorted(int(m) for m in args.marks.split(","))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"seed": seed, "size": size_text(args.size), "bands": args.bands, "marks": marks, "also": args.also,
               "backend": args.backend, "scenes": []}
    print(f"panel seed {seed}", file=sys.stderr, flush=True)
    for i, plan in chosen:
        results["scenes"].append({"index": i, **run_scene(plan, args.size, args.bands, marks, args.sweep, args.also)})
        scene_done(i, plan, args.scenes)
        save_json(out, "panel", results)
    report(out, "panel", results, markdown(results))
    plot(results, out / "panel.png")
    plot_curves(results, out / "curves.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
