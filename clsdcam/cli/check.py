"""``clsdcam check``: one OpenCL device checked against NumPy and timed (:mod:`clsdcam.devcheck`)."""
from __future__ import annotations

import sys
from pathlib import Path

from .options import examples


def add_parser(subparsers):
    p = subparsers.add_parser(
        "check", help="check an OpenCL device: limits, memory plan, every primitive and a reconstruction against "
                      "NumPy, FFT engines' speed, kernels' GB/s (exit 1 when a check fails)",
        description="Check one OpenCL device before trusting it with a reconstruction: its limits and the memory a "
                    "full-size solve plans, every primitive and a short reconstruction against NumPy (the "
                    "reference), the FFT engines' speed and the kernels' memory bandwidth, one row each. Exit 0 "
                    "when every check passes, 1 when one fails.",
        epilog=examples("clsdcam check", "clsdcam check --device Intel --json intel.json",
                        "PYOPENCL_CTX=1 clsdcam check --json check.json"))
    p.add_argument("--device", default=None,
                   help="OpenCL device: substring of platform or device name (default: PYOPENCL_CTX, else a GPU, else a CPU)")
    p.add_argument("--json", type=Path, default=None, metavar="PATH", help="also write every row here")


def run(args) -> int:
    import json

    from ..devcheck import as_json, check, passed, table
    from ..io import atomic_output, check_output

    if args.json:
        check_output(args.json, "--json")
    rows = check(args.device, progress=lambda section: print(f"checking {section} …", file=sys.stderr, flush=True))
    print(table(rows))
    if args.json:
        with atomic_output(args.json) as tmp:
            tmp.write_text(json.dumps(as_json(rows), indent=2) + "\n")
    return 0 if passed(rows) else 1
