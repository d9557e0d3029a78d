"""``clsdcam reconstruct MEAS… --calibration CAL -o OUT.h5``: one measurement (several frames averaged) to a cube."""
from __future__ import annotations

from ..errors import InputError, shape_text
from .options import (add_measurement_options, add_preprocessing_options, add_solver_options, examples, number,
                      preprocessing_from)
from .solve import print_accuracy, solve, write


def add_parser(subparsers):
    p = subparsers.add_parser("reconstruct", help="reconstruct a cube from one measurement", description=(
        "Reconstruct a spectral cube (bands × height × width) from one measurement (several frames of one scene "
        "are averaged) and a calibration: the measurement's own steps (dark, binning), the calibration's "
        "preprocessing, saturated pixels left out, then the solver. Writes the cube as HDF5 with its history and "
        "provenance, and prints what was done, the fit and, with --truth, the accuracy."), epilog=examples(
        "clsdcam reconstruct sim/measurement.npy --calibration sim/calibration.h5 -o cube.h5 --png cube",
        "clsdcam reconstruct raw.png --calibration calibration.mat --reference-preprocess -o cube.h5",
        "clsdcam reconstruct hand.tif --calibration psf.h5 -o hand.h5 --iters 500 --backend opencl",
        "clsdcam reconstruct shot_*.tif --average 4 --dark dark_*.tif --bin 2 --calibration cal.h5 -o cube.h5"))
    p.add_argument("measurement", nargs="+", metavar="MEASUREMENT",
                   help="PNG/TIFF (8/16-bit), .npy or .h5 (dataset 'measurement'); several frames are averaged")
    p.add_argument("--calibration", required=True, help="calibration.mat (psf, mask, wavs) or our .h5")
    p.add_argument("-o", "--output", required=True, help="output cube, HDF5")
    p.add_argument("--truth", default=None, help="true cube (.h5 with 'cube') to print PSNR and spectral angle")
    p.add_argument("--png", default=None, metavar="PREFIX", help="write pictures PREFIX_*.png")
    p.add_argument("--full-field", action="store_true", help="also write the whole padded field")
    add_solver_options(p)
    add_preprocessing_options(p)
    add_measurement_options(p)
    p.add_argument("--saturation", type=saturation, default="auto", metavar="auto|none|LEVEL",
                   help="pixels excluded from the data term as saturated, said in one line with their fraction "
                        "(a frame more than half saturated is refused): auto (default) those at the integer type's "
                        "maximum or on a flat plateau at the frame's maximum; none: keep every pixel; LEVEL: those "
                        "whose value is ≥ LEVEL")


def run(args) -> int:
    from ..calibrate.measurement import prepare
    from ..io import check_output, read_cube
    from ..provenance import provenance

    check_output(args.output)
    if args.png:
        check_output(f"{args.png}_falsecolour.png", "--png")
    files, preprocessing = measurement_files(args), preprocessing_from(args)
    calibration, measurement = prepare(files, args.calibration, preprocessing, report=print)
    truth = read_cube(args.truth)["cube"] if args.truth else None
    expected = (calibration.n_bands,) + measurement.shape
    if truth is not None and truth.shape != expected:
        raise InputError(f"--truth {args.truth}: cube {shape_text(truth.shape)} does not match {shape_text(expected)}")
    result = solve(args, calibration, measurement)
    dark = {"dark": preprocessing.dark} if isinstance(preprocessing.dark, tuple) else {}
    result.attrs.update(provenance({"measurement": files, "calibration": args.calibration, **dark}, preprocessing))
    code = write(args, result, truth)
    if truth is not None and code == 0:
        print_accuracy(result.cube, truth)
    return code


def saturation(text: str):
    """--saturation's value: "auto", None for "none", or a level."""
    return None if text == "none" else text if text == "auto" else number(text)


def measurement_files(args) -> list[str]:
    """The MEASUREMENT files to average: all of them, or the first N with ``--average N``."""
    if args.average is None:
        return args.measurement
    if args.average > len(args.measurement):
        raise InputError(f"--average {args.average}: only {len(args.measurement)} measurement file"
                         f"{'s' * (len(args.measurement) > 1)} given")
    return args.measurement[:args.average]
