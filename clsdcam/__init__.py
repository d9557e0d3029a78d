"""clsdcam: Spectral DiffuserCam hyperspectral reconstruction on NumPy or any OpenCL device.

    import clsdcam
    result = clsdcam.reconstruct("measurement.png", "calibration.mat", iters=300)
    result.cube, result.wavelengths, result.save("cube.h5")

Nothing heavy is imported here: the names below load their modules on first use.
"""
__version__ = "0.2.0"

_LAZY = {
    "Calibration": "clsdcam.camera.calibration",
    "Preprocessing": "clsdcam.camera.calibration",
    "prepare": "clsdcam.calibrate.measurement",
    "reconstruct": "clsdcam.solve.solver",
    "Solver": "clsdcam.solve.solver",
    "Settings": "clsdcam.solve.settings",
    "Result": "clsdcam.solve.result",
    "InputError": "clsdcam.errors",
    "load_measurement": "clsdcam.io",
}

__all__ = ["__version__", *_LAZY]


def __dir__():
    """The module's names and the public ones it loads on first use (``dir(clsdcam)``), nothing imported."""
    return sorted(set(globals()) | set(__all__))


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'clsdcam' has no attribute {name!r}")
