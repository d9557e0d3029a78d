"""The ``clsdcam`` command line: reconstruct, simulate, demo, batch, devices, analyze.

Exit codes: 0 success, 2 bad input (one line on stderr, no traceback, no output file),
130 interrupted (no partial output file).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .errors import InputError, shape_text


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error in one line (exit 2)."""

    def error(self, message):
        raise InputError(message)


def _integer_at_least(minimum: int, name: str):
    """An argparse type: an integer ≥ ``minimum`` (argparse names it ``name`` in its one-line error)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise InputError(f"{text!r} is not an integer") from None
        if value < minimum:
            raise InputError(f"{value} must be ≥ {minimum}")
        return value

    parse.__name__ = name
    return parse


_positive_int = _integer_at_least(1, "positive integer")
_non_negative_int = _integer_at_least(0, "non-negative integer")


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise InputError(f"{text!r} is not a number") from None


def _weights(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    if len(parts) != 3:
        raise InputError(f"--tv-weights {text!r}: expected WX,WY,WL")
    return tuple(_number(p) for p in parts)


def _iterations(text: str) -> tuple[int, ...]:
    return tuple(_positive_int(p) for p in text.split(","))


def _size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) != 2:
        raise InputError(f"--size {text!r}: expected HxW, e.g. 320x448")
    return tuple(_positive_int(p) for p in parts)


def add_solver_options(p: argparse.ArgumentParser):
    from .solver import DEFAULT_ITERS, DEFAULT_TOL, DEFAULT_TV

    p.add_argument("--backend", default="numpy", help="numpy (reference) or opencl")
    p.add_argument("--device", default=None,
                   help="OpenCL device: substring of platform or device name (default: PYOPENCL_CTX, else a GPU, else a CPU)")
    p.add_argument("--fft", default="auto", choices=("auto", "host", "reikna", "vkfft"),
                   help="OpenCL FFT engine (default auto: host pocketfft on CPU devices, else vkfft if installed, else reikna)")
    p.add_argument("--iters", type=_positive_int, default=DEFAULT_ITERS, help=f"FISTA iterations (default {DEFAULT_ITERS})")
    p.add_argument("--tv", type=_number, default=DEFAULT_TV,
                   help=f"3-D TV weight, relative to ‖Aᵀb‖∞ (default {DEFAULT_TV})")
    p.add_argument("--tv-weights", type=_weights, default=(1.0, 1.0, 1.0), metavar="WX,WY,WL",
                   help="TV weights along x, y and λ (default 1,1,1)")
    p.add_argument("--lowrank", type=_number, default=0.0, help="low-rank weight, relative to σ₁(Aᵀb) (default 0: off)")
    p.add_argument("--tol", type=_number, default=DEFAULT_TOL, help="stop when ‖Δx‖/‖x‖ < TOL (default: off)")
    p.add_argument("--plateau", type=_number, default=0.0,
                   help="stop when the objective fell by less than this (relative) over its last check (default: off)")
    p.add_argument("--rank", type=_non_negative_int, default=0, metavar="R",
                   help="solve for R spectral basis vectors instead of the bands (default 0: chosen automatically)")
    p.add_argument("--no-skip", action="store_true",
                   help="the full solver: the paper's 2H×2W field, every band, no spectral subspace")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--png", default=None, metavar="PREFIX", help="write pictures PREFIX_*.png")
    p.add_argument("--full-field", action="store_true", help="also write the whole padded field")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--save-on-interrupt", action="store_true",
                   help="on Ctrl-C, write the best cube so far (default: write nothing)")


def add_preprocessing_options(p: argparse.ArgumentParser):
    p.add_argument("--crop", default=None, metavar="Y0:Y1,X0:X1", help="crop calibration and measurement")
    p.add_argument("--reference-preprocess", action="store_true",
                   help="the authors' preprocessing: crop 100:420,80:540, zero the defect block, drop band 65")
    p.add_argument("--zero-defect", action="store_true", help="zero the 4×4 defect block at the mask's brightest pixel")
    p.add_argument("--drop-last-band", action="store_true", help="drop the calibration's last band")
    p.add_argument("--no-normalize-psf", action="store_true", help="keep the PSF as given (default: unit L2 norm)")
    p.add_argument("--no-normalize-filters", action="store_true", help="keep the filters as given (default: max 1)")
    p.add_argument("--saturation", type=_number, default=None, metavar="LEVEL",
                   help="exclude pixels whose raw value is ≥ LEVEL (saturated) from the data term")
    p.add_argument("--dead-pixels", default=None, metavar="FILE",
                   help="image/.npy mask (non-zero = dead, same size as the measurement) of pixels to exclude")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="clsdcam", description="Spectral DiffuserCam hyperspectral reconstruction")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    rec = sub.add_parser("reconstruct", help="reconstruct a cube from one measurement")
    rec.add_argument("measurement", help="PNG/TIFF (8/16-bit), .npy or .h5 (dataset 'measurement')")
    rec.add_argument("--calibration", required=True, help="calibration.mat (psf, mask, wavs) or our .h5")
    rec.add_argument("-o", "--output", required=True, help="output cube, HDF5")
    rec.add_argument("--truth", default=None, help="true cube (.h5 with 'cube') to print PSNR and spectral angle")
    add_solver_options(rec)
    add_preprocessing_options(rec)

    sim = sub.add_parser("simulate", help="simulate a camera, a scene and its measurement")
    sim.add_argument("outdir")
    sim.add_argument("--frames", type=_positive_int, default=None,
                     help="write a video of N frames of the scene drifting (frames.npy, truth.h5)")
    _add_simulation_options(sim)

    demo = sub.add_parser("demo", help="simulate the default scene, reconstruct it, report accuracy and time")
    demo.add_argument("outdir", nargs="?", default="clsdcam-demo")
    demo.add_argument("--report-at", type=_iterations, default=(), metavar="N,N,...",
                      help="also print the accuracy after these iterations, e.g. 100,500")
    _add_simulation_options(demo)
    add_solver_options(demo)

    sub.add_parser("devices", help="list OpenCL platforms and devices (memory, compute units, fp64)")
    from . import cli_analyze, cli_batch

    cli_analyze.add_parser(sub)
    cli_batch.add_parser(sub)
    return parser


def _add_simulation_options(p: argparse.ArgumentParser):
    p.add_argument("--scene", default="target", help="target, leds, piecewise, points or realcube")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--noise", type=_number, default=None, help="Gaussian noise variance relative to max(b)²")
    p.add_argument("--size", type=_size, default=(320, 448), metavar="HxW", help="sensor size (default 320x448)")
    p.add_argument("--bands", type=_positive_int, default=64, help="number of bands (default 64)")


# ---- commands ---------------------------------------------------------------------------
def cmd_reconstruct(args) -> int:
    from .calibration import Calibration, preprocess
    from .io import load_measurement

    calibration = Calibration.load(args.calibration)
    measurement = load_measurement(args.measurement)
    calibration, measurement = preprocess(calibration, measurement, preprocessing(args))
    truth = _read_truth(args.truth) if args.truth else None
    expected = (calibration.n_bands,) + measurement.shape
    if truth is not None and truth.shape != expected:
        raise InputError(f"--truth {args.truth}: cube {shape_text(truth.shape)} does not match {shape_text(expected)}")
    result = _solve(args, calibration, measurement)
    code = _write(args, result, truth)
    if truth is not None and code == 0:
        _print_accuracy(result.cube, truth)
    return code


def cmd_simulate(args) -> int:
    from .sim import simulate, write_simulation

    if args.frames:
        return _simulate_video(args)
    sim = simulate(**_simulation_kwargs(args))
    paths = write_simulation(args.outdir, sim)
    print(f"simulated scene {sim.scene!r} ({shape_text(sim.truth.shape)}): " +
          ", ".join(str(p) for p in paths.values()))
    return 0


def _simulate_video(args) -> int:
    from .video import simulate_video, write_video

    calibration, frames, truth = simulate_video(args.scene, args.frames, args.size, args.bands, args.seed)
    paths = write_video(args.outdir, calibration, frames, truth)
    print(f"simulated {args.frames} frames of {args.scene!r}: " + ", ".join(str(p) for p in paths.values()))
    return 0


def cmd_demo(args) -> int:
    from .sim import simulate, write_simulation

    start = time.perf_counter()
    sim = simulate(**_simulation_kwargs(args))
    write_simulation(args.outdir, sim)
    print(f"simulated scene {sim.scene!r}, {shape_text(sim.truth.shape)}, in {time.perf_counter() - start:.1f} s")
    args.output = str(Path(args.outdir) / "cube.h5")
    args.png = args.png or str(Path(args.outdir) / "cube")
    result = _solve(args, sim.calibration, sim.measurement, snapshots=args.report_at)
    code = _write(args, result, sim.truth)
    if code:
        return code
    for iteration, cube in sorted(result.snapshots.items()):
        _print_accuracy(cube, sim.truth, f"after {iteration} iterations ({result.history[iteration - 1]['seconds']:.1f} s): ")
    _print_accuracy(result.cube, sim.truth, f"final ({result.iterations} iterations): ")
    return 0


def cmd_devices(args) -> int:
    from .backends.cl_devices import format_devices

    print(format_devices())
    return 0


# ---- helpers ----------------------------------------------------------------------------
def _simulation_kwargs(args) -> dict:
    kwargs = {"scene": args.scene, "shape": args.size, "n_bands": args.bands, "seed": args.seed}
    if args.noise is not None:
        if args.noise < 0:
            raise InputError(f"--noise {args.noise}: must be ≥ 0")
        kwargs["noise_var"] = args.noise
    return kwargs


def preprocessing(args):
    from .calibration import Preprocessing, parse_crop

    base = Preprocessing.reference() if args.reference_preprocess else Preprocessing()
    crop = parse_crop(args.crop) if args.crop else base.crop
    return Preprocessing(
        crop=crop,
        normalize_psf=not args.no_normalize_psf,
        normalize_filters=not args.no_normalize_filters,
        zero_defect=args.zero_defect or base.zero_defect,
        drop_last_band=args.drop_last_band or base.drop_last_band,
        saturation=args.saturation,
        dead_pixels=_dead_pixels(args.dead_pixels, crop),
    )


def _dead_pixels(path, crop):
    """The --dead-pixels mask, cropped like the measurement."""
    if path is None:
        return None
    from .calibration import PixelMask
    from .io import load_measurement

    mask = load_measurement(path)
    return PixelMask.of(mask if crop is None else mask[crop[0]:crop[1], crop[2]:crop[3]])


def settings(args):
    """Solver settings from the command-line options."""
    from .solver import Settings

    return Settings(iters=args.iters, tv=args.tv, tv_weights=args.tv_weights, lowrank=args.lowrank,
                    tol=args.tol, plateau=args.plateau, rank=args.rank, skip=not args.no_skip, dtype=args.dtype,
                    full_field=args.full_field)


def _solve(args, calibration, measurement, snapshots=()):
    """Build the solver and run it with a progress bar; Ctrl-C without --save-on-interrupt propagates."""
    from .solver import Solver

    solver = Solver(calibration, backend=args.backend, device=args.device, settings=settings(args), fft=args.fft)
    if not args.quiet:
        print(f"backend {solver.backend.name} on {solver.backend.device_name} (FFT: {solver.backend.fft_engine}); field "
              f"{shape_text(solver.model.cube_shape)}; L = {solver.lipschitz:.4g}", file=sys.stderr)
    with _progress_bar(args.iters, args.quiet) as progress:
        result = solver.solve(measurement, progress=progress, snapshots=snapshots)
    if result.stop_reason == "interrupted" and not args.save_on_interrupt:
        raise KeyboardInterrupt
    return result


def _write(args, result, truth=None) -> int:
    """Save the cube (and pictures unless interrupted); 130 after an interrupted run, else 0."""
    result.save(args.output)
    interrupted = result.stop_reason == "interrupted"
    if args.png and not interrupted:
        from .render import save_pictures

        paths = save_pictures(args.png, result.cube, result.wavelengths, history=result.history, truth=truth)
        print("pictures: " + ", ".join(str(p) for p in paths))
    _report(args, result, Path(args.output))
    if interrupted:
        print(f"clsdcam: interrupted after {result.iterations} iterations; wrote the best cube so far to "
              f"{args.output}", file=sys.stderr)
        return 130
    return 0


class _progress_bar:
    """A tqdm bar over iterations showing the objective, the data term and the relative change."""

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


def _report(args, result, output: Path):
    seconds = result.history[-1]["seconds"] if result.history else 0.0
    per_iteration = seconds / max(result.iterations, 1)
    print(f"wrote {output}: cube {shape_text(result.cube.shape)}, {result.iterations} iterations "
          f"(stopped: {result.stop_reason}) in {seconds:.1f} s ({per_iteration:.3f} s/iteration) "
          f"on {result.attrs['backend']} [{result.attrs['device']}]")
    print("skipped: " + result.attrs["skips"].replace("\n", "\n         "))


def _print_accuracy(cube, truth, label=""):
    from .metrics import psnr, spectral_angle

    if truth.shape != cube.shape:
        raise InputError(f"--truth cube {shape_text(truth.shape)} does not match the result {shape_text(cube.shape)}")
    print(f"{label}PSNR {psnr(cube, truth):.2f} dB, mean spectral angle {spectral_angle(cube, truth):.2f}°")


def _read_truth(path):
    from .io import read_cube

    return read_cube(path)["cube"]



def cmd_batch(args) -> int:
    from .cli_batch import run

    return run(args)


def cmd_analyze(args) -> int:
    from .cli_analyze import run

    return run(args)


COMMANDS = {"reconstruct": cmd_reconstruct, "simulate": cmd_simulate, "demo": cmd_demo, "devices": cmd_devices,
            "analyze": cmd_analyze, "batch": cmd_batch}


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return COMMANDS[args.command](args)
    except InputError as exc:
        print(f"clsdcam: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("clsdcam: interrupted; no output written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
