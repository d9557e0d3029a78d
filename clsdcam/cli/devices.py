"""``clsdcam devices``: the OpenCL platforms and devices, and what ``--backend auto`` chooses among them."""
from __future__ import annotations

from argparse import Namespace

from .options import examples


def add_parser(subparsers):
    subparsers.add_parser("devices", help="list OpenCL platforms and devices (memory, compute units, fp64) and the "
                                          "backend --backend auto (the default) chooses",
                          description="List the OpenCL platforms and their devices (memory, compute units, fp64), "
                                      "then the backend that --backend auto, the default of reconstruct, batch and "
                                      "demo, chooses among them and why. Without pyopencl or a device: numpy.",
                          epilog=examples("clsdcam devices", "PYOPENCL_CTX=0 clsdcam devices"))


def run(args) -> int:
    """The table, or the one line that says why there is none (no pyopencl, no driver: the core install without
    an extra), then the backend ``auto`` chooses: numpy when nothing is found, which is an answer, not an error."""
    from ..backends import format_devices
    from ..errors import InputError
    from .solve import chosen_backend

    try:
        print(format_devices())
    except InputError as nothing:
        print(nothing)
    chosen_backend(Namespace(backend="auto", device=None))
    return 0
