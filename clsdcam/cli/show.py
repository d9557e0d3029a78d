"""``clsdcam show CUBE.h5``: the pictures of an existing cube (:func:`clsdcam.render.save_pictures`), next to a
truth cube when given."""
from __future__ import annotations

from pathlib import Path

from ..errors import InputError, shape_text
from .options import examples

EXAMPLES = examples("clsdcam show cube.h5                        # cube_falsecolour.png, ...",
                    "clsdcam show cube.h5 --truth sim/truth.h5   # truth spectra dashed",
                    "clsdcam show cube.h5 -o pictures/run1       # pictures/run1_falsecolour.png, ...")
PICTURES = ("Draw PREFIX_falsecolour.png, _projections.png, _spectra.png and, when the file holds the solver's "
            "history, _convergence.png.")


def add_parser(subparsers):
    p = subparsers.add_parser("show", help="draw the pictures of an existing cube", description=PICTURES,
                              epilog=EXAMPLES)
    p.add_argument("cube", help="an HDF5 file with a 3-D 'cube' (clsdcam reconstruct, or a simulator's truth.h5)")
    p.add_argument("--truth", default=None, metavar="TRUTH.h5", help="a cube of the same shape, drawn dashed")
    p.add_argument("-o", "--output", default=None, metavar="PREFIX",
                   help="prefix of the PNG files (default: CUBE's path without its suffix)")


def run(args) -> int:
    from ..io import check_output, read_cube
    from ..render import save_pictures

    prefix = Path(args.output) if args.output else Path(args.cube).with_suffix("")
    check_output(prefix.with_name(prefix.name + "_falsecolour.png"), "pictures")
    data = read_cube(args.cube)
    truth = read_cube(args.truth)["cube"] if args.truth else None
    if truth is not None and truth.shape != data["cube"].shape:
        raise InputError(f"truth {args.truth}: cube {shape_text(truth.shape)} does not match "
                         f"{args.cube}'s {shape_text(data['cube'].shape)}")
    paths = save_pictures(prefix, data["cube"], data["wavelengths"], history=records(data["history"]), truth=truth)
    print("pictures: " + ", ".join(str(p) for p in paths))
    return 0


def records(history: dict) -> list[dict]:
    """A cube file's history group {key: values per iteration} as one record per iteration."""
    return [dict(zip(history, row)) for row in zip(*history.values())]
