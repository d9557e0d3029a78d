"""One reconstruction from the command line: the solver with a progress bar, the cube and pictures written,
the report and the accuracy printed (shared by ``reconstruct`` and ``demo``)."""
from __future__ import annotations

import sys
from pathlib import Path

from ..errors import InputError, shape_text
from .options import settings_from


def solve(args, calibration, measurement, snapshots=()):
    """Build the solver and run it with a progress bar; Ctrl-C without --save-on-interrupt propagates."""
    from ..solver import Solver

    solver = Solver(calibration, backend=args.backend, device=args.device, settings=settings_from(args), fft=args.fft,
                    path=args.path)
    be = solver.backend
    if not args.quiet:
        print(f"backend {be.name} on {be.device_name} ({be.path} path, FFT: {be.fft_engine}); field "
              f"{shape_text(solver.model.cube_shape)}; L = {solver.lipschitz:.4g}", file=sys.stderr)
    with ProgressBar(args.iters, args.quiet) as progress:
        result = solver.solve(measurement, progress=progress, snapshots=snapshots)
    if result.stop_reason == "interrupted" and not args.save_on_interrupt:
        raise KeyboardInterrupt
    return result


def write(args, result, truth=None) -> int:
    """Save the cube (and pictures unless interrupted); 130 after an interrupted run, else 0."""
    result.save(args.output)
    interrupted = result.stop_reason == "interrupted"
    if args.png and not interrupted:
        from ..render import save_pictures

        paths = save_pictures(args.png, result.cube, result.wavelengths, history=result.history, truth=truth)
        print("pictures: " + ", ".join(str(p) for p in paths))
    report(result, Path(args.output))
    if interrupted:
        print(f"clsdcam: interrupted after {result.iterations} iterations; wrote the best cube so far to "
              f"{args.output}", file=sys.stderr)
        return 130
    return 0


class ProgressBar:
    """A tqdm bar over iterations showing the objective, the data term, the relative change and the rank."""

    def __init__(self, total: int, quiet: bool):
        self.bar = None if quiet else _tqdm(total)
        self.last_objective = "-"

    def __enter__(self):
        return None if self.bar is None else self.update

    def update(self, record: dict):
        fields = {"data": f"{record['data']:.4g}", "change": f"{record['change']:.2e}", "rank": record["rank"]}
        if record["objective"] == record["objective"]:  # not NaN
            self.last_objective = f"{record['objective']:.5g}"
        fields["objective"] = self.last_objective
        self.bar.set_postfix(fields, refresh=False)
        self.bar.update(1)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()


def _tqdm(total: int):
    from tqdm import tqdm

    return tqdm(total=total, unit="it", file=sys.stderr, dynamic_ncols=True)


def report(result, output: Path):
    seconds = result.history[-1]["seconds"] if result.history else 0.0
    per_iteration = seconds / max(result.iterations, 1)
    print(f"wrote {output}: cube {shape_text(result.cube.shape)}, {result.iterations} iterations "
          f"(stopped: {result.stop_reason}) in {seconds:.1f} s ({per_iteration:.3f} s/iteration) "
          f"on {result.attrs['backend']} [{result.attrs['device']}]")
    print("skipped: " + result.attrs["skips"].replace("\n", "\n         "))


def print_accuracy(cube, truth, label=""):
    from ..metrics import psnr, spectral_angle

    if truth.shape != cube.shape:
        raise InputError(f"--truth cube {shape_text(truth.shape)} does not match the result {shape_text(cube.shape)}")
    print(f"{label}PSNR {psnr(cube, truth):.2f} dB, mean spectral angle {spectral_angle(cube, truth):.2f}°")
