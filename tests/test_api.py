"""The public Python API (README, "Python"), and a light import."""
import subprocess
import sys

import numpy as np

import clsdcam


def test_top_level_names_are_the_documented_objects():
    from clsdcam import Calibration, reconstruct

    assert callable(reconstruct) and reconstruct.__module__ == "clsdcam.solver"
    import clsdcam.solver  # noqa: F401  (importing the module must not shadow the function)

    assert clsdcam.reconstruct is reconstruct and Calibration.__name__ == "Calibration"


def test_import_is_light():
    code = "import sys, clsdcam; print(sorted(m for m in ('numpy', 'scipy', 'pyopencl', 'matplotlib', 'h5py') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_reconstruct_result_fields(tmp_path):
    from clsdcam.sim import simulate

    sim = simulate(scene="points", shape=(20, 24), n_bands=3, seed=0)
    result = clsdcam.reconstruct(sim.measurement, sim.calibration, iters=5)
    assert result.cube.shape == (3, 20, 24) and result.cube.dtype == np.float32
    assert result.wavelengths.shape == (3,) and len(result.history) == 5
    assert result.save(tmp_path / "c.h5") is None and (tmp_path / "c.h5").exists()
