#!/usr/bin/env python3
"""Converged by default: the default's final cube against the model's own answer, and its time against today's
300 FISTA iterations, on a fresh randomised panel (the scenes of :mod:`bench_panel`).

    python tools/bench_converged.py --size 128x160 --bands 64 --scenes 20 --out converged

Per scene, in one process and one after another:

* **today**: FISTA, 300 iterations, ``--tv auto`` (the default before ``--iters auto``);
* **default**: the default settings as they are now (whatever ``clsdcam reconstruct`` runs without options); the
  weight τ its ``--tv auto`` chooses is the scene's weight;
* **the reference**, the model's own answer at τ: FISTA and ADMM each run ``--reference-iters`` in band space, and
  for each metric the better final is taken (PSNR the higher, mean spectral angle the lower). A reference depends
  only on the scene's seed, size and τ, so it is cached under ``--cache`` (the first 20-scene panel costs about
  two hours on a 2-core machine; a replay costs the two short solves).

The rules (issue "Converged by default"), each scene's margins positive when it holds:

* **answer**: PSNR ≥ reference − 0.2 dB and angle ≤ reference + 0.5°;
* **time**: default's seconds / today's, median ≤ 1.0 and worst ≤ 2.0;
* **no regression**: not (PSNR below today's by more than 0.2 dB *and* angle above today's by more than 0.5°).

Also reported: FISTA's own seconds to come within 0.2 dB and 0.5° of the reference (from the reference run's
snapshots) over the default's, the speed-up. Writes ``converged.json`` (after every scene; with the host's ADMM
steps, ``host_steps``: compiled or NumPy's), ``converged.md`` and
``converged.png`` (every scene's PSNR and angle against seconds: both references' curves, today and the default as
points, the reference's band). ``--seed`` replays a panel, ``--only I,J`` some scenes of it; ``--weight-from
today`` takes the weight from today's run instead, ``--replay`` replays the stop at other tolerances on the
cached reference runs, and ``--converge T`` runs the default with another stopping tolerance (the package's
``--converge`` T: what a new default tolerance would give, judged by the same rules). ``--kinds points`` (or any
list of kinds) draws those kinds in turn: the simulator's scenes of a few points (``points``, ``sources``) are
among them, which the panel's five kinds are not. ``--against DIR`` times an earlier run's panel (its
``converged.json``) again on this code, today's and the default's solves, judged against that run's references:
for a change that leaves the model's answer where it was (a faster pass), whose default's weight then differs from
the cached one's in the last digits.

``--variants 'alpha=1.7,tv=0.003;alpha=1'`` measures ADMM's constants instead (``clsdcam.algorithms.admm``'s DATA,
TV, NONNEG, NONNEG_POINT_LIKE, RELAXATION, MARGIN_STEPS and BALANCE_AT, and THRESHOLD_OVER_RMS,
THRESHOLD_POINT_LIKE and THRESHOLD_FEW_POINTS of its balance, by the names data, tv, nonneg, nonneg_point, alpha,
margin, balance_at, balance, point_balance and few_balance; ``balance_at=1e9``: no balance): each variant runs
``--variant-iters`` at the scene's weight, told what the default's probe found (point-like, a few points; not an
accelerated variant, below), scored every 10 iterations, and the table gives the mark from which it stays within the rules and
where the stop would stop it at each ``--replay`` tolerance (``variants.md``, ``variants.json``). The names
``momentum`` (restart factor η), ``anderson`` (memory m) and ``spectral`` (period T) run one of
:mod:`admm_acceleration`'s accelerations (host steps; "restarts" counts its restarts, dropped points or penalty
changes). ``fista_start=N`` starts ADMM (duals zero) from N FISTA iterations' field, ``answer_start=N`` from N ADMM
iterations' (the model's own answer: the bound on any start of the primal alone, a coarse-to-fine one included);
"start" is what making it took, in the variant's own iterations' time. ``duals=1`` (ξ) or ``2`` (every dual) sets
the start's duals at their fixed-point values for its cube, ``refresh=N`` sets them so from the iterate at
iteration N, ``rebalance=N`` balances the TV penalties again there (:mod:`admm_duals`; "restarts" counts them).
"""
from __future__ import annotations

import hashlib
import json
import sys
from contextlib import contextmanager
from importlib import import_module
from pathlib import Path

import numpy as np

from admm_acceleration import ACCELERATIONS, accelerated
from admm_duals import DUAL_VARIANTS, dual_variants
from bench_accuracy import Where, add_backend_option, panel_parser, report, save_json, size_text, timed_run
from bench_panel import (add_kinds_option, chosen_scenes, panel_scene, scene_indices, progress, scene_done,
                         scene_name)
from clsdcam.algorithms.admm.algorithm import POINT_LIKE_BELOW, host_steps
from clsdcam.cli.options import WORK
from clsdcam.errors import InputError
from clsdcam.metrics import psnr, spectral_angle
from clsdcam.render import new_figure
from clsdcam.solve.auto_weights import (AUTO_AT, RECOUNT_AT, probe_reading, recount_reroutes, tell_point_like,
                                        tell_recount)
from clsdcam.solve.convergence import DistanceEstimate
from clsdcam.solve.solver import Settings

PSNR_DB, ANGLE_DEG = 0.2, 0.5           # rule 2's tolerance (and rule 4's)
TIME_MEDIAN, TIME_WORST = 1.0, 2.0      # rule 3
TODAY = {"iters": 300, "algorithm": "fista"}      # today's default: FISTA, 300 iterations, --tv auto
REFERENCE_ALGORITHMS = ("fista", "admm")
HISTORY = ("change", "data", "objective", "seconds")   # per-iteration numbers a cached reference keeps


def reference_marks(iters: int) -> list[int]:
    """Where a reference run's cube is scored: about 24 marks, log-spaced from 10 to ``iters``."""
    return sorted({int(round(m)) for m in np.geomspace(10, iters, 24)})


def timed_solve(sim, fields: dict, marks=(), x0=None) -> tuple:
    """:func:`bench_accuracy.timed_run` on a simulated scene: (result, seconds)."""
    return timed_run(sim.calibration, sim.measurement, fields, marks, x0)


def final_point(sim, result, seconds: float) -> dict:
    return {"psnr": psnr(result.cube, sim.truth), "angle": spectral_angle(result.cube, sim.truth),
            "seconds": seconds, "iterations": result.iterations, "stop_reason": result.stop_reason,
            "estimate": result.attrs.get("distance_estimate"), "tolerance": result.attrs.get("stop_tolerance"),
            "mean_over_peak": result.attrs.get("mean_over_peak"), "noise_estimate": result.attrs.get("noise_estimate"),
            "lit_voxels": result.attrs.get("lit_voxels"), "lit_per_pixel": result.attrs.get("lit_per_pixel"),
            "lit_voxels_recounted": result.attrs.get("lit_voxels_recounted")}


def curve(sim, result) -> list[dict]:
    """The run's PSNR, angle and seconds at its snapshots (seconds from its history)."""
    seconds = {r["iteration"]: r["seconds"] for r in result.history}
    return [{"iteration": k, "psnr": psnr(cube, sim.truth), "angle": spectral_angle(cube, sim.truth),
             "seconds": seconds[k]} for k, cube in sorted(result.snapshots.items())]


def cached(sim, plan: dict, tau: float, algorithm: str, iters: int, cache: Path) -> tuple[str, Path]:
    """A reference run's key and its file in ``cache`` (by seed, size, τ, algorithm and iterations)."""
    key = f"{plan['kind']}|{plan['level']}|{plan['seed']}|{sim.truth.shape}|{tau!r}|{algorithm}|{iters}"
    return key, cache / f"{hashlib.sha1(key.encode()).hexdigest()[:16]}.npz"


def reference_cube(sim, plan: dict, tau: float, algorithm: str, iters: int, cache: Path) -> np.ndarray:
    """A reference run's final cube, from ``cache`` (where :func:`reference_run` put it)."""
    return np.load(cached(sim, plan, tau, algorithm, iters, cache)[1])["cube"]


def scene_weight(sim, weight_from: str) -> tuple[float, dict]:
    """(τ, probe): the weight today's run (``weight_from`` "today") or the default's ``--tv auto`` chose, and what
    that run's probe and its recount tell ADMM, :func:`told_point_like`'s arguments (FISTA's run reads no probe:
    nothing)."""
    weight_run, _ = timed_solve(sim, TODAY if weight_from == "today" else {})
    point_like, few_points, lighter = probe_reading(weight_run.attrs, POINT_LIKE_BELOW)
    return float(weight_run.attrs["tv_chosen"]), {"point_like": point_like, "few_points": few_points,
                                                  "lighter": lighter,
                                                  "rerouted": recount_reroutes(weight_run.attrs, POINT_LIKE_BELOW)}


@contextmanager
def told_point_like(point_like: bool = False, few_points: bool = False, lighter: bool = False,
                    rerouted: bool = False):
    """While it lasts, where ``point_like``, every ADMM solve is told so before its iteration AUTO_AT + 1 (and whether
    the scene is ``few_points``, unless it is one to make ``lighter``), as the default's probe tells it
    (``Admm.point_like``), and before its iteration RECOUNT_AT + 1, where the default's recount ``rerouted``
    (:func:`clsdcam.solve.auto_weights.recount_reroutes`), what it found: lit spots on a few points
    (``Admm.lit_spots``), or a few points on a few points to make lighter (``Admm.few_points_to_lighten``). A run at a
    given weight reads no probe, so without this it would keep the penalties of the spread scenes where the default's
    change. (A stop replayed on such a run forgets its windows at AUTO_AT alone, :func:`replay_stop`, where the
    default's also does at the recount.) Only for solves at a given weight: a solve with ``--tv auto`` reads its own
    probe and would be told twice."""
    from clsdcam.algorithms.admm.algorithm import Admm

    plain = Admm.iterate

    def iterate(algorithm, problem):
        if algorithm._iterations == AUTO_AT:
            tell_point_like(algorithm, few_points, lighter)
        if algorithm._iterations == RECOUNT_AT and rerouted:
            tell_recount(algorithm, lighter)
        return plain(algorithm, problem)

    Admm.iterate = iterate if point_like else plain
    try:
        yield
    finally:
        Admm.iterate = plain


def reference_run(sim, plan: dict, tau: float, algorithm: str, iters: int, cache: Path) -> dict:
    """One reference run's curve (cached: :func:`cached`)."""
    key, path = cached(sim, plan, tau, algorithm, iters, cache)
    if path.exists():
        stored = np.load(path, allow_pickle=False)
        return {"points": [dict(zip(stored["names"], map(float, row))) for row in stored["points"]],
                "change": stored["history_change"].tolist()}
    result, seconds = timed_solve(sim, {"tv": tau, "iters": iters, "algorithm": algorithm}, reference_marks(iters))
    progress(f"{scene_name(plan)}: {algorithm}'s reference, {iters} iterations in {seconds:.0f} s")
    points = curve(sim, result)
    names = list(points[0])
    np.savez(path, names=names, points=np.array([[p[n] for n in names] for p in points]), key=key,
             **{f"history_{n}": [r[n] for r in result.history] for n in HISTORY}, cube=result.cube)
    return {"points": points, "change": [r["change"] for r in result.history]}


def reference(runs: dict) -> dict:
    """The model's own answer: the better final of the reference runs, metric by metric."""
    finals = [run["points"][-1] for run in runs.values()]
    return {"psnr": max(p["psnr"] for p in finals), "angle": min(p["angle"] for p in finals)}


def within(point: dict, ref: dict) -> bool:
    """Whether a scored ``point`` is within the answer's tolerance of ``ref`` (rule 2)."""
    return point["psnr"] >= ref["psnr"] - PSNR_DB and point["angle"] <= ref["angle"] + ANGLE_DEG


def first_within(points: list[dict], ref: dict) -> dict | None:
    """The first scored mark within the answer's tolerance of ``ref``, or None."""
    return next((p for p in points if within(p, ref)), None)


def time_within(points: list[dict], ref: dict) -> float | None:
    """Seconds of the first scored mark within the answer's tolerance of ``ref``, or None."""
    found = first_within(points, ref)
    return None if found is None else found["seconds"]


def replay_stop(run: dict, tolerance: float) -> dict | None:
    """Where ``--converge tolerance`` would have stopped a reference run (its recorded steps replayed through
    :class:`DistanceEstimate`, forgotten at AUTO_AT as a default solve's are when it chooses the weight), with the
    PSNR and angle there interpolated between the run's scored marks; None: not within the run."""
    estimate = DistanceEstimate()
    for i, change in enumerate(run["change"], start=1):
        if i == AUTO_AT + 1:
            estimate.restart()
        estimate.add(change)
        if estimate.distance < tolerance:
            marks = [p["iteration"] for p in run["points"]]
            return {"iteration": i, **{m: float(np.interp(i, marks, [p[m] for p in run["points"]]))
                                       for m in ("psnr", "angle")}}
    return None


def settled_within(points: list[dict], ref: dict) -> int | None:
    """The first scored mark from which every mark is within the answer's tolerance of ``ref``, or None."""
    inside = [within(p, ref) for p in points]
    return next((int(points[i]["iteration"]) for i in range(len(points)) if all(inside[i:])), None)


# a constant's name -> (its module in clsdcam.algorithms.admm, the constant)
ADMM_CONSTANTS = {"data": ("algorithm", "DATA"), "tv": ("algorithm", "TV"), "nonneg": ("algorithm", "NONNEG"),
                  "nonneg_point": ("algorithm", "NONNEG_POINT_LIKE"),
                  "alpha": ("algorithm", "RELAXATION"), "balance_at": ("algorithm", "BALANCE_AT"),
                  "margin": ("algorithm", "MARGIN_STEPS"),
                  "balance": ("balance", "THRESHOLD_OVER_RMS"), "point_balance": ("balance", "THRESHOLD_POINT_LIKE"),
                  "few_balance": ("balance", "THRESHOLD_FEW_POINTS")}
STARTS = {"fista_start": "fista", "answer_start": "admm"}   # a start's name -> the algorithm that makes its cube
VARIANT_NAMES = (*ADMM_CONSTANTS, *ACCELERATIONS, *STARTS, *DUAL_VARIANTS)


def parse_variants(text: str) -> list[dict]:
    """'alpha=1.7,tv=0.003;alpha=1' → [{'alpha': 1.7, 'tv': 0.003}, {'alpha': 1.0}] (names: ADMM_CONSTANTS)."""
    variants = []
    for part in filter(None, text.split(";")):
        pairs = [item.split("=") for item in part.split(",")]
        if any(len(p) != 2 or p[0] not in VARIANT_NAMES for p in pairs):
            raise ValueError(f"--variants {part!r}: NAME=VALUE pairs, names {', '.join(VARIANT_NAMES)}")
        variants.append({name: float(value) for name, value in pairs})
    return variants


@contextmanager
def admm_constants(variant: dict):
    """ADMM's module constants set to ``variant``'s (restored after; its other names are not constants)."""
    places = {key: (import_module(f"clsdcam.algorithms.admm.{module}"), name)
              for key, (module, name) in ADMM_CONSTANTS.items()}
    saved = {key: getattr(*place) for key, place in places.items()}
    try:
        for key, value in variant.items():
            if key in places:
                setattr(*places[key], value)
        yield
    finally:
        for key, value in saved.items():
            setattr(*places[key], value)


def variant_start(sim, tau: float, variant: dict) -> tuple:
    """(x0, seconds): the whole field ADMM starts from (its duals zero) and what making it took; (None, 0) for the
    zero start. ``fista_start=N``: N FISTA iterations at the scene's weight; ``answer_start=N``: N ADMM iterations,
    the model's own answer (what no start can better: the bound on any start of the primal alone). Made by the
    solver as built, whatever constants or acceleration the variant names."""
    named = [name for name in STARTS if name in variant]
    if not named:
        return None, 0.0
    iters = int(variant[named[0]])
    result, seconds = timed_solve(sim, {"tv": tau, "iters": iters, "algorithm": STARTS[named[0]], "full_field": True})
    return result.full_field, seconds


def variant_runs(plan: dict, shape, bands: int, args, cache: Path) -> dict:
    """One scene's ADMM variants at its weight (today's or the default's ``--tv auto`` choice) against its reference."""
    sim = panel_scene(plan, shape, bands)
    tau, probe = scene_weight(sim, args.weight_from)
    ref = reference({a: reference_run(sim, plan, tau, a, args.reference_iters, cache) for a in REFERENCE_ALGORITHMS})
    rows = []
    for variant in args.variants:
        x0, start_seconds = variant_start(sim, tau, variant)
        told = {} if any(name in variant for name in ACCELERATIONS) else probe
        with admm_constants(variant), accelerated(variant) as events, dual_variants(variant, events), \
                told_point_like(**told):
            result, seconds = timed_solve(sim, {"tv": tau, "iters": args.variant_iters, "algorithm": "admm"},
                                          range(10, args.variant_iters + 1, 10), x0)
        run = {"points": curve(sim, result), "change": [r["change"] for r in result.history]}
        rows.append({"variant": variant, "within": settled_within(run["points"], ref),
                     "stops": [replay_stop(run, t) for t in args.tolerances],
                     "ms_per_iteration": 1e3 * seconds / args.variant_iters, "restarts": events["restarts"],
                     "start_iterations": start_seconds / seconds * args.variant_iters,
                     "balance": balance_factors(result), "final": run["points"][-1]})
    return {**plan, "tv": tau, **probe, "reference": ref, "variants": rows}


def balance_factors(result) -> list | None:
    """The β_d (λ, y, x) the run's TV penalties were balanced by, relative to μ₂ when the balance ran (the camera's,
    or half of it on a few points to lighten, ``lighter_few_points``; times C: the threshold over the differences' RMS
    that μ₂ had), or None where it did not balance."""
    carry = result.state.carry
    balance = None if carry is None else carry[0].penalties.tv_balance
    return None if balance is None else list(balance)


def variant_rows(results: dict) -> list[str]:
    tolerances = results["replay"]
    rows = ["| # | kind | variant | start, in its iterations' time | stays within from | restarts | β_λ, β_y, β_x | "
            + " | ".join(f"stop at {t:g}" for t in tolerances) + " |",
            "|---:|---|---|---:|---|---:|---|" + "---|" * len(tolerances)]
    for s in results["scenes"]:
        for v in s["variants"]:
            name = ", ".join(f"{k} {x:g}" for k, x in v["variant"].items()) or "as built"
            cells = [stop_cell(stop, s["reference"]) for stop in v["stops"]]
            rows.append(f"| {s['index']} | {s['kind']}, {s['level']} | {name} | {v['start_iterations']:.0f} | "
                        f"{v['within'] or '–'} | {v['restarts']} | {balance_cell(v.get('balance'))} | "
                        + " | ".join(cells) + " |")
    return rows


def balance_cell(factors) -> str:
    return "–" if factors is None else ", ".join(f"{b:.2g}" for b in factors)


def regression_margin(run: dict, today: dict) -> float:
    """Rule 4's margin for a run's final point against today's (positive: it holds): not lower in PSNR by more than
    PSNR_DB *and* higher in angle by more than ANGLE_DEG at once."""
    return max(run["psnr"] - today["psnr"] + PSNR_DB, today["angle"] + ANGLE_DEG - run["angle"])


def margins(scene: dict) -> dict:
    """Every rule's margin for one scene (positive: it holds)."""
    ref, today, default = scene["reference"], scene["today"], scene["default"]
    fista_time = time_within(scene["references"]["fista"]["points"], ref)
    return {"answer_db": default["psnr"] - ref["psnr"] + PSNR_DB,
            "answer_deg": ref["angle"] + ANGLE_DEG - default["angle"],
            "time_ratio": default["seconds"] / today["seconds"],
            "regression": regression_margin(default, today),
            "speedup": None if fista_time is None else fista_time / default["seconds"]}


def run_scene(plan: dict, shape, bands: int, iters: int, cache: Path, weight_from: str = "default",
              converge: float | None = None, references: dict | None = None) -> dict:
    """Today, the default (with ``--converge converge`` where given) and the references of one scene (run or cached;
    or, given, an earlier run's ``references``: --against), with the rules' margins."""
    sim = panel_scene(plan, shape, bands)
    today_result, today_seconds = timed_solve(sim, TODAY)
    progress(f"{scene_name(plan)}: today's {today_result.iterations} iterations in {today_seconds:.0f} s")
    default_result, default_seconds = timed_solve(sim, {} if converge is None else {"converge": converge})
    progress(f"{scene_name(plan)}: the default's {default_result.iterations} iterations "
             f"({default_result.stop_reason}) in {default_seconds:.0f} s")
    tau = float((default_result if weight_from == "default" else today_result).attrs["tv_chosen"])
    runs = references or {a: reference_run(sim, plan, tau, a, iters, cache) for a in REFERENCE_ALGORITHMS}
    scene = {**plan, "tv": tau, "today": final_point(sim, today_result, today_seconds),
             "default": final_point(sim, default_result, default_seconds), "references": runs,
             "reference": reference(runs)}
    return {**scene, "margins": margins(scene)}


def summary(results: dict) -> list[str]:
    scenes = results["scenes"]
    ratios = [s["margins"]["time_ratio"] for s in scenes]
    answer = sum(min(s["margins"]["answer_db"], s["margins"]["answer_deg"]) >= 0 for s in scenes)
    kept = sum(s["margins"]["regression"] >= 0 for s in scenes)
    speedups = [s["margins"]["speedup"] for s in scenes if s["margins"]["speedup"] is not None]
    return [f"- answer (within {PSNR_DB} dB and {ANGLE_DEG}° of the reference): {answer} of {len(scenes)} scenes",
            f"- time against today's 300 FISTA iterations: median {np.median(ratios):.2f}×, worst {max(ratios):.2f}× "
            f"(rule: ≤ {TIME_MEDIAN}×, ≤ {TIME_WORST}×)",
            f"- no regression against today: {kept} of {len(scenes)} scenes",
            "- FISTA's own time to the reference's tolerance over the default's: median "
            + (f"{np.median(speedups):.2f}× ({len(speedups)} scenes where FISTA got there)" if speedups else "–")]


def scene_rows(results: dict) -> list[str]:
    rows = ["| # | kind | noise | τ | reference | today (300 it) | default | iters, stop | time × | answer margin |",
            "|---:|---|---|---:|---|---|---|---|---:|---|"]
    for s in results["scenes"]:
        m, d = s["margins"], s["default"]
        rows.append(f"| {s['index']} | {s['kind']} | {s['level']} | {s['tv']:.3g} | {pair(s['reference'])} | "
                    f"{pair(s['today'])} | {pair(d)} | {d['iterations']}, {stop_words(d)} | "
                    f"{m['time_ratio']:.2f} | {m['answer_db']:+.2f} dB / {m['answer_deg']:+.2f}° |")
    return rows


def stop_words(point: dict) -> str:
    """Why a run stopped, with the tolerance where it stopped "converged" ("converged at 0.1")."""
    tolerance = point.get("tolerance")
    return point["stop_reason"] + (f" at {tolerance:.2g}" if tolerance and point["stop_reason"] == "converged" else "")


def pair(point: dict) -> str:
    return f"{point['psnr']:.2f} dB / {point['angle']:.2f}°"


def markdown(results: dict) -> str:
    tolerance = "" if results.get("converge") is None else f", the default at --converge {results['converge']:g}"
    head = (f"Seed {results['seed']}, {results['size']}×{results['bands']}, references: FISTA and ADMM "
            f"{results['reference_iters']} iterations, backend {results['backend']}{tolerance}.")
    return "\n".join([head, ""] + summary(results) + ["", "Every scene (PSNR / mean spectral angle):", ""]
                     + scene_rows(results) + ["", "Each reference run: its first scored mark within the rules, and "
                                              "where the stop would have stopped it at each replayed tolerance "
                                              "(iteration: PSNR and angle against the reference's):", ""]
                     + replay_rows(results))


def replay_rows(results: dict) -> list[str]:
    tolerances = results.get("replay", [])
    rows = ["| # | kind | run | first within | " + " | ".join(f"stop at {t:g}" for t in tolerances) + " |",
            "|---:|---|---|---|" + "---|" * len(tolerances)]
    for s in results["scenes"]:
        ref = s["reference"]
        for name, run in s["references"].items():
            first = first_within(run["points"], ref)
            cells = [stop_cell(replay_stop(run, t), ref) for t in tolerances]
            rows.append(f"| {s['index']} | {s['kind']}, {s['level']} | {name} | "
                        f"{int(first['iteration']) if first else '–'} | " + " | ".join(cells) + " |")
    return rows


def stop_cell(stop: dict | None, ref: dict) -> str:
    if stop is None:
        return "not within the run"
    return f"{stop['iteration']}: {stop['psnr'] - ref['psnr']:+.2f} dB / {stop['angle'] - ref['angle']:+.2f}°"


def plot(results: dict, path: Path, per_row: int = 5):
    """Every scene's PSNR (upper) and angle (lower) against seconds: the reference runs' curves, today's and the
    default's finals as points, the reference's tolerance as a band."""
    scenes = results["scenes"]
    columns, rows = min(len(scenes), per_row), -(-len(scenes) // per_row)
    fig = new_figure(figsize=(3.2 * columns, 4.6 * rows))
    axes = np.array(fig.subplots(2 * rows, columns, squeeze=False))
    for i, scene in enumerate(scenes):
        pair_axes = axes[2 * (i // per_row), i % per_row], axes[2 * (i // per_row) + 1, i % per_row]
        for ax, metric, sign in zip(pair_axes, ("psnr", "angle"), (-1, 1)):
            for name, run in scene["references"].items():
                ax.plot([p["seconds"] for p in run["points"]], [p[metric] for p in run["points"]], label=name)
            ref = scene["reference"][metric]
            ax.axhspan(ref, ref + sign * (PSNR_DB if metric == "psnr" else ANGLE_DEG), color="0.85", zorder=0)
            for name, marker in (("today", "s"), ("default", "*")):
                ax.plot(scene[name]["seconds"], scene[name][metric], marker, ms=8, label=name, color="k")
            ax.set_xscale("log")
        pair_axes[0].set(title=f"{scene['index']}: {scene['kind']}, {scene['level']}", ylabel="PSNR (dB)")
        pair_axes[1].set(xlabel="seconds", ylabel="mean spectral angle (°)")
    for i in range(len(scenes), rows * columns):
        axes[2 * (i // per_row), i % per_row].set_visible(False)
        axes[2 * (i // per_row) + 1, i % per_row].set_visible(False)
    axes[0, 0].legend(fontsize=7, framealpha=0.5)
    fig.suptitle(f"Seed {results['seed']}, {results['size']}×{results['bands']}: error against time\n"
                 "(grey: within the reference's tolerance)", fontsize=10)     # two lines: a panel of two is narrow
    fig.savefig(path, dpi=90)


WEIGHT_FROM = {"default": "the default's", "today": "today's"}   # --weight-from: whose --tv auto choice


def add_panel_options(parser, scenes: int, reference_iters: int, weight_from: str, seed_required: bool = False):
    """The options of a tool on this module's panel and its reference cache (bench_stop's too): --scenes, --kinds,
    --seed, --only, --reference-iters, --cache and --weight-from, with the tool's defaults."""
    parser.add_argument("--scenes", type=int, default=scenes, help=f"random scenes (kinds in turn; default {scenes})")
    add_kinds_option(parser)
    parser.add_argument("--seed", type=int, default=None, required=seed_required,
                        help="the panel" + ("" if seed_required else " to replay (default: fresh entropy)"))
    parser.add_argument("--only", type=scene_indices, metavar="I[,J...]", help="these scenes of the panel alone")
    parser.add_argument("--reference-iters", type=int, default=reference_iters,
                        help=f"each reference run's iterations (default {reference_iters})")
    parser.add_argument("--cache", default=f"{WORK}/converged-cache", help="folder of cached reference runs")
    parser.add_argument("--weight-from", choices=tuple(WEIGHT_FROM), default=weight_from,
                        help=f"whose --tv auto choice is the scene's weight (default: {WEIGHT_FROM[weight_from]})")


def stored_panel(parser, args) -> tuple[int, list[tuple[int, dict, dict]]]:
    """--against DIR: the seed of the run in DIR/converged.json and its scenes that --only keeps, each as (index,
    plan, references); its size, bands, kinds and reference iterations replace the options'. A file that cannot be
    read, or an index of --only that it does not hold, is the parser's one-line error."""
    path = Path(args.against) / "converged.json"
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
        args.size, args.bands = tuple(int(n) for n in stored["size"].split("x")), stored["bands"]
        args.reference_iters, args.kinds = stored["reference_iters"], stored["kinds"]
        scenes = [(s["index"], {k: s[k] for k in ("kind", "level", "seed")}, s["references"])
                  for s in stored["scenes"]]
        seed = stored["seed"]
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        parser.error(f"--against {args.against}: not a run's converged.json ({error!r})")
    missing = sorted(set(args.only or ()) - {index for index, _, _ in scenes})
    if missing:
        parser.error(f"--only {','.join(map(str, missing))}: not among {path}'s scenes")
    if not scenes:
        parser.error(f"--against {args.against}: {path} holds no scenes")
    return seed, [scene for scene in scenes if not args.only or scene[0] in args.only]


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "converged", named_scenes=False)
    parser.set_defaults(size=(128, 160))
    add_panel_options(parser, scenes=20, reference_iters=3000, weight_from="default")
    parser.add_argument("--replay", default="0.1,0.05,0.03",
                        help="tolerances at which to replay the stop on the reference runs (the table's last part)")
    parser.add_argument("--variants", default="", metavar="NAME=V[,…][;…]",
                        help="measure ADMM's constants, accelerations or starts instead (names: "
                             f"{', '.join(VARIANT_NAMES)}; the docstring)")
    parser.add_argument("--variant-iters", type=int, default=500, help="each variant's iterations (default 500)")
    parser.add_argument("--converge", type=float, default=None, metavar="T",
                        help="the default's stopping tolerance (default: the package's, --converge's default)")
    parser.add_argument("--against", metavar="DIR",
                        help="time the panel of an earlier run (DIR/converged.json) again on this code, judged against "
                             "that run's references (a change that leaves the model's answer where it was)")
    add_backend_option(parser)
    args = parser.parse_args(argv)
    try:
        args.variants = parse_variants(args.variants)
    except ValueError as error:
        parser.error(str(error))
    if args.converge is not None:
        try:
            Settings(converge=args.converge)          # the package's own rule for --converge
        except InputError as error:
            parser.error(str(error))
    host_only = {*ACCELERATIONS, *DUAL_VARIANTS}
    if args.backend != "numpy" and any(set(v) & host_only for v in args.variants):
        parser.error("--variants momentum/anderson/spectral/duals/refresh/rebalance wrap the host steps: "
                     "--backend numpy")
    if args.against and args.variants:
        parser.error("--against re-times the default and today: no --variants")
    Where.use(args.backend)
    if args.against:
        seed, chosen = stored_panel(parser, args)
    else:
        seed = args.seed if args.seed is not None else int(np.random.SeedSequence().entropy % 2 ** 63)
        chosen = [(i, plan, None) for i, plan in chosen_scenes(parser, args, seed)]
    out, cache = Path(args.out), Path(args.cache)
    out.mkdir(parents=True, exist_ok=True)
    cache.mkdir(parents=True, exist_ok=True)
    results = {"seed": seed, "kinds": args.kinds, "size": size_text(args.size), "bands": args.bands,
               "backend": args.backend, "reference_iters": args.reference_iters, "weight_from": args.weight_from,
               "converge": args.converge, "replay": [float(t) for t in args.replay.split(",") if t],
               "against": args.against, "scenes": [],
               "host_steps": host_steps().__name__ if args.backend == "numpy" else None}
    args.tolerances = results["replay"]
    name = "variants" if args.variants else "converged"
    print(f"panel seed {seed}", file=sys.stderr, flush=True)
    for i, plan, references in chosen:
        scene = (variant_runs(plan, args.size, args.bands, args, cache) if args.variants else
                 run_scene(plan, args.size, args.bands, args.reference_iters, cache, args.weight_from, args.converge,
                           references))
        results["scenes"].append({"index": i, **scene})
        scene_done(i, plan, args.scenes)
        save_json(out, name, results)
    if args.variants:
        report(out, name, results, "\n".join(variant_rows(results)))
        return 0
    report(out, name, results, markdown(results))
    plot(results, out / "converged.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
