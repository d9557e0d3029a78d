"""One reconstruction from the command line: the backend chosen, the solver with a progress bar, the cube and
pictures written, the report and the accuracy printed (shared by ``reconstruct`` and ``demo``; ``batch`` shares the
backend's choice)."""
from __future__ import annotations

import sys
import time
from pathlib import Path

from ..errors import InputError, shape_text
from .options import settings_from


def solve(args, calibration, measurement, snapshots=(), settings=None):
    """Build the solver (with ``settings``, by default the options') and run it with a progress bar; Ctrl-C without
    --save-on-interrupt propagates."""
    from ..solve.solver import Solver

    settings = settings or settings_from(args)
    solver = Solver(calibration, backend=chosen_backend(args, settings.algorithm), device=args.device,
                    settings=settings, fft=args.fft, path=args.path)
    be = solver.backend
    if not args.quiet:
        print(f"backend {be.name} on {be.device_name} ({be.path} path, FFT: {be.fft_engine}); field "
              f"{shape_text(solver.model.cube_shape)}; L = {solver.lipschitz:.4g}", file=sys.stderr)
    with ProgressBar(solver.settings.budget, args.quiet) as progress:
        result = solver.solve(measurement, progress=progress, snapshots=snapshots)
    if result.stop_reason == "interrupted" and not args.save_on_interrupt:
        raise KeyboardInterrupt
    return result


def chosen_backend(args, algorithm: str = "fista") -> str:
    """The backend ``--backend`` names; for ``auto`` (the default) its choice
    (:func:`clsdcam.backends.resolve_backend`), said in one line: ``backend: opencl on DEVICE (auto: a GPU was
    found)`` or ``backend: numpy (auto: no OpenCL GPU)``; NumPy for an ``algorithm`` (the settings' name, "auto"
    resolved) whose ``backends`` leave OpenCL out."""
    from ..algorithms import ALGORITHMS
    from ..backends import resolve_backend

    runs_on = ALGORITHMS[algorithm].backends
    if args.backend == "auto" and runs_on is not None and "opencl" not in runs_on:
        name, why = "numpy", f"--algorithm {algorithm} runs on NumPy"
    else:
        name, why = resolve_backend(args.backend, args.device)
    if why:
        where = ""
        if name == "opencl":
            from ..backends import choose_device, describe

            where = f" on {describe(choose_device(args.device))}"
        print(f"backend: {name}{where} (auto: {why})")
    return name


def write(args, result, truth=None) -> int:
    """Save the cube and, with --png, its pictures (after a Ctrl-C with --save-on-interrupt too: of the best cube so
    far, the one saved); 130 after an interrupted run, else 0."""
    result.save(args.output)
    if args.png:
        from ..render import save_pictures

        paths = save_pictures(args.png, result.cube, result.wavelengths, history=result.history, truth=truth)
        print("pictures: " + ", ".join(str(p) for p in paths))
    report(result, Path(args.output))
    if result.stop_reason == "interrupted":
        pictures = f" and its pictures to {args.png}_*.png" if args.png else ""
        print(f"clsdcam: interrupted after {result.iterations} iterations; wrote the best cube so far to "
              f"{args.output}{pictures}", file=sys.stderr)
        return 130
    return 0


LOG_EVERY = 10.0    # seconds between progress lines when stderr is not a terminal (a log file, a pipe)
POOR_FIT = 0.1      # ‖Av − b‖/‖b‖ above this after a solve: the cube does not explain the measurement, …
NOT_NOISE = 6.0     # … unless the residual is noise: rms(r)/σ̂(r) of 1.0–4.0 on the six simulated scenes, 8.6–18.8 with
                    # another camera's calibration (Reconstruction._residual_figures), …
TAIL = 10           # … or the solve was cut short: the data term's fall over its last TAIL iterations …
LEVELLED = 0.1      # … is LEVELLED or more (leds, target: 62–93% after 5 to 14 iterations with the right calibration at
                    # 64×96×16 and 320×448×64; 1.1–5.7% after 60 with another camera's, 32×40×4 to 320×448×64)


class ProgressBar:
    """Progress over iterations (objective, data term, relative change, rank): a tqdm bar on a terminal; elsewhere a
    line after the first iteration (the work has started), every LOG_EVERY seconds and at the end (a redrawn bar
    would make a log one long line)."""

    def __init__(self, total: int, quiet: bool):
        self.total = total
        self.bar = None if quiet or not sys.stderr.isatty() else _tqdm(total)
        self.quiet = quiet
        self.last_objective = "-"
        self.last_line = self.start = time.monotonic()
        self.record = None
        self.lines = 0

    def __enter__(self):
        return None if self.quiet else self.update

    def update(self, record: dict):
        self.record = record
        fields = {"data": f"{record['data']:.4g}", "change": f"{record['change']:.2e}", "rank": record["rank"]}
        if "distance" in record:        # --iters auto: the estimated distance to the limit (∞ until it is known)
            fields["distance"] = f"{record['distance']:.1e}"
        if record["objective"] == record["objective"]:  # not NaN
            self.last_objective = f"{record['objective']:.5g}"
        fields["objective"] = self.last_objective
        if self.bar is not None:
            self.bar.set_postfix(fields, refresh=False)
            self.bar.update(1)
        elif self.lines == 0 or time.monotonic() - self.last_line >= LOG_EVERY:
            self._line(fields)

    def _line(self, fields: dict):
        self.last_line = time.monotonic()
        self.lines += 1
        print(f"clsdcam: iteration {self.record['iteration']}/{self.total} "
              f"({self.last_line - self.start:.0f} s) " + ", ".join(f"{k} {v}" for k, v in fields.items()),
              file=sys.stderr, flush=True)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()
        elif self.record is not None and not self.quiet:
            self._line({"objective": self.last_objective})


def _tqdm(total: int):
    from tqdm import tqdm

    return tqdm(total=total, unit="it", file=sys.stderr, dynamic_ncols=True)


def report(result, output: Path):
    seconds = result.history[-1]["seconds"] if result.history else 0.0
    per_iteration = seconds / max(result.iterations, 1)
    print(f"wrote {output}: cube {shape_text(result.cube.shape)}, {result.iterations} iterations "
          f"(stopped: {stop_text(result)}) in {seconds:.1f} s ({per_iteration:.3f} s/iteration) "
          f"on {result.attrs['backend']} [{result.attrs['device']}]")
    print("skipped: " + result.attrs["skips"].replace("\n", "\n         "))
    fit, structure = result.attrs.get("relative_residual", 0.0), result.attrs.get("residual_to_noise", 0.0)
    print(f"fit: ‖Av − b‖/‖b‖ = {100 * fit:.2g}% (the part of the measurement the cube does not explain), "
          f"{structure:.2g}× the noise level")
    if fit > POOR_FIT and structure > NOT_NOISE:
        print(poor_fit_warning(result, fit), file=sys.stderr)


def stop_text(result) -> str:
    """Why the solve stopped, and with ``--iters auto`` how close to the converged cube it estimates it is."""
    distance = result.attrs.get("distance_estimate")
    if distance is None:
        return result.stop_reason
    close = (f"about {100 * distance:.2g}% from the converged cube" if distance < float("inf")
             else "its distance to the converged cube not yet known")
    tolerance = result.attrs["stop_tolerance"]
    converge = f"auto: {tolerance:.2g}" if result.attrs["converge"] == "auto" else f"{tolerance:g}"
    return f"{result.stop_reason}, {close} by its own estimate (--converge {converge})"


def poor_fit_warning(result, fit: float) -> str:
    """The one-line warning for a cube that leaves ``fit`` = ‖Av − b‖/‖b‖ of the measurement unexplained, beyond
    noise: a solve cut short (by --iters or Ctrl-C) while the data term was still falling by LEVELLED or more over
    its last TAIL iterations is told to run longer; a fit that had levelled off puts the calibration in doubt."""
    fall = data_fall(result.history)
    unexplained = f"clsdcam: warning: the cube leaves {100 * fit:.0f}% of the measurement unexplained"
    if fall is not None and fall < LEVELLED:
        return f"{unexplained}: is the calibration the camera's, with the measurement's crop and orientation?"
    how = "was interrupted" if result.stop_reason == "interrupted" else "stopped"
    trend = "" if fall is None else \
        f" (½‖Ay − b‖² fell {100 * fall:.0f}% over its last {tail(result.history)} iterations)"
    return (f"{unexplained}, but the solve {how} after {result.iterations} iterations with the fit still improving"
            f"{trend}: run more iterations (--iters) before judging the calibration")


def tail(history: list[dict]) -> int:
    """k = min(TAIL, n − 1): the iterations over which :func:`data_fall` reads the trend of n recorded ones."""
    return min(TAIL, len(history) - 1)


def data_fall(history: list[dict]) -> float | None:
    """1 − d_n / d_(n−k) of the recorded data term d = ½‖Ay − b‖² over the last k = :func:`tail` iterations
    (negative when it rose); None before a second iteration (no trend yet)."""
    k = tail(history)
    if k < 1:
        return None
    before = history[-1 - k]["data"]
    return 1.0 - history[-1]["data"] / before if before > 0 else 0.0


def print_accuracy(cube, truth, label=""):
    from ..metrics import accuracy

    if truth.shape != cube.shape:
        raise InputError(f"--truth cube {shape_text(truth.shape)} does not match the result {shape_text(cube.shape)}")
    print(label + accuracy_text(accuracy(cube, truth)))


def accuracy_text(figures: dict) -> str:
    """:func:`clsdcam.metrics.accuracy`'s figures as printed."""
    return (f"PSNR {figures['psnr']:.2f} dB, mean spectral angle {figures['spectral_angle']:.2f}°, "
            f"peak ratio {figures['peak_ratio']:.3f}")
