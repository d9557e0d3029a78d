"""One solve (clsdcam.solve.reconstruction, clsdcam.solve.units): every figure that leaves a solve is in one set of
units, the
per-solve state stays on the solve, and the Solver keeps only what serves all of its solves."""
from dataclasses import replace

import numpy as np
import pytest

from clsdcam import prepare
from clsdcam.sim import simulate
from clsdcam.solve.solver import Settings, Solver
from clsdcam.solve.units import Units


@pytest.fixture(scope="module")
def unnormalised():
    """A 48×64×8 camera whose PSF (×3.7) and filters (×0.4) are not normalised, prepared as the API does: the
    calibration's scale is then not 1."""
    sim = simulate(scene="leds", shape=(48, 64), n_bands=8, seed=3)
    raw = replace(sim.calibration, psf=3.7 * sim.calibration.psf, filters=0.4 * sim.calibration.filters)
    calibration, measurement = prepare(sim.measurement, raw)
    assert abs(calibration.scale - 1.0) > 0.1
    return calibration, measurement


@pytest.mark.parametrize("algorithm", ["fista", "admm"])
def test_the_last_snapshot_is_the_cube_on_a_calibration_that_was_normalised(unnormalised, algorithm):
    calibration, measurement = unnormalised
    result = Solver(calibration, settings=Settings(iters=12, algorithm=algorithm)).solve(measurement,
                                                                                        snapshots=[6, 12])
    assert np.array_equal(result.snapshots[12], result.cube)
    assert not np.array_equal(result.snapshots[6], result.cube)


def test_progress_and_history_are_in_the_measurements_units(unnormalised):
    """The progress callback's records equal the history's: the data term and objective in data units, ×s²."""
    calibration, measurement = unnormalised
    seen = []
    result = Solver(calibration, settings=Settings(iters=5)).solve(2.0 * measurement, progress=seen.append)
    assert [r["data"] for r in seen] == [r["data"] for r in result.history]
    unscaled = Solver(calibration, settings=Settings(iters=5)).solve(measurement)
    assert result.history[-1]["data"] == pytest.approx(4.0 * unscaled.history[-1]["data"], rel=1e-4)


def test_a_warm_start_and_a_carried_state_come_back_in_the_calibrations_units(unnormalised):
    """A full field handed back as x0 starts where the solve ended (its first data term at most the last one's), and the
    state's field is the result's full field in the calibration's units."""
    calibration, measurement = unnormalised
    solver = Solver(calibration, settings=Settings(iters=20, full_field=True))
    first = solver.solve(measurement)
    np.testing.assert_allclose(solver.backend.to_host(first.state.field), first.full_field, rtol=1e-6,
                               atol=1e-6 * np.abs(first.full_field).max())
    again = solver.solve(measurement, x0=first.full_field)
    assert again.history[0]["data"] <= 1.05 * first.history[-1]["data"]


def test_the_solver_keeps_no_measurement():
    """Per-solve state lives on the solve: after a solve the Solver holds no b, no scale and no history."""
    sim = simulate(scene="leds", shape=(32, 48), n_bands=4, seed=1)
    solver = Solver(sim.calibration, settings=Settings(iters=3))
    before = set(vars(solver))
    solver.solve(sim.measurement)
    assert set(vars(solver)) == before and not {"b", "scale", "history"} & before


def test_units_convert_both_ways():
    units = Units(measurement=8.0, calibration=2.0)
    x = np.array([1.0, 3.0])
    assert units.cube_factor == 4.0 and units.solver_factor == 0.25
    np.testing.assert_array_equal(units.cube(units.to_solver(x)), x.astype(np.float32))
    assert units.record({"data": 1.0, "objective": 2.0}) == {"data": 64.0, "objective": 128.0}
