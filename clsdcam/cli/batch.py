"""``clsdcam batch FRAMES... --calibration CAL -o OUT.h5``: many frames, on Dask distributed."""
from __future__ import annotations

import sys

from .options import (add_measurement_options, add_preprocessing_options, add_solver_options, examples,
                      integer_at_least, positive_int)


EXAMPLES = examples(
    "clsdcam batch video/frames.npy --calibration video/calibration.h5 -o cubes.h5 --workers 2 --iters 10 "
    "--truth video/truth.h5",
    "clsdcam batch frames/ --calibration calibration.mat --reference-preprocess -o run.h5 --workers 0 --tol 1e-4",
    "clsdcam batch /shared/frames.h5 --calibration /shared/cal.mat -o /shared/cubes.h5 --scheduler tcp://host:8786",
    "# after Ctrl-C or a crash, the same command computes only the frames still missing")


def add_parser(subparsers):
    from ..solve.settings import COLD_ITERS, DEFAULT_ITERS

    p = subparsers.add_parser("batch", help="reconstruct many frames (warm-started streams on Dask workers)",
                              description="Reconstruct many frames: warm-started streams, on Dask workers; a "
                                          "re-run computes only the frames still missing.",
                              epilog=EXAMPLES)
    p.add_argument("frames", nargs="+", help="frame files, a folder of them, or one stack (.npy/.h5 (N,H,W), TIFF)")
    p.add_argument("--calibration", required=True, help="calibration.mat (psf, mask, wavs) or our .h5")
    p.add_argument("-o", "--output", required=True, help="OUT.h5 (parts in OUT.h5.parts/)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=integer_at_least(0), default=1,
                       help="worker processes of an embedded Dask LocalCluster, at most one per core, each with "
                            "cores / workers threads (0: one in-process stream on all cores)")
    where.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT", help="an existing Dask scheduler")
    p.add_argument("--chunk", type=positive_int, default=None,
                   help="frames per task (default: missing frames / workers, at most 64: each chunk's first frame "
                        "is a cold start)")
    p.add_argument("--cold-iters", type=positive_int, default=None,
                   help=f"iterations of a cold start (a chunk's first frame); --iters is the budget of the "
                        f"warm-started frames after it (default: the larger of {COLD_ITERS} and --iters, so "
                        f"{DEFAULT_ITERS} with the default --iters)")
    p.add_argument("--no-warm-start", action="store_true", help="start every frame from zero (each with --iters)")
    p.add_argument("--overwrite", action="store_true", help="recompute everything (default: only the missing frames)")
    p.add_argument("--truth", default=None, metavar="TRUTH.h5",
                   help="a simulated video's true cubes (truth.h5 of clsdcam simulate --frames), checked against the "
                        "frames before any work: each frame's PSNR, mean spectral angle and peak ratio (its peaks "
                        "over the truth's at the truth's brightest points) printed and stored in OUT.h5's attributes")
    add_solver_options(p)
    add_preprocessing_options(p)
    add_measurement_options(p, average=False)


def run(args) -> int:
    """Exit code: 0, 1 if some frame failed, 130 after a Ctrl-C that kept some frames (said on stderr); 2 without
    the video extra, before anything is said or done."""
    from ..batch import BatchInterrupted
    from ..extras import require

    require("batch")
    try:
        summary = _run_batch(args)
    except BatchInterrupted as stop:
        print(f"clsdcam: {stop}", file=sys.stderr)
        return 130
    rate = summary.computed_frames / summary.seconds if summary.seconds else 0.0
    print(f"wrote {args.output}: {summary.n_frames} frames ({summary.computed_frames} computed now, "
          f"{rate:.2f} frames/s, on {summary.layout}), {len(summary.failed)} failed")
    if summary.accuracy:
        print(f"against {args.truth}:\n" + "\n".join(accuracy_lines(summary)))
    for index, reason in summary.failed:
        print(f"  frame {index}: {reason}", file=sys.stderr)
    return summary.exit_code


def accuracy_lines(summary) -> list[str]:
    """One line per frame: how it was solved (cold or warm, iterations) and its accuracy (or that it failed)."""
    from .solve import accuracy_text

    records, lines = summary.per_frame, []
    for i in range(summary.n_frames):
        start, iterations = "warm" if records["warm"][i] else "cold", int(records["iterations"][i])
        figures = {name: values[i] for name, values in summary.accuracy.items()}
        lines.append(f"  frame {i}: " + ("failed" if records["error"][i] else f"{start}, {iterations} iteration"
                                         f"{'s' * (iterations != 1)}: {accuracy_text(figures)}"))
    return lines


def _run_batch(args):
    """run_batch as the options ask, with a progress bar unless --quiet."""
    from ..batch import BatchSpec, run_batch
    from .options import preprocessing_from, settings_from
    from .solve import chosen_backend

    settings = settings_from(args)
    spec = BatchSpec(frames=tuple(args.frames), calibration=args.calibration, preprocessing=preprocessing_from(args),
                     settings=settings, backend=chosen_backend(args, settings.algorithm), device=args.device,
                     fft=args.fft, path=args.path, warm_start=not args.no_warm_start, cold_iters=args.cold_iters)
    bars = []
    try:
        return run_batch(spec, args.output, workers=args.workers, scheduler=args.scheduler, chunk=args.chunk,
                         overwrite=args.overwrite, truth=args.truth, progress=lambda k: bars and bars[0].update(k),
                         on_plan=None if args.quiet else lambda n, missing, layout: bars.append(
                             _bar(n, n - missing, layout)))
    finally:
        for bar in bars:
            bar.close()


def _bar(total: int, done: int, layout):
    """One bar over all frames (those done by an earlier run already counted), headed by where they run
    (``layout``); tqdm shows frames/s and ETA."""
    from tqdm import tqdm

    return tqdm(total=total, initial=done, unit="frame", file=sys.stderr, dynamic_ncols=True, smoothing=0.1,
                desc=str(layout))
