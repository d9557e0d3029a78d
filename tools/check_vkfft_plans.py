#!/usr/bin/env python3
"""How often a fresh VkFFT plan transforms wrong, per shape, on the device clsdcam picks (PYOPENCL_CTX).

    eval "$(python -m clsdcam.backends.cl_icd /tmp/clsdcam-vendors)"
    PYOPENCL_CTX='Intel(R) OpenCL' python tools/check_vkfft_plans.py --plans 15

For each (K, H, W) shape it builds ``--plans`` fresh pyvkfft R2C plans (out of place, as clsdcam's ``vkfft``
engine does, but without its routing of planes with a prime factor above 7 to reikna) and counts those whose
forward transform of a random cube is off numpy's rfft2 by more than WRONG (relative): a wrong plan is off by
order 1, a right one by float32 rounding. Prints a Markdown table: shape, whether VkFFT chose Bluestein's
algorithm for an axis, wrong plans. Evidence for the routing in ``clsdcam/backends/fft.py`` (a plan is wrong
for its whole life, so one check per plan suffices), and the check to rerun when pyvkfft changes.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

WRONG = 1e-3
SHAPES = "2x21x35,2x21x63,2x21x31,2x21x41,2x21x43,2x21x47,2x21x62,2x43x32"


def wrong_plans(queue, shape: tuple, plans: int, seed: int = 3) -> tuple[int, list]:
    """(plans off numpy by more than WRONG, VkFFT's Bluestein flags, fastest axis first) for ``plans`` fresh plans."""
    import pyopencl.array as cla
    from pyvkfft.opencl import VkFFTApp

    x = np.random.default_rng(seed).standard_normal(shape).astype(np.float32)
    reference = np.fft.rfft2(x)
    wrong, bluestein = 0, []
    for _ in range(plans):
        app = VkFFTApp(shape, np.float32, queue=queue, ndim=2, r2c=True, inplace=False, norm=1)
        out = cla.empty(queue, shape[:-1] + (shape[-1] // 2 + 1,), np.complex64)
        app.fft(cla.to_device(queue, x), out)
        wrong += np.linalg.norm(out.get().astype(np.complex128) - reference) > WRONG * np.linalg.norm(reference)
        bluestein = [bool(flag) for flag in (app.use_bluestein_fft or [])][:2]
    return int(wrong), bluestein


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", default=SHAPES, help="K x H x W, comma-separated")
    parser.add_argument("--plans", type=int, default=15, help="fresh plans per shape")
    args = parser.parse_args(argv)
    import pyopencl as cl

    from clsdcam.backends import cl_devices

    device = cl_devices.choose_device()
    context = cl.Context([device])
    queue = cl.CommandQueue(context)
    print(f"{device.platform.name.strip()}: {device.name.strip()}, {args.plans} fresh plans per shape\n")
    print("| shape | Bluestein (W, H axes) | wrong plans |\n|---|---|---:|")
    for text in args.shapes.split(","):
        shape = tuple(int(v) for v in text.split("x"))
        wrong, bluestein = wrong_plans(queue, shape, args.plans)
        print(f"| {text} | {', '.join('yes' if b else 'no' for b in bluestein)} | {wrong} of {args.plans} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
