"""``clsdcam devices``: the OpenCL platforms and devices."""
from __future__ import annotations


def add_parser(subparsers):
    subparsers.add_parser("devices", help="list OpenCL platforms and devices (memory, compute units, fp64)")


def run(args) -> int:
    from ..backends.cl_devices import format_devices

    print(format_devices())
    return 0
