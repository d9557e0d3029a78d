"""``clsdcam simulate OUTDIR``: a simulated camera, scene and measurement (or a drifting video)."""
from __future__ import annotations

import argparse

from ..errors import InputError, shape_text
from .options import add_simulation_options, examples, positive_int


def drift_pair(text: str) -> tuple[float, float]:
    """``DY,DX`` px per frame."""
    try:
        dy, dx = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected DY,DX in px per frame, e.g. 0.3,0.6") from None
    return dy, dx


def add_parser(subparsers):
    p = subparsers.add_parser("simulate", help="simulate a camera, a scene and its measurement", description=(
        "Simulate a Spectral DiffuserCam (caustic PSF, tiled filter array) looking at a scene, and write its "
        "calibration.h5, the noisy measurement.npy and the true cube truth.h5 into OUTDIR (a video's frames.npy "
        "with --frames, a monochromator sweep with --sweep): inputs for reconstruct, batch and calibrate whose "
        "answer is known."), epilog=examples(
        "clsdcam simulate sim/ --scene target",
        "clsdcam simulate small/ --scene leds --size 64x96 --bands 16 --noise 1e-4",
        "clsdcam simulate video/ --scene leds --frames 16 --drift 0.3,0.6",
        "clsdcam simulate lab/ --sweep --size 48x64 --bands 16   # + a monochromator sweep to calibrate from"))
    p.add_argument("outdir", metavar="OUTDIR", help="the folder to write into")
    p.add_argument("--frames", type=positive_int, default=None,
                   help="write a video of N frames of the scene drifting (frames.npy, truth.h5)")
    p.add_argument("--drift", type=drift_pair, default=None, metavar="DY,DX",
                   help="the video's drift in px per frame (default: 0,1 for leds, 0.5,0.5 for the others)")
    p.add_argument("--sweep", action="store_true",
                   help="also write a monochromator sweep of the filter array (sweep/, dark/, sweep_wavelengths.csv, "
                        "power.csv, true_filters.h5, psf_calibration.h5) for 'clsdcam calibrate filters'; the "
                        "camera's filters are then the true transmissions integrated over each band")
    add_simulation_options(p)


def run(args) -> int:
    from ..io import check_folder
    from ..sim import simulate, write_simulation

    if args.frames and args.sweep:
        raise InputError("--sweep and --frames: choose one")
    check_folder(args.outdir, f"output folder {args.outdir}")
    if args.frames:
        return _simulate_video(args)
    if args.sweep:
        return _simulate_sweep(args)
    sim = simulate(**simulation_kwargs(args))
    paths = write_simulation(args.outdir, sim)
    print(f"simulated scene {sim.scene!r} ({shape_text(sim.truth.shape)}): " +
          ", ".join(str(p) for p in paths.values()))
    return 0


def _simulate_video(args) -> int:
    from ..sim import simulate_video, write_video

    calibration, frames, truth = simulate_video(args.scene, args.frames, args.size, args.bands, args.seed,
                                                drift=args.drift)
    paths = write_video(args.outdir, calibration, frames, truth)
    print(f"simulated {args.frames} frames of {args.scene!r}: " + ", ".join(str(p) for p in paths.values()))
    return 0


def _simulate_sweep(args) -> int:
    from ..sim.sweep import simulate_with_sweep, write_sweep

    sim, sweep = simulate_with_sweep(**simulation_kwargs(args))
    paths = write_sweep(args.outdir, sim, sweep)
    print(f"simulated scene {sim.scene!r} ({shape_text(sim.truth.shape)}) and a sweep of {len(sweep.wavelengths)} "
          f"frames {sweep.wavelengths[0]:g}–{sweep.wavelengths[-1]:g} nm (power: {sweep.power_source}): " +
          ", ".join(str(p) for p in paths.values()))
    return 0


def simulation_kwargs(args) -> dict:
    """simulate()'s arguments from the simulation options."""
    kwargs = {"scene": args.scene, "shape": args.size, "n_bands": args.bands, "seed": args.seed}
    if args.noise is not None:
        if args.noise < 0:
            raise InputError(f"--noise {args.noise}: must be ≥ 0")
        kwargs["noise_var"] = args.noise
    return kwargs
