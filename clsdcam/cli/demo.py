"""``clsdcam demo [OUTDIR]``: simulate the default scene, reconstruct it, report accuracy and time."""
from __future__ import annotations

import time
from pathlib import Path

from ..errors import shape_text
from .options import add_simulation_options, add_solver_options, examples, iterations
from .simulate import simulation_kwargs
from .solve import print_accuracy, solve, write


def add_parser(subparsers):
    p = subparsers.add_parser("demo", help="simulate the default scene, reconstruct it, report accuracy and time",
                              epilog=examples("clsdcam demo", "clsdcam demo out/ --iters 500 --report-at 100,300",
                                              "clsdcam demo small/ --size 64x96 --bands 16 --backend opencl"))
    p.add_argument("outdir", nargs="?", default="clsdcam-demo")
    p.add_argument("--report-at", type=iterations, default=(), metavar="N,N,...",
                   help="also print the accuracy after these iterations, e.g. 100,500")
    add_simulation_options(p)
    add_solver_options(p)


def run(args) -> int:
    from ..io import check_output
    from ..sim import simulate, write_simulation

    check_output(Path(args.outdir) / "cube.h5", "demo folder")
    start = time.perf_counter()
    sim = simulate(**simulation_kwargs(args))
    write_simulation(args.outdir, sim)
    print(f"simulated scene {sim.scene!r}, {shape_text(sim.truth.shape)}, in {time.perf_counter() - start:.1f} s")
    args.output = str(Path(args.outdir) / "cube.h5")
    args.png = str(Path(args.outdir) / "cube")
    result = solve(args, sim.calibration, sim.measurement, snapshots=args.report_at)
    code = write(args, result, sim.truth)
    if code:
        return code
    for iteration, cube in sorted(result.snapshots.items()):
        print_accuracy(cube, sim.truth, f"after {iteration} iterations ({result.history[iteration - 1]['seconds']:.1f} s): ")
    print_accuracy(result.cube, sim.truth, f"final ({result.iterations} iterations): ")
    return 0
