"""``clsdcam devices``: the OpenCL platforms and devices."""
from __future__ import annotations

from .options import examples


def add_parser(subparsers):
    subparsers.add_parser("devices", help="list OpenCL platforms and devices (memory, compute units, fp64)",
                          epilog=examples("clsdcam devices", "PYOPENCL_CTX=0 clsdcam devices"))


def run(args) -> int:
    from ..backends.cl_devices import format_devices

    print(format_devices())
    return 0
