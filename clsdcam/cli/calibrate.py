"""``clsdcam calibrate {psf,filters}``: lab measurements → a calibration file (:mod:`clsdcam.calibrate`).

``psf``: point-source frames → a complete one-band calibration (plain DiffuserCam) that also records the raw
steps, so ``clsdcam reconstruct`` takes raw frames of that camera as they come. ``filters``: a monochromator
sweep of the filter array → the filter function in K bands and a defect map; with ``--psf`` a complete
spectral calibration.
"""
from __future__ import annotations

import argparse

from ..camera.prototype import N_BANDS, SPECTRAL_RANGE
from .options import examples, number, positive_int

PSF_EXAMPLES = (
    "clsdcam calibrate psf psf.tif --dark-corner 10 --bin 4 -o cal.h5   # the DiffuserCam tutorial's steps",
    "clsdcam calibrate psf psf_*.tif --dark dark_*.tif --crop 100:1100,200:1400 --center --png psf -o psf.h5",
    "clsdcam calibrate psf psf.npy --dark 64 --wavelength 530 -o green.h5")
FILTER_EXAMPLES = (
    "clsdcam calibrate filters sweep/ --wavelengths 370:898:2 --power power.csv --dark 100 --psf psf.h5 -o cal.h5",
    "clsdcam calibrate filters sweep.tif --wavelengths nm.csv --exposure exposure.csv --band-edges edges.csv "
    "-o filters.h5",
    "clsdcam simulate sim/ --sweep --size 48x64 --bands 16 && clsdcam calibrate filters sim/sweep --wavelengths "
    "sim/sweep_wavelengths.csv --power sim/power.csv --dark sim/dark/*.tif --bands 16 --psf sim/psf_calibration.h5 "
    "--png sim/filters -o sim/recovered.h5")
PSF_TEXT = ("Average point-source frames, remove the dark (clipped at 0), crop, bin, report the centring against "
            "the frame centre (H//2, W//2) (--center moves the centroid there), normalise to unit L2 norm, and "
            "write a one-band calibration (filters all ones) that records these raw steps.")
FILTER_TEXT = ("Divide each sweep frame (dark removed, cropped, binned) by the source power and the exposure, "
               "integrate the transmission over each band (trapezoid rule), map dead, hot and saturated pixels, "
               "scale to max 1. --psf adds a 'calibrate psf' PSF for a complete calibration.")


def span(text: str) -> tuple[float, float]:
    """'A:B' (nm) → (A, B)."""
    parts = text.split(":")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r}: expected A:B, e.g. 386:898")
    return tuple(number(p) for p in parts)


def add_parser(subparsers):
    p = subparsers.add_parser("calibrate", help="lab measurements → a calibration file (PSF frames, a filter sweep)",
                              description="From lab measurements to a calibration file; each sub-command's --help "
                                          "shows its options, their defaults and examples.",
                              epilog=examples(*PSF_EXAMPLES[:2], *FILTER_EXAMPLES[:1]))
    which = p.add_subparsers(dest="what", required=True, metavar="{psf,filters}")
    psf = which.add_parser("psf", help="point-source frames → PSF (a one-band calibration)", description=PSF_TEXT,
                           epilog=examples(*PSF_EXAMPLES))
    psf.add_argument("frames", nargs="+", metavar="FRAME", help="PSF frames (PNG/TIFF/.npy), averaged")
    psf.add_argument("--center", action="store_true", help="shift the PSF (whole pixels, zero fill) so that its "
                     "centroid lies on the frame centre (H//2, W//2)")
    psf.add_argument("--wavelength", type=number, default=550.0, metavar="NM", help="the band's wavelength, nm")
    _add_common(psf)
    filters = which.add_parser("filters", help="a monochromator sweep → filter function (with --psf a calibration)",
                               description=FILTER_TEXT, epilog=examples(*FILTER_EXAMPLES))
    filters.add_argument("sweep", help="a folder of frames (sorted by name) or one stack (N, H, W): .npy, .h5 "
                         "(dataset 'frames') or multi-page TIFF")
    filters.add_argument("--wavelengths", required=True, metavar="START:STOP:STEP|CSV",
                         help="each frame's wavelength (nm): a grid, STOP included, or a CSV (first column)")
    filters.add_argument("--power", default=None, metavar="CSV", help="source power: wavelength (nm), power; "
                         "interpolated linearly, normalised to its max (default: constant)")
    filters.add_argument("--exposure", default=None, metavar="SECONDS|CSV",
                         help="a constant or a CSV (wavelength, exposure); frames are divided by it (default: 1)")
    filters.add_argument("--bands", type=positive_int, default=N_BANDS, metavar="K", help="number of equal bands")
    filters.add_argument("--range", type=span, default=SPECTRAL_RANGE, metavar="A:B",
                         help=f"the bands' range, nm (default {SPECTRAL_RANGE[0]:g}:{SPECTRAL_RANGE[1]:g})")
    filters.add_argument("--band-edges", default=None, metavar="CSV",
                         help="the K + 1 band edges, nm (first column), instead of --bands and --range")
    filters.add_argument("--saturation", type=number, default=None, metavar="CODE",
                         help="raw value of a saturated pixel (default: the largest value of the frames' integer type)")
    filters.add_argument("--psf", default=None, metavar="PSF.h5",
                         help="a 'calibrate psf' file of the same binned size: write a complete calibration")
    _add_common(filters)


def _add_common(p):
    """-o, the dark, crop, bin and pictures: the same for both sub-commands."""
    p.add_argument("-o", "--output", required=True, metavar="CAL.h5", help="the file to write (HDF5)")
    dark = p.add_mutually_exclusive_group()
    dark.add_argument("--dark", nargs="+", default=None, metavar="FILE|LEVEL",
                      help="dark frames (averaged) or one dark level (default: none)")
    dark.add_argument("--dark-corner", type=positive_int, default=None, metavar="N",
                      help="dark level = mean of the N×N patch N//2 px in from the top-left corner (N = 10: "
                           "[5:15, 5:15], as the DiffuserCam tutorial); PSF: of the averaged frame, filters: of "
                           "the first sweep frame (default: off)")
    p.add_argument("--crop", default=None, metavar="Y0:Y1,X0:X1", help="crop the raw frames (default: none)")
    p.add_argument("--bin", type=positive_int, default=1, metavar="N", help="N×N block means, ragged edge dropped")
    p.add_argument("--png", default=None, metavar="PREFIX", help="write pictures PREFIX_*.png")


def run(args) -> int:
    return _run_psf(args) if args.what == "psf" else _run_filters(args)


def _checked(args, pictures):
    """Output paths checked before any work; the --crop window."""
    from ..calibrate.pictures import picture_paths
    from ..camera.calibration import parse_crop
    from ..io import check_output

    check_output(args.output)
    for path in picture_paths(args.png, pictures) if args.png else ():
        check_output(path, "--png")
    return parse_crop(args.crop) if args.crop else None


def _run_psf(args) -> int:
    from ..calibrate.pictures import save_psf_pictures
    from ..calibrate.psf import calibrate_psf, one_band, report_lines

    crop = _checked(args, ("psf", "autocorrelation"))
    result = calibrate_psf(args.frames, args.dark, args.dark_corner, crop, args.bin, args.center)
    print("\n".join(report_lines(result)))
    calibration = one_band(result, args.wavelength, "clsdcam calibrate psf " + " ".join(args.frames))
    calibration.save(args.output)
    print(f"wrote {args.output}: one-band calibration (plain DiffuserCam, filters all ones) at {args.wavelength:g} nm; "
          f"raw steps recorded ({result.steps.describe()})")
    _pictures(save_psf_pictures(args.png, result.psf) if args.png else [])
    return 0


def _run_filters(args) -> int:
    from ..calibrate.bands import edges_from_csv, equal_edges
    from ..calibrate.filters import calibrate_filters, save_filters_only, with_psf
    from ..calibrate.pictures import save_filter_pictures
    from ..camera.calibration import Calibration

    crop = _checked(args, ("peak_wavelength", "transmission"))
    psf = Calibration.load(args.psf) if args.psf else None
    edges = edges_from_csv(args.band_edges) if args.band_edges else equal_edges(args.bands, *args.range)
    result = calibrate_filters(args.sweep, args.wavelengths, edges, args.power, args.exposure, args.dark,
                               args.dark_corner, crop, args.bin, args.saturation)
    print("\n".join(result.lines))
    source = f"clsdcam calibrate filters {args.sweep}" + (f" with the PSF of {args.psf}" if psf else "")
    if psf is not None:
        calibration = with_psf(result, psf, source)
        calibration.save(args.output)
        print(f"wrote {args.output}: calibration of {calibration.n_bands} bands, {calibration.shape[0]}×"
              f"{calibration.shape[1]}, PSF from {args.psf}")
    else:
        save_filters_only(args.output, result, source)
        print(f"wrote {args.output}: the filter part only (no PSF; give --psf PSF.h5 from 'calibrate psf' for a "
              "complete calibration)")
    _pictures(save_filter_pictures(args.png, result.sweep_wavelengths, result.transmission, result.defects.mask)
              if args.png else [])
    return 0


def _pictures(paths):
    if paths:
        print("pictures: " + ", ".join(str(p) for p in paths))
