#!/usr/bin/env python3
"""Accuracy panel: the default solver against the full solver (``--no-skip``), PSNR and mean spectral angle
at fixed iterations, on every simulated scene, plus a sweep of fixed TV weights and the real hand (K = 1).

    python tools/bench_accuracy.py --size 320x448 --bands 64 --marks 50,100,300,500 --out accuracy

Scenes: the README's four (target, leds, piecewise, realcube), the paper's point sources (``sources``: 16
single-pixel 10 nm lines, with each source's peak-wavelength error) and narrow lines at the range's ends, on
bin boundaries and one faint (``lines``). A scene passes when, at every mark, the default's PSNR is at least
the full solver's − 0.2 dB and its spectral angle at most the full solver's + 0.5°. ``--sweep`` adds the
default solver at fixed ``--tv`` weights (the best of them against the default's weight choice), ``--ranks`` at
fixed ``--rank`` sizes (what each basis size costs in seconds and gives in accuracy, beside the default's band
space). ``--hand``
adds the DiffuserCam tutorial's hand (``../shared/data``; dark corner subtracted, binned 4×): correlation of
each run with a long ``--no-skip`` run at ``--hand-tv``. Writes ``accuracy.json`` and ``accuracy.md``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from clsdcam.analysis import peak_wavelength
from clsdcam.backends import get_backend
from clsdcam.cli.options import WORK, size
from clsdcam.metrics import psnr, spectral_angle
from clsdcam.sim import noiseless_measurement, shared_data_dir, simulate
from clsdcam.sim.scenes import source_lines, source_positions
from clsdcam.solve.settings import AUTO
from clsdcam.solve.solver import Settings, Solver

SCENES = ("target", "leds", "piecewise", "realcube", "sources", "lines")
CONFIGS = {"default": {}, "--no-skip": {"skip": False}}
PSNR_MARGIN_DB, ANGLE_MARGIN_DEG, SWEEP_MARGIN_DB = 0.2, 0.5, 0.5
HAND = ("psf/diffusercam_tutorial_psf_sample.tif", "psf/diffusercam_tutorial_rawdata_hand_sample.tif")
HAND_BIN, DARK_CORNER = 4, (slice(5, 15), slice(5, 15))


class Where:
    """The backend every :func:`solve` runs on: ``numpy``, or an OpenCL backend on the device clsdcam picks
    (PYOPENCL_CTX names another), made once for the run (its context, program and FFT plans); the tools'
    ``--backend`` sets it (:func:`add_backend_option`, :meth:`use`)."""

    backend = "numpy"

    @classmethod
    def use(cls, name: str) -> None:
        cls.backend = name if name == "numpy" else get_backend(name)


def add_backend_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--backend", default="numpy", choices=("numpy", "opencl"),
                        help="where every solve runs (opencl: the device clsdcam picks; PYOPENCL_CTX names another)")


def timed_run(calibration, measurement, fields: dict, marks=(), x0=None) -> tuple:
    """(result, seconds) of one solve with ``Settings(**fields)`` on :attr:`Where.backend`, snapshots at ``marks``,
    from ``x0`` if given; the seconds the solve's alone (the solver's set-up left out)."""
    solver = Solver(calibration, backend=Where.backend, settings=Settings(**fields))
    start = time.perf_counter()
    result = solver.solve(measurement, x0=x0, snapshots=marks)
    return result, time.perf_counter() - start


def solve(calibration, measurement, fields: dict, marks) -> tuple[dict, dict]:
    """{iteration: cube} at ``marks`` and the result's attributes (plus seconds per iteration), on
    :attr:`Where.backend`; ``marks`` "auto": one solve to the default stop (``--iters auto``), {its iterations: its
    final cube}, and why it stopped."""
    to_stop = marks == AUTO
    result, seconds = timed_run(calibration, measurement, fields if to_stop else dict(fields, iters=max(marks)),
                                () if to_stop else marks)
    kept = ("tv", "final_rank", "fft_work_saved", "noise_estimate", "stop_reason", "algorithm")
    attrs = {key: result.attrs[key] for key in kept if key in result.attrs}
    attrs["tv_chosen"] = result.attrs.get("tv_chosen", result.attrs.get("tv"))
    attrs["seconds"] = seconds
    return ({result.iterations: result.cube} if to_stop else result.snapshots), attrs


def scene_points(scene: str, sim, snapshots: dict) -> list[dict]:
    """PSNR and spectral angle at each mark; for ``sources`` also the median and worst peak error (nm)."""
    points = []
    for k, cube in sorted(snapshots.items()):
        point = {"iteration": k, "psnr": psnr(cube, sim.truth), "angle": spectral_angle(cube, sim.truth)}
        if scene == "sources":
            errors = np.abs(source_peaks(cube, sim.calibration.wavelengths) -
                            source_lines(sim.calibration.wavelengths))
            point.update(median_peak_nm=float(np.median(errors)), worst_peak_nm=float(errors.max()))
        points.append(point)
    return points


def source_peaks(cube, wavelengths) -> np.ndarray:
    """Each source's peak wavelength on the spectrum summed over its 3 × 3 neighbourhood (as clsdcam analyze)."""
    return np.array([peak_wavelength(cube[:, y - 1:y + 2, x - 1:x + 2].sum(axis=(1, 2)), wavelengths)
                     for y, x in source_positions(cube.shape[1:])])


def run_configs(sweep, ranks, algorithms=()) -> dict:
    """Run name -> Settings fields: the default, the full solver, each other algorithm, each fixed weight, each fixed
    rank."""
    return {**CONFIGS, **algorithm_configs(algorithms), **{f"--tv {tv:g}": {"tv": tv} for tv in sweep},
            **{f"--rank {r}": {"rank": r} for r in ranks}}


def algorithm_configs(algorithms) -> dict:
    return {f"--algorithm {name}": {"algorithm": name} for name in algorithms}


def true_noise(sim) -> float:
    """The simulated noise's standard deviation relative to max b (what ``--tv auto`` estimates)."""
    calibration = sim.calibration
    clean = noiseless_measurement(calibration.psf, calibration.filters, sim.truth)
    return float(np.std(sim.measurement - clean) / np.max(sim.measurement))


def run_scene(scene: str, shape, bands: int, marks, sweep, ranks, algorithms=()) -> dict:
    sim = simulate(scene=scene, shape=shape, n_bands=bands, seed=0)
    runs = {}
    for name, fields in run_configs(sweep, ranks, algorithms).items():
        snapshots, attrs = solve(sim.calibration, sim.measurement, fields, marks)
        runs[name] = {"points": scene_points(scene, sim, snapshots), **attrs}
        if name == "default":
            runs[name]["true_noise"] = true_noise(sim)
        print(f"  {scene} {name}: {attrs['seconds']:.0f} s", file=sys.stderr, flush=True)
    return runs


def binned(path: Path) -> np.ndarray:
    """A raw tutorial frame: the dark corner's mean subtracted, clipped at 0, HAND_BIN× block means."""
    import tifffile

    from clsdcam.analysis import bin_pixels

    image = tifffile.imread(path).astype(np.float64)
    return bin_pixels(np.maximum(image - image[DARK_CORNER].mean(), 0.0), HAND_BIN)


def run_hand(marks, sweep, reference_iters: int, reference_tv: float, out: Path, algorithms=()) -> dict | None:
    """The hand (K = 1): correlation of each run's image with a long ``--no-skip`` run at ``reference_tv``;
    ``hand_<run>.png``: each run's image after the last mark, and the reference's."""
    from clsdcam.camera.calibration import Calibration

    paths = [shared_data_dir() / relative for relative in HAND]
    if not all(p.exists() for p in paths):
        print("  hand: ../shared/data not present, skipped", file=sys.stderr)
        return None
    psf, raw = (binned(p) for p in paths)
    calibration = Calibration(psf / np.linalg.norm(psf), np.ones((1,) + psf.shape), [550.0], source="tutorial")
    reference = solve(calibration, raw, {"skip": False, "tv": reference_tv}, [reference_iters])[0][reference_iters]
    save_grey(out / "hand_reference.png", reference[0])
    runs = {}
    for name, fields in {"default": {}, **algorithm_configs(algorithms),
                         **{f"--tv {tv:g}": {"tv": tv} for tv in sweep}}.items():
        snapshots, attrs = solve(calibration, raw, fields, marks)
        runs[name] = {"points": [{"iteration": k, "correlation": float(np.corrcoef(c.ravel(), reference.ravel())[0, 1])}
                                 for k, c in sorted(snapshots.items())], **attrs}
        save_grey(out / f"hand_{name.replace('--tv ', 'tv').replace('--algorithm ', '')}.png",
                  snapshots[max(marks)][0])
    return {"reference": f"--no-skip --tv {reference_tv:g}, {reference_iters} iterations", "runs": runs}


def save_grey(path: Path, image: np.ndarray):
    """A grey PNG of an image, scaled to its 99.5th percentile."""
    from PIL import Image

    top = np.percentile(image, 99.5) or 1.0
    Image.fromarray((np.clip(image / top, 0, 1) * 255).astype(np.uint8)).save(path)


def verdict(runs: dict) -> str:
    """'yes' when the default is within the margins of the full solver at every mark, else where it is not."""
    misses = [f"{d['iteration']}: {d['psnr'] - f['psnr']:+.2f} dB, {d['angle'] - f['angle']:+.1f}°"
              for d, f in zip(runs["default"]["points"], runs["--no-skip"]["points"])
              if d["psnr"] < f["psnr"] - PSNR_MARGIN_DB or d["angle"] > f["angle"] + ANGLE_MARGIN_DEG]
    return "yes" if not misses else "no (" + "; ".join(misses) + ")"


def sweep_table(results: dict) -> list[str]:
    """Per scene, at the last mark: the default's (automatic) weight against the best fixed ``--tv`` of the
    sweep, and whether it is within SWEEP_MARGIN_DB of it in PSNR."""
    lines = ["", "`--tv auto` against the sweep's best fixed weight, PSNR at the last mark:", "",
             "| scene | auto τ | auto PSNR | best fixed τ | its PSNR | auto − best | within "
             f"{SWEEP_MARGIN_DB} dB |", "|---|---:|---:|---:|---:|---:|---|"]
    for scene, runs in results["scenes"].items():
        fixed = {name: run for name, run in runs.items() if name.startswith("--tv ")}
        if not fixed:
            continue
        best = max(fixed.values(), key=lambda run: run["points"][-1]["psnr"])
        auto, top = runs["default"]["points"][-1]["psnr"], best["points"][-1]["psnr"]
        lines.append(f"| {scene} | {runs['default']['tv_chosen']:.3g} | {auto:.2f} dB | {best['tv_chosen']:.3g} | "
                     f"{top:.2f} dB | {auto - top:+.2f} dB | {'yes' if auto >= top - SWEEP_MARGIN_DB else 'no'} |")
    return lines if len(lines) > 5 else []


def noise_table(results: dict) -> list[str]:
    """Per scene: the noise ``--tv auto`` read from the residual against the simulated noise, and its weight."""
    lines = ["", "The noise `--tv auto` read (σ̂, relative to max b) against the simulated noise:", "",
             "| scene | true σ | σ̂ | σ̂ / σ | auto τ |", "|---|---:|---:|---:|---:|"]
    for scene, runs in results["scenes"].items():
        run = runs["default"]
        if "noise_estimate" in run:
            lines.append(f"| {scene} | {run['true_noise']:.3g} | {run['noise_estimate']:.3g} | "
                         f"{run['noise_estimate'] / run['true_noise']:.2f} | {run['tv_chosen']:.3g} |")
    return lines if len(lines) > 5 else []


def rank_table(results: dict) -> list[str]:
    """Per scene with fixed ``--rank`` runs: each run's final rank and seconds (the marks' PSNR and spectral
    angle are in the main table), the automatic rule and the full solver first."""
    lines = ["", "Basis size against time (seconds for the whole run, on a shared machine: compare within a scene):",
             "", "| scene | run | final rank | seconds |", "|---|---|---:|---:|"]
    for scene, runs in results["scenes"].items():
        if any(name.startswith("--rank ") for name in runs):
            lines += [f"| {scene} | {name} | {run.get('final_rank', '')} | {run['seconds']:.0f} |"
                      for name, run in runs.items() if not name.startswith("--tv ")]
    return lines if len(lines) > 5 else []


def markdown(results: dict, marks) -> str:
    lines = ["| scene | run | τ | " + " | ".join(f"{m} it: PSNR / SA" for m in marks) + " | passes |",
             "|---|---|---:|" + "---|" * len(marks) + "---|"]
    for scene, runs in results["scenes"].items():
        for name, run in runs.items():
            cells = [f"{p['psnr']:.2f} dB / {p['angle']:.2f}°" + (f" (peaks {p['median_peak_nm']:.1f} / "
                                                                 f"{p['worst_peak_nm']:.1f} nm)" if "worst_peak_nm" in p
                                                                 else "") for p in run["points"]]
            mark = verdict(runs) if name == "default" else ""
            lines.append(f"| {scene} | {name} | {run['tv_chosen']:.3g} | " + " | ".join(cells) + f" | {mark} |")
    lines += sweep_table(results) + noise_table(results) + rank_table(results)
    hand = results.get("hand")
    if hand:
        lines += ["", f"Hand (K = 1), correlation with {hand['reference']}:", "",
                  "| run | τ | " + " | ".join(f"{m} it" for m in marks) + " |", "|---|---:|" + "---:|" * len(marks)]
        for name, run in hand["runs"].items():
            lines.append(f"| {name} | {run['tv_chosen']:.3g} | " +
                         " | ".join(f"{p['correlation']:.4f}" for p in run["points"]) + " |")
    return "\n".join(lines)


def save_json(out: Path, name: str, results: dict):
    """``out/<name>.json`` (written after every scene too: partial results survive a stop)."""
    (out / f"{name}.json").write_text(json.dumps(results, indent=1))


def report(out: Path, name: str, results: dict, text: str):
    """The closing table printed and written to ``out/<name>.md``, beside the final ``<name>.json``."""
    print(text)
    save_json(out, name, results)
    (out / f"{name}.md").write_text(text + "\n")


def size_text(shape) -> str:
    """(H, W) as --size writes it: "HxW" (the results' "size")."""
    return "x".join(str(n) for n in shape)


def panel_parser(description: str, out: str, named_scenes: bool = True) -> argparse.ArgumentParser:
    """The options every tool on the panel's scenes takes: --scenes (the named scenes, unless ``named_scenes`` is
    False), --size HxW (parsed to (H, W) as the CLI's), --bands, --out (default WORK/``out``)."""
    parser = argparse.ArgumentParser(description=description)
    if named_scenes:
        parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--size", type=size(), default="320x448", metavar="HxW")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--out", default=f"{WORK}/{out}")
    return parser


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "accuracy")
    parser.add_argument("--marks", default="50,100,300,500")
    parser.add_argument("--sweep", default="", help="fixed --tv weights to compare, e.g. 1e-4,3e-4,1e-3,3e-3")
    parser.add_argument("--ranks", default="", help="fixed --rank sizes to compare, e.g. 4,6,8,12")
    parser.add_argument("--algorithms", default="", help="other algorithms to run beside FISTA, e.g. admm")
    parser.add_argument("--hand", action="store_true", help="also the real hand (K = 1) from ../shared/data")
    parser.add_argument("--hand-tv", type=float, default=1e-4, help="--tv of the hand's long --no-skip reference")
    parser.add_argument("--hand-reference-iters", type=int, default=1000)
    add_backend_option(parser)
    args = parser.parse_args(argv)
    Where.use(args.backend)
    marks = [int(m) for m in args.marks.split(",")]
    sweep = [float(t) for t in args.sweep.split(",") if t]
    ranks = [int(r) for r in args.ranks.split(",") if r]
    algorithms = [a for a in args.algorithms.split(",") if a]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"size": size_text(args.size), "bands": args.bands, "marks": marks, "backend": args.backend, "scenes": {}}
    for scene in (s for s in args.scenes.split(",") if s):      # --scenes "": the hand alone
        results["scenes"][scene] = run_scene(scene, args.size, args.bands, marks, sweep, ranks, algorithms)
        save_json(out, "accuracy", results)
    if args.hand:
        results["hand"] = run_hand(marks, sweep, args.hand_reference_iters, args.hand_tv, out, algorithms)
    report(out, "accuracy", results, markdown(results, marks))
    return 0


if __name__ == "__main__":
    sys.exit(main())
