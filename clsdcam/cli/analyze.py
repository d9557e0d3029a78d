"""``clsdcam analyze {resolution,condition,designs,spectral,twopoint,all} OUTDIR``: the paper's analyses
(:mod:`clsdcam.analyses`), each writing ``NAME.json`` and ``NAME.png`` into OUTDIR and printing its key figures;
``all`` also writes ``report.html`` and ``summary.md`` and prints the summary table next to the paper's values."""
from __future__ import annotations

import argparse
import time

from ..camera.prototype import N_BANDS, SENSOR_SHAPE
from .options import DATA_OPTION, examples, integer_at_least, size

ANALYSES = ("resolution", "condition", "designs", "spectral", "twopoint")
HELP = {"resolution": "PSF autocorrelation half-width at 70 % (simulated and measured PSFs)",
        "condition": "local condition numbers of groups of points: diffuser, low-NA and high-NA lenses",
        "designs": "the resolution target through the three designs: PSNR, spectral angle, pictures",
        "spectral": "peak-wavelength error of narrow-band point sources over 386–898 nm",
        "twopoint": "two-point resolution at 618, 522, 466 nm by the Rayleigh criterion",
        "all": "every analysis, a summary table and report.html"}
RECONSTRUCTION = ("recon_size", "bands", "iters", "seed")
USES = {"resolution": ("size", "seed", "data"), "condition": ("size", "bands", "trials", "seed"),
        "designs": RECONSTRUCTION, "spectral": RECONSTRUCTION, "twopoint": RECONSTRUCTION}
USES["all"] = tuple(dict.fromkeys(option for name in ANALYSES for option in USES[name]))


def options() -> dict:
    """Each option an analysis may read, by name: its flag and add_argument's keywords."""
    return {"size": ("--size", dict(type=size(8), default=SENSOR_SHAPE, metavar="HxW",
                                    help="sensor of the PSF and condition-number analyses (default 320x448)")),
            "recon_size": ("--recon-size", dict(type=size(8), default=(64, 96), metavar="HxW",
                                                help="sensor of the reconstruction analyses (default 64x96)")),
            "bands": ("--bands", dict(type=integer_at_least(2), default=N_BANDS,
                                      help="bands of the filter array and the reconstructions (default 64)")),
            "iters": ("--iters", dict(type=integer_at_least(1), default=200,
                                      help="iterations per reconstruction (default 200)")),
            "trials": ("--trials", dict(type=integer_at_least(1), default=5,
                                        help="random placements per condition number (default 5)")),
            "seed": ("--seed", dict(type=int, default=0, help="seed of every random choice")),
            "data": DATA_OPTION}


def add_parser(subparsers) -> argparse.ArgumentParser:
    """The ``analyze`` subcommand with one sub-choice per analysis (dest ``what``), each taking OUTDIR and the
    options it reads (USES)."""
    parser = subparsers.add_parser("analyze", help="the paper's resolution analyses (JSON + PNG per analysis)",
                                   description="Reproduce the paper's resolution analyses on the simulated camera: "
                                               "each writes NAME.json and NAME.png into OUTDIR; all runs every one "
                                               "and also writes summary.md and report.html, printing the summary "
                                               "beside the paper's values. Each analysis's --help shows its options.",
                                   epilog=examples("clsdcam analyze all analysis/",
                                                   "clsdcam analyze resolution out/ --size 320x448",
                                                   "clsdcam analyze spectral out/ --recon-size 64x96 --iters 200"))
    which = parser.add_subparsers(dest="what", required=True, metavar="{" + ",".join(ANALYSES + ("all",)) + "}")
    table = options()
    for name in ANALYSES + ("all",):
        sub = which.add_parser(name, help=HELP[name].replace("%", "%%"), description=HELP[name])
        sub.add_argument("outdir", help="folder for the JSON, PNG (and report) files")
        for option in USES[name]:
            flag, keywords = table[option]
            sub.add_argument(flag, **keywords)
    return parser


def run(args) -> int:
    """Run the chosen analyses; print where each went and its key figures (what it skipped among them); for ``all``
    the summary table and the report."""
    from ..analyses import RUNNERS, figure_lines, summary_table, write_json, write_report
    from ..io import atomic_output, check_folder

    out = check_folder(args.outdir, f"output folder {args.outdir}")
    names = ANALYSES if args.what == "all" else (args.what,)
    results = {}
    for name in names:
        start = time.perf_counter()
        results[name] = RUNNERS[name](args, out)
        results[name]["seconds"] = round(time.perf_counter() - start, 1)
        write_json(out / f"{name}.json", results[name])
        print(f"{name}: {out / (name + '.json')}, {out / (name + '.png')} ({results[name]['seconds']:.0f} s)")
        print("\n".join(figure_lines(name, results[name])))
    if args.what == "all":
        table = summary_table(results)
        print(table)
        with atomic_output(out / "summary.md") as tmp:
            tmp.write_text(table + "\n", encoding="utf-8")
        write_report(out, table, results)
    return 0
