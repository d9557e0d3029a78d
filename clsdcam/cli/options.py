"""The command line's parser: argument types, the option groups commands share, and ``build_parser``
(one sub-command per module of :mod:`clsdcam.cli` but the helpers: a new command is a new module).

Building the parser imports only this package's command modules, ``clsdcam.solve.settings`` (with the prior
table that generates one ``--flag`` per prior) and ``clsdcam.camera.prototype``: every heavy import (SciPy, h5py,
the solver, the simulator) waits inside a command's ``run``. A usage error is an InputError: one line,
exit 2.
"""
from __future__ import annotations

import argparse
import importlib

from .. import __version__
from ..errors import InputError

ORDER = ("reconstruct", "batch", "calibrate", "simulate", "demo", "export", "show", "analyze", "check", "devices")
HELPERS = ("options", "solve")       # modules of this package that are not commands
SCENES = ("target", "leds", "lines", "piecewise", "points", "sources", "realcube")   # clsdcam.sim.SCENES (tested)


WORK = "clsdcam-out"    # what the demo and the tools write under by default, as the docs' examples do (.gitignore)
OUTPUTS = ("output", "outdir", "png", "json")   # the destinations of options that name where a command writes
CREATES_FOLDERS = "missing folders are created when it is written"


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Epilogs kept as written (worked examples); every option's default shown unless its help says it."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text.lower() or any(action.default is v for v in (None, False, argparse.SUPPRESS)) \
                or not action.option_strings:
            return text
        return text + " (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as an InputError (one line, exit 2), shows defaults and examples, and
    says where a command's outputs create folders."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self.parsed = argparse.Namespace()      # what the parse in progress has read, for error()

    def parse_known_args(self, args=None, namespace=None):
        self.parsed = argparse.Namespace() if namespace is None else namespace
        return super().parse_known_args(args, self.parsed)

    def error(self, message):
        """The usage error; a missing argument that an option of several values took says so."""
        took = [f"{action.option_strings[-1]} took {' '.join(getattr(self.parsed, action.dest))!r}: give "
                f"{action.option_strings[-1]} after them" for action in self._actions
                if action.option_strings and action.nargs == "+"
                and len(getattr(self.parsed, action.dest, None) or ()) > 1]
        if took and message.startswith("the following arguments are required"):
            message += f" ({'; '.join(took)})"
        raise InputError(message)

    def add_argument(self, *args, **kwargs):
        """argparse's, but the help of an argument that names where a command writes (OUTPUTS) says that missing
        folders are created (CREATES_FOLDERS)."""
        action = super().add_argument(*args, **kwargs)
        if action.dest in OUTPUTS:
            action.help = f"{action.help or 'where to write'} ({CREATES_FOLDERS})"
        return action


def examples(*lines: str) -> str:
    """An epilog of worked examples, one command per line."""
    return "examples:\n" + "\n".join(f"  {line}" for line in lines)


# ---- argument types (argparse names the option in its one-line error) -----------------------------------
def number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def integer_at_least(minimum: int):
    """An argparse type: an integer ≥ ``minimum``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{value} must be ≥ {minimum}")
        return value

    return parse


positive_int = integer_at_least(1)
non_negative_int = integer_at_least(0)


def iteration_count(text: str):
    """An argparse type for ``--iters``: ``auto`` or an integer ≥ 1."""
    return text if text == "auto" else positive_int(text)


def weight(auto: bool):
    """An argparse type: a number, or ``auto`` when the prior has an auto rule."""
    def parse(text: str):
        if not auto:
            return number(text)
        try:
            return text if text == "auto" else number(text)
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number or auto") from None

    return parse


def weights(text: str) -> tuple[float, float, float]:
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected WX,WY,WL")
    return tuple(number(p) for p in parts)


def iterations(text: str) -> tuple[int, ...]:
    return tuple(positive_int(p) for p in text.split(","))


def size(minimum: int = 1):
    """An argparse type: 'HxW' (or 'H×W') -> (H, W), both ≥ ``minimum``."""
    def parse(text: str) -> tuple[int, int]:
        parts = text.replace("×", "x").lower().split("x")
        if len(parts) != 2:
            raise argparse.ArgumentTypeError(f"{text!r}: expected HxW, e.g. 320x448")
        return tuple(integer_at_least(minimum)(p) for p in parts)

    return parse


def existing_folder(text: str) -> str:
    """An argparse type: a path that is an existing folder."""
    from pathlib import Path

    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no such folder")
    return text


# ---- option groups --------------------------------------------------------------------------------------
DATA_OPTION = ("--data", dict(
    type=existing_folder, default=None, metavar="DIR",
    help="the shared data folder (real cubes, measured PSFs, lamp spectra; default: $CLSDCAM_DATA, else the first "
         "shared/data in the working folder or a folder above it, e.g. ../shared/data from a clone beside it, else "
         "beside the package's clone)"))


def add_data_option(p: argparse.ArgumentParser):
    """``--data DIR``: the shared data folder (:mod:`clsdcam.data`) for the commands that read it."""
    flag, keywords = DATA_OPTION
    p.add_argument(flag, **keywords)


def add_backend_options(p: argparse.ArgumentParser):
    p.add_argument("--backend", default="auto", choices=("auto", "numpy", "opencl"),
                   help="auto: opencl on an OpenCL GPU when one is found (or on --device when given), else numpy, "
                        "saying which; a CPU's OpenCL device (PoCL) only when opencl is named: no faster than numpy, "
                        "the reference (docs/benchmarks.md)")
    p.add_argument("--device", default=None,
                   help="OpenCL device: substring of platform or device name (default: PYOPENCL_CTX, else a GPU, else a CPU)")
    p.add_argument("--path", default="auto", choices=("auto", "host", "device"),
                   help="which code runs the heavy primitives: host code on mapped buffers (CPU devices only) or "
                        "kernels with the FFT on the device (what a GPU runs; on a CPU device such as PoCL it is ten "
                        "to a hundred times slower than host: docs/benchmarks.md) (default auto: host on CPU "
                        "devices, device elsewhere)")
    p.add_argument("--fft", default="auto", choices=("auto", "host", "reikna", "vkfft"),
                   help="FFT engine (default auto: host pocketfft on the host path, vkfft if installed else reikna on "
                        "the device path)")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"),
                   help="the solver's floating-point precision on the backend (float64 needs a device with fp64)")


def add_solver_options(p: argparse.ArgumentParser):
    """The solver's options: iterations, one weight per prior of the table, stopping rules, skips, backend."""
    from ..algorithms import ALGORITHMS
    from ..solve.priors import PRIORS
    from ..solve.auto_weights import AUTO_AT, POINTS_IN_GOOD_LIGHT_STOP, RECOUNT_AT
    from ..solve.settings import AUTO_CAP, CONVERGE, CONVERGE_WIDE, DEFAULT_ITERS

    p.add_argument("--iters", type=iteration_count, default=DEFAULT_ITERS, metavar="N|auto",
                   help=f"iterations: a number, or auto (the default): until the estimated distance to the converged "
                        f"cube is below --converge, at most {AUTO_CAP}")
    p.add_argument("--converge", type=weight(True), default="auto", metavar="D|auto",
                   help=f"with --iters auto: stop when the estimated relative distance to the converged cube is below "
                        f"D; auto (the default): {CONVERGE:g}, or {CONVERGE_WIDE:g} once iteration {AUTO_AT} shows a "
                        f"scene that is not point-like (unless sparse in good light), "
                        f"{CONVERGE * POINTS_IN_GOOD_LIGHT_STOP:g} on a point-like one in good light, or less on one "
                        f"of few lit voxels until a recount at iteration {RECOUNT_AT}, which widens it where it finds "
                        f"lit spots ({CONVERGE:g}; {CONVERGE * POINTS_IN_GOOD_LIGHT_STOP:g} in good light, if not of "
                        f"the fewest); "
                        f"{CONVERGE:g} where that probe does not run (FISTA, a weight given; docs/convergence.md)")
    p.add_argument("--algorithm", default="auto", choices=("auto",) + tuple(ALGORITHMS),
                   help="the algorithm the solve runs: fista (FISTA with adaptive restart), admm (ADMM with "
                        "closed-form steps: fewer iterations, band space only, --tv and --l1 only), or auto (the "
                        "default): admm with --iters auto where it can run, else fista")
    for row in PRIORS:
        p.add_argument(row.flag, dest=row.name, type=weight(row.prior.auto_weight is not None), default=row.default,
                       metavar="W|auto" if row.prior.auto_weight else "W", help=f"{row.help} (default {row.default})")
    p.add_argument("--tv-weights", type=weights, default=(1.0, 1.0, 1.0), metavar="WX,WY,WL",
                   help="TV weights along x, y and λ (default 1,1,1)")
    p.add_argument("--tol", type=number, default=0.0, help="stop when ‖Δx‖/‖x‖ < TOL (default: off)")
    p.add_argument("--plateau", type=number, default=0.0,
                   help="stop when the objective fell by less than this (relative) over its last check (default: off)")
    p.add_argument("--rank", type=non_negative_int, default=0, metavar="R",
                   help="solve for R spectral basis vectors instead of the bands (default 0: as --subspace says)")
    p.add_argument("--subspace", action="store_true",
                   help="enter a spectral subspace of automatic size once the spectra settle: faster, but it can "
                        "cost spectral angle on scenes with many smooth, overlapping spectra (default: band space; "
                        "ignored with --no-skip)")
    p.add_argument("--support-field", action="store_true",
                   help="solve on the field the PSF's support needs instead of the paper's 2H×2W: faster (~20%% at "
                        "full size), but the solve then differs from --no-skip's (0.2 dB at 500 iterations on a real "
                        "cube; default: the paper's field; ignored with --no-skip)")
    p.add_argument("--no-skip", action="store_true",
                   help="the full solver: the paper's 2H×2W field, every band, no spectral subspace")
    add_backend_options(p)
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
    p.add_argument("--dead-pixels", default=None, metavar="FILE",
                   help="image/.npy mask (non-zero = dead, same size as the measurement) of pixels to exclude")


def add_measurement_options(p: argparse.ArgumentParser, average: bool = True):
    """The measurement's own steps (:mod:`clsdcam.calibrate.measurement`): frames averaged (``average``: not for
    batch, whose frames are a video), dark, binning."""
    if average:
        p.add_argument("--average", type=positive_int, default=None, metavar="N",
                       help="average N consecutive frames into one measurement: the first N measurement files "
                            "(default: all the files given)")
    p.add_argument("--dark", nargs="+", default=None, metavar="FILE|LEVEL",
                   help="the measurement's dark, subtracted and clipped at 0: dark frames (averaged) or one level; "
                        "replaces the dark a calibration recorded (default: none, or the recorded one)")
    p.add_argument("--bin", type=positive_int, default=1, metavar="N",
                   help="N×N block means of the measurement, ragged edge dropped (a measurement of a calibration's "
                        "raw size gets its recorded binning)")


def add_simulation_options(p: argparse.ArgumentParser):
    """The simulated camera and scene: scene, seed, noise, size, bands, and the shared data folder (``realcube``)."""
    from ..camera.prototype import N_BANDS, SENSOR_SHAPE

    p.add_argument("--scene", default="target", choices=SCENES, metavar="SCENE",
                   help=f"{', '.join(SCENES)} (default target)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    p.add_argument("--noise", type=number, default=None,
                   help="Gaussian read-noise variance relative to max(b)², after shot noise of 20 000 photons at the "
                        "peak (default 1e-5)")
    p.add_argument("--size", type=size(), default=SENSOR_SHAPE, metavar="HxW",
                   help=f"sensor size (default {SENSOR_SHAPE[0]}x{SENSOR_SHAPE[1]})")
    p.add_argument("--bands", type=positive_int, default=N_BANDS, help=f"number of bands (default {N_BANDS})")
    add_data_option(p)


# ---- the parser -----------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """``clsdcam`` with one sub-command per module of this package (each module's ``add_parser``)."""
    parser = Parser(prog="clsdcam", description="Spectral DiffuserCam hyperspectral reconstruction")
    parser.add_argument("--version", action="version", version=f"clsdcam {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser,
                                title="commands (clsdcam COMMAND --help for each)")
    for name in commands():
        command_module(name).add_parser(sub)
    return parser


def commands() -> list[str]:
    """The command modules of this package (each with ``add_parser`` and ``run``), in ORDER, then any other."""
    import pkgutil

    found = {m.name for m in pkgutil.iter_modules(importlib.import_module(__package__).__path__)
             if not m.name.startswith("_") and m.name not in HELPERS}
    return [n for n in ORDER if n in found] + sorted(found - set(ORDER))


def command_module(name: str):
    """``clsdcam.cli.<name>``: its ``add_parser(subparsers)`` and ``run(args) -> exit code``."""
    return importlib.import_module(f"{__package__}.{name}")


# ---- options -> objects ---------------------------------------------------------------------------------
def settings_from(args):
    """Solver settings from the command-line options (every prior's weight by its table name)."""
    from ..solve.priors import PRIORS
    from ..solve.settings import Settings

    return Settings(iters=args.iters, converge=args.converge, algorithm=args.algorithm, tv_weights=args.tv_weights, tol=args.tol, plateau=args.plateau, rank=args.rank,
                    subspace=args.subspace, support_field=args.support_field, skip=not args.no_skip, dtype=args.dtype,
                    full_field=getattr(args, "full_field", False),
                    **{row.name: getattr(args, row.name) for row in PRIORS})


def preprocessing_from(args):
    """The preprocessing steps the options ask for (``--reference-preprocess`` as the base)."""
    from ..camera.calibration import Preprocessing, parse_crop

    base = Preprocessing.reference() if args.reference_preprocess else Preprocessing()
    crop = parse_crop(args.crop) if args.crop else base.crop
    return Preprocessing(
        crop=crop,
        normalize_psf=not args.no_normalize_psf,
        normalize_filters=not args.no_normalize_filters,
        zero_defect=args.zero_defect or base.zero_defect,
        drop_last_band=args.drop_last_band or base.drop_last_band,
        saturation=getattr(args, "saturation", None),
        dead_pixels=_dead_pixels(args.dead_pixels, crop),
        dark=_dark(getattr(args, "dark", None)),
        bin=getattr(args, "bin", 1),
    )


def _dark(values):
    """--dark's values: one level (a number), dark frame files (a tuple) or None."""
    from ..calibrate.dark import dark_level

    if values is None:
        return None
    level = dark_level(values)
    return tuple(values) if level is None else level


def _dead_pixels(path, crop):
    """The --dead-pixels mask, cropped like the measurement."""
    if path is None:
        return None
    from ..camera.calibration import PixelMask
    from ..io import load_measurement

    mask = load_measurement(path)
    return PixelMask.of(mask if crop is None else mask[crop[0]:crop[1], crop[2]:crop[3]])
