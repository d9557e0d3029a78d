"""The public Python API (README, "Python"), and a light import."""
import subprocess
import sys

import numpy as np

import clsdcam


def test_top_level_names_are_the_documented_objects():
    from clsdcam import Calibration, reconstruct

    assert callable(reconstruct) and reconstruct.__module__ == "clsdcam.solve.solver"
    import clsdcam.solve.solver  # noqa: F401  (importing the module must not shadow the function)

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


def test_paths_and_the_cli_give_the_same_cube_in_the_truths_units(tmp_path):
    """reconstruct() takes file paths and preprocesses as the command line does; normalising the PSF and the
    filters conditions the solve without changing units: the cube comes back in the truth's units."""
    import h5py

    from clsdcam.cli import main
    from clsdcam.metrics import psnr

    assert main(["simulate", str(tmp_path), "--size", "32x40", "--bands", "4", "--scene", "leds", "--seed", "3"]) == 0
    measurement, calibration = tmp_path / "measurement.npy", tmp_path / "calibration.h5"
    api = clsdcam.reconstruct(str(measurement), str(calibration), iters=60)
    assert main(["reconstruct", str(measurement), "--calibration", str(calibration), "-o", str(tmp_path / "c.h5"),
                 "--iters", "60", "--quiet"]) == 0
    assert main(["reconstruct", str(measurement), "--calibration", str(calibration), "-o", str(tmp_path / "raw.h5"),
                 "--iters", "60", "--quiet", "--no-normalize-psf", "--no-normalize-filters"]) == 0
    with h5py.File(tmp_path / "c.h5", "r") as f, h5py.File(tmp_path / "raw.h5", "r") as g:
        cli, unnormalised = f["cube"][...], g["cube"][...]
    np.testing.assert_allclose(api.cube, cli, rtol=1e-5, atol=1e-6 * cli.max())
    assert api.attrs["calibration_scale"] != 1.0                 # the filters' max is 0.95 here, not 1
    np.testing.assert_allclose(cli, unnormalised, rtol=0, atol=2e-3 * cli.max())   # the same units either way
    with h5py.File(tmp_path / "truth.h5", "r") as t:
        assert psnr(cli, t["cube"][...]) > psnr(np.zeros_like(cli), t["cube"][...]) + 1


def test_load_measurement_is_public(tmp_path):
    np.save(tmp_path / "m.npy", np.ones((4, 5)))
    assert clsdcam.load_measurement(tmp_path / "m.npy").shape == (4, 5)
