"""``clsdcam demo [OUTDIR]``: simulate the default scene, reconstruct it, draw it beside its truth and its input,
report accuracy and time."""
from __future__ import annotations

import time
from pathlib import Path

from ..errors import shape_text
from .options import WORK, add_simulation_options, add_solver_options, examples, iterations, settings_from
from .simulate import simulation_kwargs
from .solve import print_accuracy, solve, write

QUICK = {"size": (160, 224), "iters": 100}   # --quick: a first look (half the sensor's sides, a third the iterations)
OUTDIR, QUICK_OUTDIR = f"{WORK}/demo", f"{WORK}/demo-quick"   # the default folders: the full demo's, --quick's
HALF_PEAK = 0.5     # a pixel passes a band when its filter transmits at least this fraction of the band's best pixel
# the project's analyses, quoted by the note on the target (README, "What the demo shows"; measured 2026-11-25):
PSF_RESOLUTION = "3.1 px"     # clsdcam analyze resolution: the simulated PSF's autocorrelation half-width at 70 %
TWO_POINT = "5–6 px"          # clsdcam analyze twopoint: two narrow-band points at 618, 522, 466 nm (Rayleigh)


def add_parser(subparsers):
    p = subparsers.add_parser("demo",
                              help=f"simulate the default scene, reconstruct it into {OUTDIR}/, report accuracy "
                                   "and time",
                              description=f"Simulate the default scene, reconstruct it, and write the cube, its "
                                          f"pictures and the simulation into OUTDIR (default {OUTDIR}/; with --quick "
                                          f"{QUICK_OUTDIR}/, so a first look leaves the full demo's folder alone); "
                                          "print PSNR, spectral angle and time.",
                              epilog=examples("clsdcam demo", "clsdcam demo --quick    # a first look",
                                              "clsdcam demo out/ --iters 500 --report-at 100,300",
                                              "clsdcam demo small/ --size 64x96 --bands 16 --backend opencl"))
    p.add_argument("outdir", nargs="?", default=None, metavar="OUTDIR",
                   help=f"the folder to write into (default: {OUTDIR}, with --quick {QUICK_OUTDIR})")
    p.add_argument("--report-at", type=iterations, default=(), metavar="N,N,...",
                   help="also print the accuracy after these iterations, e.g. 100,500 (default: the final one only)")
    p.add_argument("--quick", action="store_true",
                   help=f"a first look: --size {QUICK['size'][0]}x{QUICK['size'][1]} --iters {QUICK['iters']} "
                        "where not given (about a tenth of the default's time)")
    add_simulation_options(p)
    add_solver_options(p)
    p.set_defaults(size=None, iters=None)   # filled in by run(): the prototype's, or QUICK's with --quick


def run(args) -> int:
    from ..input_pictures import Inputs
    from ..io import check_output
    from ..provenance import provenance
    from ..sim import simulate, write_simulation
    from .show import draw

    fill_defaults(args)
    settings = settings_from(args)      # a bad solver option is refused before the simulation is written
    outdir = Path(args.outdir)
    check_output(outdir / "cube.h5", "demo folder")
    start = time.perf_counter()
    sim = simulate(**simulation_kwargs(args))
    files = write_simulation(outdir, sim)
    print(f"simulated scene {sim.scene!r}, {shape_text(sim.truth.shape)}, in {time.perf_counter() - start:.1f} s")
    args.output, args.png = str(outdir / "cube.h5"), None    # the pictures are drawn below, with the input's
    result = solve(args, sim.calibration, sim.measurement, snapshots=args.report_at, settings=settings)
    result.attrs.update(provenance({name: files[name].resolve() for name in ("measurement", "calibration")}))
    code = write(args, result, sim.truth)
    draw(outdir / "cube", result.cube, result.wavelengths, result.history, sim.truth, None,
         Inputs.of(sim.measurement, str(files["measurement"]), sim.calibration, str(files["calibration"])))
    if code:
        return code
    for iteration, cube in sorted(result.snapshots.items()):
        print_accuracy(cube, sim.truth, f"after {iteration} iterations ({result.history[iteration - 1]['seconds']:.1f} s): ")
    print_accuracy(result.cube, sim.truth, f"final ({result.iterations} iterations): ")
    if sim.scene == "target" and sim.calibration.n_bands > 1:
        print(why_blocky(sim.calibration))
    return 0


def fill_defaults(args):
    """OUTDIR, --size and --iters where not given: OUTDIR, the prototype's sensor and the solver's default, or
    QUICK_OUTDIR and QUICK's."""
    from ..camera.prototype import SENSOR_SHAPE
    from ..solve.settings import DEFAULT_ITERS

    defaults = {"outdir": QUICK_OUTDIR, **QUICK} if args.quick else \
        {"outdir": OUTDIR, "size": SENSOR_SHAPE, "iters": DEFAULT_ITERS}
    for name, value in defaults.items():
        if getattr(args, name) is None:
            setattr(args, name, value)


def why_blocky(calibration) -> str:
    """Why the target's red, green and blue quadrants resolve coarser than its white one: the share of the sensor's
    pixels that each line's band reaches (:func:`passing_share`) and the resolutions of the project's analyses."""
    from ..sim.scenes import RGB_LINES

    lines = ", ".join(f"{nm:.0f}" for nm in RGB_LINES.values())
    shares = ", ".join(f"{100 * passing_share(calibration, nm):.1f} %" for nm in RGB_LINES.values())
    return (f"note: the red, green and blue quadrants look blocky. Light of one narrow band reaches only the filters "
            f"that pass\n  it (at {lines} nm: {shares} of the pixels; white light: all of them), so fine narrow-band "
            f"detail is seen\n  by few pixels: resolution depends on the scene's complexity (the paper). The project's "
            f"analyses: the PSF\n  resolves {PSF_RESOLUTION} (clsdcam analyze resolution), two narrow-band points "
            f"{TWO_POINT} apart (clsdcam analyze twopoint);\n  a pattern as dense as the bars, in one narrow band, "
            f"resolves coarser.")


def passing_share(calibration, nm: float) -> float:
    """The fraction of pixels whose filter passes the band nearest ``nm``: F_k(y, x) ≥ HALF_PEAK · max F_k."""
    import numpy as np

    band = calibration.filters[int(np.argmin(np.abs(calibration.wavelengths - nm)))]
    return float(np.mean(band >= HALF_PEAK * band.max()))
