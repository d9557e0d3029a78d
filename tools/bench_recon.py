#!/usr/bin/env python3
"""Run time against error: every configuration on every simulated scene, side by side with the
authors' published algorithm (tools/authors_baseline.py), all in one run.

    python tools/bench_recon.py --size 128x160 --bands 64 --iters 500 --out bench-recon

For each scene and configuration it records, at fixed iterations: wall time since the solver was
made (set-up included), objective, PSNR and mean spectral angle against the truth, and the
relative error against a converged float64 solution of the full problem (``--reference-iters``).
Writes ``results.json``, ``results.md`` and ``error_vs_time.png`` (log axes) in ``--out`` and
prints two tables: speed against the authors' algorithm (how much sooner each configuration reaches
the PSNR the authors' algorithm has after its last iteration), and what the skips cost (the default
against the full solver, ``--no-skip``: its final PSNR, and how soon the default comes within 0.2 dB
of it).

The authors' seconds leave out the time spent scoring their cubes; their seconds per iteration are timed
between the first and the last scored iteration. At full size 500 published iterations take over an hour
per scene. ``--authors-timed N`` times only their set-up and first N iterations and takes the error curve
from ``AuthorsReplay``, the same iteration in float32 with real FFTs, placing its k-th iterate at set-up +
k × the published seconds per iteration (their iteration has no adaptive parts, so its cost does not
change from one to the next); the replay's cube after iteration N is compared with the published one
(``replay_difference``, relative). The replays run after every timed run, side by side, so they never
share the machine with a timing. ``--reference-iters 0`` leaves the relative-error column out.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from authors_baseline import AuthorsReplay, AuthorsSolver  # noqa: E402

from clsdcam.cli.options import WORK  # noqa: E402
from clsdcam.metrics import psnr, relative_error, spectral_angle  # noqa: E402
from clsdcam.sim import simulate  # noqa: E402
from clsdcam.solve.solver import Settings, Solver  # noqa: E402

CONFIGS = {  # name -> (backend, Settings fields)
    "numpy": ("numpy", {}),
    "numpy --no-skip": ("numpy", {"skip": False}),
    "numpy --algorithm admm": ("numpy", {"algorithm": "admm"}),
    "numpy --support-field": ("numpy", {"support_field": True}),
    "numpy --subspace --support-field": ("numpy", {"subspace": True, "support_field": True}),
    "opencl": ("opencl", {}),
    "opencl --no-skip": ("opencl", {"skip": False}),
    "numpy float64": ("numpy", {"dtype": "float64"}),
}
RANKED = "numpy --rank "     # + N: the default at a fixed basis size (what an oracle rank would give)
AUTHORS = "authors"
FULL, DEFAULT = "numpy --no-skip", "numpy"
SKIP_MARGIN_DB = 0.2


def config(name: str) -> tuple[str, dict]:
    """(backend, Settings fields) of a configuration name: one of CONFIGS, or ``numpy --rank N``."""
    if name.startswith(RANKED) and name[len(RANKED):].isdigit():
        return "numpy", {"rank": int(name[len(RANKED):])}
    if name not in CONFIGS:
        raise ValueError(f"unknown configuration {name!r} (from: {', '.join(CONFIGS)}, {RANKED}N)")
    return CONFIGS[name]


def marks(iters: int) -> list[int]:
    """Every 5 iterations up to 100, then every 10, and the last."""
    return sorted(set(range(5, min(iters, 100) + 1, 5)) | set(range(100, iters + 1, 10)) | {1, iters})


def point(k, seconds, cube, truth, reference) -> dict:
    return {"iteration": k, "seconds": seconds, "psnr": psnr(cube, truth), "angle": spectral_angle(cube, truth),
            "error": None if reference is None else relative_error(cube, reference)}


def run_clsdcam(sim, backend, fields, iters, reference) -> dict:
    """Curve points; times include making the solver and each solve's work before its first iteration."""
    start = time.perf_counter()
    solver = Solver(sim.calibration, backend=backend, settings=Settings(iters=iters, **fields))
    made = time.perf_counter()
    result = solver.solve(sim.measurement, snapshots=marks(iters))
    overhead = (made - start) + (time.perf_counter() - made) - result.history[-1]["seconds"]
    seconds = [r["seconds"] for r in result.history]
    curve = [point(k, overhead + seconds[k - 1], cube, sim.truth, reference) for k, cube in sorted(result.snapshots.items())]
    return {"curve": curve, "per_iteration": seconds[-1] / len(seconds), "setup": overhead,
            "fft": solver.backend.fft_engine, "skips": result.attrs["skips"], "ranks": [r["rank"] for r in result.history]}


def run_authors(sim, iters, reference, timed: int = 0) -> tuple[dict, AuthorsSolver, np.ndarray]:
    """(run, solver, last cube) of the published solver over ``iters`` iterations, or over its first ``timed``
    only, to be replayed (:func:`replay_authors`). The time spent scoring cubes is left out; the seconds per
    iteration are those between the first and the last scored iteration (the first also pays warm-up; with one
    iteration, since set-up)."""
    start = time.perf_counter()
    solver = AuthorsSolver(sim.calibration.psf, sim.calibration.filters)
    setup = time.perf_counter() - start
    wanted, curve, scoring = set(marks(timed or iters)), [], 0.0
    for k, cube in solver.run(sim.measurement, timed or iters):
        if k in wanted:
            now = time.perf_counter()
            curve.append(point(k, now - start - scoring, cube, sim.truth, reference))
            scoring += time.perf_counter() - now
    first, last = curve[0] if len(curve) > 1 else {"iteration": 0, "seconds": setup}, curve[-1]   # one: from set-up
    per_iteration = (last["seconds"] - first["seconds"]) / (last["iteration"] - first["iteration"])
    return {"curve": curve, "per_iteration": per_iteration, "setup": setup, "fft": "numpy complex128"}, solver, cube


def replay_authors(sim, run: dict, solver: AuthorsSolver, published: np.ndarray, iters: int, reference) -> dict:
    """A timed :func:`run_authors` ``run`` with its curve from :class:`AuthorsReplay` over ``iters`` iterations, the
    k-th at set-up + k × the published seconds per iteration. ``replay_difference``: the relative error of the
    replay's cube against ``published``, the published cube after the last timed iteration."""
    timed = run["curve"][-1]["iteration"]
    wanted, curve = set(marks(iters)), []
    for k, cube in AuthorsReplay(solver).run(sim.measurement, iters):
        if k == timed:
            difference = relative_error(cube, published)
        if k in wanted:
            curve.append(point(k, run["setup"] + k * run["per_iteration"], cube, sim.truth, reference))
    return {**run, "curve": curve, "timed_curve": run["curve"], "timed_iterations": timed,
            "replay_difference": difference, "fft": "numpy complex128 (timed); replay float32 scipy rfft"}


def time_to_reach(curve, target_psnr):
    """Seconds until the curve first reaches ``target_psnr`` (None if it never does)."""
    return next((p["seconds"] for p in curve if p["psnr"] >= target_psnr), None)


def speed_table(results) -> str:
    """Per configuration: how much sooner it reaches the PSNR the authors' algorithm has after its last
    iteration, against that run's time and against the first time the authors' curve reaches that PSNR
    (their PSNR can peak earlier and fall)."""
    lines = ["| scene | configuration | s/iteration | set-up s | final PSNR dB | final SA ° | rel. error | "
             "time to the authors' final PSNR | speed-up vs their run | vs their first time there |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for scene, configs in results.items():
        authors = configs.get(AUTHORS, {}).get("curve")
        target = authors[-1]["psnr"] if authors else None
        first = time_to_reach(authors, target) if authors else None
        for name, run in configs.items():
            last = run["curve"][-1]
            reach = time_to_reach(run["curve"], target) if authors else None
            versus = (f"{authors[-1]['seconds'] / reach:.0f}× | {first / reach:.0f}×" if reach and name != AUTHORS
                      else "— | —")
            error = "—" if last["error"] is None else f"{last['error']:.3f}"
            lines.append(f"| {scene} | {name} | {run['per_iteration']:.4f} | {run.get('setup', 0.0):.2f} | "
                         f"{last['psnr']:.2f} | {last['angle']:.1f} | {error} | "
                         f"{f'{reach:.2f} s' if reach else 'not reached'} | {versus} |")
    return "\n".join(lines)


def skip_table(results) -> str:
    """The default (skips on) against the full solver, per scene."""
    lines = [f"| scene | full solver: final PSNR, time | default: final PSNR | PSNR cost of the skips (< 0: a gain) | "
             f"time to within {SKIP_MARGIN_DB} dB of the full solver's final: full / default | ratio | final rank |",
             "|---|---|---:|---:|---|---:|---:|"]
    for scene, configs in results.items():
        if FULL not in configs or DEFAULT not in configs:
            continue
        full, fast = configs[FULL]["curve"], configs[DEFAULT]["curve"]
        target = full[-1]["psnr"] - SKIP_MARGIN_DB
        t_full, t_fast = time_to_reach(full, target), time_to_reach(fast, target)
        ratio = f"{t_fast / t_full:.2f}" if t_full and t_fast else "—"
        lines.append(f"| {scene} | {full[-1]['psnr']:.2f} dB, {full[-1]['seconds']:.1f} s | {fast[-1]['psnr']:.2f} dB | "
                     f"{full[-1]['psnr'] - fast[-1]['psnr']:+.2f} dB | {t_full:.1f} s / "
                     f"{f'{t_fast:.1f} s' if t_fast else 'never'} | {ratio} | {configs[DEFAULT]['ranks'][-1]} |")
    return "\n".join(lines)


PLOTTED = {"error": "relative error vs converged\nfull-problem float64 solution", "psnr": "PSNR vs truth (dB)",
           "angle": "mean spectral angle\nvs truth (°)"}


def plot(results, path: Path):
    """Top row (with a reference): relative error against the converged full-problem solution; then PSNR and mean
    spectral angle against the truth (a subspace solution, or another algorithm's with its own prior, converges to
    its own optimum, so the rows tell different stories)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    runs = [run for configs in results.values() for run in configs.values()]
    rows = [key for key in PLOTTED if all(run["curve"][0][key] is not None for run in runs)]
    fig = Figure(figsize=(3.6 * len(results), 3.2 * len(rows)))
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(rows), len(results), squeeze=False)
    for column, (scene, configs) in zip(axes.T, results.items()):
        for name, run in configs.items():
            seconds = [p["seconds"] for p in run["curve"]]
            style = {"marker": "." if name == AUTHORS else None, "lw": 1.2, "label": name}
            for ax, key in zip(column, rows):
                (ax.loglog if key == "error" else ax.semilogx)(seconds, [p[key] for p in run["curve"]], **style)
        column[0].set(title=scene)
        column[-1].set(xlabel="seconds (set-up included)")
        for ax in column:
            ax.grid(True, which="both", alpha=0.3)
    for ax, key in zip(axes[:, 0], rows):
        ax.set_ylabel(PLOTTED[key])
    axes[-1, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)


def save(results, out: Path):
    """results.json (written after every scene: partial results survive a stop)."""
    (out / "results.json").write_text(json.dumps(results, indent=1))


def converged_reference(sim, iters: int):
    """A float64 ``--no-skip`` solution of ``iters`` iterations (None for 0)."""
    if not iters:
        return None
    return Solver(sim.calibration, settings=Settings(iters=iters, dtype="float64", skip=False)).solve(sim.measurement).cube


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="leds,target,piecewise,realcube")
    parser.add_argument("--size", default="128x160")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--iters", type=int, default=500, help="iterations of every configuration")
    parser.add_argument("--authors-iters", type=int, default=500, help="0 leaves the authors' algorithm out")
    parser.add_argument("--authors-timed", type=int, default=0,
                        help="time only this many published iterations and replay the rest (see above); 0: run them all")
    parser.add_argument("--reference-iters", type=int, default=1000, help="0 leaves the relative error out")
    parser.add_argument("--configs", default=",".join(CONFIGS), help=f"from: {', '.join(CONFIGS)}, {RANKED}N")
    parser.add_argument("--out", default=f"{WORK}/bench-recon")
    args = parser.parse_args(argv)
    try:
        configs = {name: config(name) for name in args.configs.split(",")}
    except ValueError as error:
        parser.error(str(error))
    if args.authors_timed and not 2 <= args.authors_timed < args.authors_iters:
        parser.error(f"--authors-timed {args.authors_timed}: 0, or from 2 to fewer than --authors-iters")
    shape = tuple(int(v) for v in args.size.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results, replays = {}, {}
    for scene in args.scenes.split(","):
        sim = simulate(scene=scene, shape=shape, n_bands=args.bands, seed=0)
        reference = converged_reference(sim, args.reference_iters)
        results[scene] = {name: run_clsdcam(sim, *chosen, args.iters, reference) for name, chosen in configs.items()}
        if args.authors_iters:
            results[scene][AUTHORS], solver, last = run_authors(sim, args.authors_iters, reference, args.authors_timed)
            if args.authors_timed:
                replays[scene] = (sim, solver, last, reference)
        print(f"{scene}: timed", file=sys.stderr)
        save(results, out)
    if replays:
        with ThreadPoolExecutor(len(replays)) as pool:      # untimed: side by side, after every timing
            done = {scene: pool.submit(replay_authors, sim, results[scene][AUTHORS], solver, last, args.authors_iters,
                                       reference) for scene, (sim, solver, last, reference) in replays.items()}
            for scene, future in done.items():
                results[scene][AUTHORS] = future.result()
        save(results, out)
    text = speed_table(results) + "\n\n" + skip_table(results)
    print(text)
    (out / "results.md").write_text(text + "\n")
    plot(results, out / "error_vs_time.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
