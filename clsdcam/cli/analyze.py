"""``clsdcam analyze {resolution,condition,designs,spectral,twopoint,all} OUTDIR``: the paper's analyses
(:mod:`clsdcam.analyses`), each writing ``NAME.json`` and ``NAME.png`` into OUTDIR; ``all`` also writes
``report.html`` and ``summary.md`` and prints the summary table next to the paper's values."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..prototype import N_BANDS, SENSOR_SHAPE
from .options import examples, integer_at_least, size

ANALYSES = ("resolution", "condition", "designs", "spectral", "twopoint")
HELP = {"resolution": "PSF autocorrelation half-width at 70 %% (simulated and measured PSFs)",
        "condition": "local condition numbers of groups of points: diffuser, low-NA and high-NA lenses",
        "designs": "the resolution target through the three designs: PSNR, spectral angle, pictures",
        "spectral": "peak-wavelength error of narrow-band point sources over 386–898 nm",
        "twopoint": "two-point resolution at 618, 522, 466 nm by the Rayleigh criterion",
        "all": "every analysis, a summary table and report.html"}


def add_parser(subparsers) -> argparse.ArgumentParser:
    """The ``analyze`` subcommand with one sub-choice per analysis (dest ``what``), each taking OUTDIR
    and the size options."""
    options = argparse.ArgumentParser(add_help=False)
    options.add_argument("outdir", help="folder for the JSON, PNG (and report) files")
    options.add_argument("--size", type=size(8), default=SENSOR_SHAPE, metavar="HxW",
                         help="sensor of the PSF and condition-number analyses (default 320x448)")
    options.add_argument("--recon-size", type=size(8), default=(64, 96), metavar="HxW",
                         help="sensor of the reconstruction analyses (default 64x96)")
    options.add_argument("--bands", type=integer_at_least(2), default=N_BANDS,
                         help="bands of the filter array and the reconstructions (default 64)")
    options.add_argument("--iters", type=integer_at_least(1), default=200,
                         help="iterations per reconstruction (default 200)")
    options.add_argument("--trials", type=integer_at_least(1), default=5,
                         help="random placements per condition number (default 5)")
    options.add_argument("--seed", type=int, default=0, help="seed of every random choice")
    parser = subparsers.add_parser("analyze", help="the paper's resolution analyses (JSON + PNG per analysis)",
                                   epilog=examples("clsdcam analyze all analysis/",
                                                   "clsdcam analyze resolution out/ --size 320x448",
                                                   "clsdcam analyze spectral out/ --recon-size 64x96 --iters 200"))
    which = parser.add_subparsers(dest="what", required=True, metavar="{" + ",".join(ANALYSES + ("all",)) + "}")
    for name in ANALYSES + ("all",):
        which.add_parser(name, parents=[options], help=HELP[name], description=HELP[name])
    return parser


def run(args) -> int:
    """Run the chosen analyses; print where each went; for ``all`` the summary table and the report."""
    from ..analyses import RUNNERS, summary_table, write_json, write_report
    from ..io import atomic_output

    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    names = ANALYSES if args.what == "all" else (args.what,)
    results = {}
    for name in names:
        start = time.perf_counter()
        results[name] = RUNNERS[name](args, out)
        results[name]["seconds"] = round(time.perf_counter() - start, 1)
        write_json(out / f"{name}.json", results[name])
        print(f"{name}: {out / (name + '.json')}, {out / (name + '.png')} ({results[name]['seconds']:.0f} s)")
    if args.what == "all":
        table = summary_table(results)
        print(table)
        with atomic_output(out / "summary.md") as tmp:
            tmp.write_text(table + "\n", encoding="utf-8")
        write_report(out, table, results)
    return 0
