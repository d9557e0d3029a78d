"""``clsdcam show CUBE.h5``: the pictures of an existing cube (:func:`clsdcam.render.save_pictures`), next to a
truth cube when given, and of what it was reconstructed from (:mod:`clsdcam.input_pictures`)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import InputError, shape_text
from .options import examples, non_negative_int

EXAMPLES = examples("clsdcam show cube.h5                           # cube_falsecolour.png, ...",
                    "clsdcam show cube.h5 --truth sim/truth.h5      # truth spectra dashed",
                    "clsdcam show cube.h5 --points '40,60;200,300'  # spectra at (y=40, x=60) and (y=200, x=300)",
                    "clsdcam show vid/cubes.h5 --frame 7 --truth vid/truth.h5   # frame 7 of a batch output",
                    "clsdcam show cube.h5 -o pictures/run1          # pictures/run1_falsecolour.png, ...")
PICTURES = ("Draw PREFIX_falsecolour.png, _projections.png and _spectra.png (numbered on the false colour); "
            "_convergence.png when the file holds the solver's history; _input.png (the raw frame, the PSF and the "
            "filter array's layout) when the measurement or the calibration is known. See docs/pictures.md.")
# what `clsdcam simulate` writes beside its truth.h5, which records no inputs: named when show finds them there
SIMULATED = {"measurement": {"measurement.npy": "the simulated frame",
                             "frames.npy": "the simulated video: --frame N draws its frame N"},
             "calibration": {"calibration.h5": "the simulated calibration"}}


def add_parser(subparsers):
    p = subparsers.add_parser("show", help="draw the pictures of an existing cube", description=PICTURES,
                              epilog=EXAMPLES)
    p.add_argument("cube", help="a cube file (clsdcam reconstruct, demo), a batch output (clsdcam batch) or a "
                                "simulator's truth.h5 (one cube, or a video's cubes: see --frame)")
    p.add_argument("--frame", type=non_negative_int, default=0,
                   help="the frame of a batch output or a video's truth, for CUBE and --truth alike")
    p.add_argument("--truth", default=None, metavar="TRUTH.h5", help="a cube of the same shape, drawn dashed")
    p.add_argument("--points", type=points, default=None, metavar="Y,X;Y,X;...",
                   help="the pixels whose spectra are drawn (default: one per distinct lit region, up to 6, "
                        "found in the truth when given)")
    p.add_argument("--measurement", default=None, metavar="FILE",
                   help="the raw frame (or a stack of them) drawn in _input.png (default: the one the cube records)")
    p.add_argument("--calibration", default=None, metavar="CAL",
                   help="the calibration whose PSF and filters _input.png draws (default: the one the cube records)")
    p.add_argument("-o", "--output", default=None, metavar="PREFIX",
                   help="prefix of the PNG files (default: CUBE's path without its suffix)")


def points(text: str) -> list[tuple[int, int]]:
    """An argparse type: 'y,x;y,x;…' → [(y, x), …] (integers; checked against the image when drawn)."""
    try:
        pairs = [tuple(int(v) for v in pair.split(",")) for pair in text.split(";") if pair.strip()]
    except ValueError:
        pairs = []
    if not pairs or any(len(pair) != 2 for pair in pairs):
        raise argparse.ArgumentTypeError(f"{text!r}: expected pixels as y,x pairs split by ';', e.g. '40,60;200,300'")
    return pairs


def run(args) -> int:
    from ..export import read_source
    from ..io import check_output

    prefix = Path(args.output) if args.output else Path(args.cube).with_suffix("")
    check_output(prefix.with_name(prefix.name + "_falsecolour.png"), "pictures")
    data = read_source(args.cube, args.frame)
    truth = read_source(args.truth, args.frame)["cube"] if args.truth else None
    if truth is not None and truth.shape != data["cube"].shape:
        raise InputError(f"truth {args.truth}: cube {shape_text(truth.shape)} does not match "
                         f"{args.cube}'s {shape_text(data['cube'].shape)}")
    inputs, notes = find_inputs(args, data["attrs"])
    draw(prefix, data["cube"], data["wavelengths"], records(data.get("history", {})), truth, args.points, inputs)
    for note in notes:
        print(note)
    return 0


def draw(prefix, cube, wavelengths, history, truth, chosen, inputs):
    """The cube's pictures (spectra at ``chosen``, or None for :func:`clsdcam.picks.spectrum_points` of the truth
    when given, else of the cube) and the input picture of ``inputs`` (:class:`clsdcam.input_pictures.Inputs`);
    prints their paths and the pixels of the spectra."""
    from ..input_pictures import save_input_picture
    from ..picks import spectrum_points
    from ..render import save_pictures

    chosen = spectrum_points(cube if truth is None else truth, wavelengths) if chosen is None else chosen
    paths = save_pictures(prefix, cube, wavelengths, history=history, points=chosen, truth=truth)
    paths += save_input_picture(prefix, inputs)
    print("pictures: " + ", ".join(str(p) for p in paths))
    if cube.shape[0] > 1:
        print("spectra at: " + "; ".join(f"{i + 1} (y={y}, x={x})" for i, (y, x) in enumerate(chosen)))


# ---- what the cube was reconstructed from ----------------------------------------------------------------
def find_inputs(args, attrs: dict):
    """(:class:`clsdcam.input_pictures.Inputs`, notes to print): the raw frame and the calibration from
    ``--measurement`` / ``--calibration``, else from the paths the cube records (``measurement_path`` or a batch's
    ``frames_path``, ``calibration_path``), each found as recorded or by its name beside the cube. A given file
    that cannot be read is an InputError; a recorded one that is missing or unreadable is left out, with a note."""
    from ..camera.calibration import Calibration
    from ..input_pictures import Inputs

    def calibration(paths):
        return Calibration.load(paths[0]), str(paths[0])

    notes = []
    frame, frame_source = load(lambda paths: read_frame(paths, args.frame), args.measurement,
                               recorded(attrs, "measurement_path", "frames_path"), "measurement", args.cube, notes)
    cal, cal_source = load(calibration, args.calibration, recorded(attrs, "calibration_path"), "calibration",
                           args.cube, notes)
    return Inputs.of(frame, frame_source, cal, cal_source), notes


def recorded(attrs: dict, *keys: str) -> list[str]:
    """The paths under the first of ``keys`` the cube's attributes hold (a JSON list for several files), or []."""
    for key in keys:
        value = str(attrs.get(key, ""))
        if value:
            return json.loads(value) if value.startswith("[") else [value]
    return []


def load(reader, given: str | None, paths: list[str], what: str, cube, notes: list):
    """``reader(files)`` → (value, its name) for the ``given`` file, else for the recorded ``paths`` once located;
    (None, "") with a note when there are none, they are not found, or they cannot be read."""
    if given:
        return reader([given])
    found = [locate(p, cube) for p in paths]
    if not paths or None in found:
        where = f"{paths[found.index(None)]} (recorded) is not there nor beside the cube; give --{what}" if paths \
            else unrecorded(what, cube)
        notes.append(f"input picture: no {what}: {where}")
        return None, ""
    try:
        return reader(found)
    except InputError as exc:
        notes.append(f"input picture: no {what}: {exc}")
        return None, ""


def unrecorded(what: str, cube) -> str:
    """The note on a cube that records no ``what``: which option to give, naming the simulator's file of it
    (SIMULATED) when one lies beside the cube."""
    beside = [(path, text) for name, text in SIMULATED[what].items() if (path := Path(cube).parent / name).is_file()]
    hint = f" {beside[0][0]}, beside it ({beside[0][1]})" if beside else ""
    return f"the cube records none; give --{what}{hint}"


def locate(path: str, cube) -> Path | None:
    """``path`` as recorded if it is a file, else the file of its name beside ``cube``, else None."""
    for candidate in (Path(path), Path(cube).parent / Path(path).name):
        if candidate.is_file():
            return candidate
    return None


def read_frame(paths: list, index: int):
    """(frame ``index`` of the frames in ``paths``, its name): a stack or one file per frame
    (:class:`clsdcam.batch.frames.FrameSource`); the only frame when there is one."""
    from ..batch.frames import FrameSource

    source = FrameSource(paths)
    if len(source) == 1:
        return source.read(0), str(source.paths[0])
    if index >= len(source):
        raise InputError(f"measurement {paths[0]}: no frame {index} (it holds frames 0 to {len(source) - 1})")
    name = f"{source.paths[0]}, frame {index}" if source.stack else str(source.paths[index])
    return source.read(index), name


def records(history: dict) -> list[dict]:
    """A cube file's history group {key: values per iteration} as one record per iteration."""
    return [dict(zip(history, row)) for row in zip(*history.values())]
