"""``clsdcam export CUBE.h5 -o OUT``: a cube as ENVI, multi-page TIFF, NetCDF or a false-colour PNG, or a batch
output made self-contained (``--format h5``); the writers are in :mod:`clsdcam.export`."""
from __future__ import annotations

from .options import examples, non_negative_int

FORMATS = ("envi", "tiff", "netcdf", "png", "h5")   # clsdcam.export.FORMATS (tested)

EXAMPLES = examples("clsdcam export cube.h5 -o cube.hdr          # ENVI: cube.hdr + cube.img",
                    "clsdcam export cube.h5 -o cube.nc           # NetCDF, for xarray and ncview",
                    "clsdcam export video.h5 -o video-all.h5     # no video.h5.parts/ needed any more",
                    "clsdcam export video.h5 -o f7.tif --frame 7 # frame 7 as a 32-bit float TIFF")


def add_parser(subparsers):
    description = ("Write a cube file's cube (or one frame of a batch output) for other tools, or copy a batch "
                   "output's frames into one self-contained HDF5 file.")
    p = subparsers.add_parser("export", help="write a cube as ENVI, TIFF, NetCDF or PNG, or a batch output "
                              "self-contained", description=description, epilog=EXAMPLES)
    p.add_argument("cube", help="a cube file (clsdcam reconstruct) or a batch output (clsdcam batch)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="the file to write (ENVI: OUT's stem .hdr and .img)")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="default: from OUT's suffix (.hdr/.img envi, .tif/.tiff tiff, .nc netcdf, .png png, .h5 h5)")
    p.add_argument("--frame", type=non_negative_int, default=0,
                   help="the frame of a batch output to write (all formats but h5, which copies every frame)")


def run(args) -> int:
    from ..export import export, format_for, output_paths
    from ..io import check_output

    fmt = format_for(args.output, args.format)
    for path in output_paths(args.output, fmt):
        check_output(path)
    paths = export(args.cube, args.output, fmt, args.frame)
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0
