"""clsdcam: Spectral DiffuserCam hyperspectral reconstruction on NumPy or any OpenCL device.

    from clsdcam import Calibration, reconstruct
    cal = Calibration.load("calibration.mat")
    result = reconstruct(measurement, cal, backend="opencl", iters=500)

Nothing heavy is imported here: the names below load their modules on first use.
"""
__version__ = "0.2.0"

_LAZY = {
    "Calibration": "clsdcam.calibration",
    "Preprocessing": "clsdcam.calibration",
    "reconstruct": "clsdcam.solver",
    "Solver": "clsdcam.solver",
    "Settings": "clsdcam.settings",
    "Result": "clsdcam.solver",
    "InputError": "clsdcam.errors",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'clsdcam' has no attribute {name!r}")
