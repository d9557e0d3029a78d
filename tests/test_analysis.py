"""The paper's analyses on tiny problems against brute force (explicit A, numpy.linalg.cond,
direct correlation sums, analytic profiles), the lens comparators, and ``analyze`` through a parser."""
import argparse
import json
import re

import numpy as np
import pytest
import scipy.ndimage as ndi
from scipy.signal import correlate2d

from clsdcam import analyses, analysis, sim
from clsdcam.cli import analyze as cli_analyze
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.metrics import psnr
from clsdcam.camera.model import ForwardModel

SHAPE = (9, 12)
RNG = np.random.default_rng(0)


def dense_columns(psf, filters, voxels):
    """Columns of A by applying the forward model (NumPy, float64) to unit voxels on the sensor window."""
    model = ForwardModel(NumpyBackend("float64"), psf, filters)
    out = []
    for k, y, x in voxels:
        cube = np.zeros(filters.shape)
        cube[k, y, x] = 1.0
        out.append(model.forward(model.embed(cube)).ravel())
    return np.stack(out, axis=1)


def aligned_filters(shape):
    """The default 64 filters at 64 bands on a perfectly aligned, unrotated array (exactly block-constant)."""
    wavelengths = sim.band_wavelengths(64)
    return sim.filter_array(shape, wavelengths, 0, misalignment=(0.0, 0.0), rotation_deg=0.0)


# ---- resolution from the PSF ------------------------------------------------------------------
def test_autocorrelation_resolution_of_a_gaussian_psf():
    """A Gaussian of σ has a Gaussian autocorrelation of σ√2: half-width at 70 % = 2σ·√ln(1/0.7)."""
    y, x = np.mgrid[:80, :96]
    sigma = 3.5
    psf = np.exp(-((y - 40) ** 2 + (x - 48) ** 2) / (2 * sigma ** 2))
    result = analysis.autocorrelation_resolution(psf)
    assert result.pixels == pytest.approx(2 * sigma * np.sqrt(np.log(1 / 0.7)), rel=0.01)
    assert result.superpixels == pytest.approx(result.pixels / 16)


def test_autocorrelation_is_the_direct_correlation_sum():
    """(h ⋆ h)(Δ) = Σ_p h(p) h(p + Δ) by brute force (scipy's direct correlate2d), peak 1 at [H, W]."""
    psf = RNG.random((7, 10))
    direct = correlate2d(psf, psf, mode="full")
    corr = sim.autocorrelation(psf)
    np.testing.assert_allclose(corr[1:, 1:], direct / direct.max(), atol=1e-12)
    assert corr[7, 10] == pytest.approx(1.0)
    np.testing.assert_allclose(corr[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(corr[:, 0], 0.0, atol=1e-12)


def test_measured_psf_subtracts_the_dark_ring_and_bins_to_the_prototype_scale():
    assert [analysis.binning_factor(s) for s in ((1200, 1600), (550, 570), (320, 448), (100, 100))] == [4, 2, 1, 1]
    raw = np.full((640, 881), 100.0)  # 881 px: binned by 2, the last column dropped
    raw[300:304, 400:406] = 500.0
    psf, factor = analysis.measured_psf(raw)
    expected = np.zeros((320, 440))
    expected[150:152, 200:203] = 400.0
    assert factor == 2
    np.testing.assert_allclose(psf, expected)


# ---- local condition numbers -------------------------------------------------------------------
def test_columns_equal_the_forward_model_applied_to_unit_voxels():
    psf, filters = RNG.random(SHAPE), RNG.random((3,) + SHAPE)
    voxels = [(0, 0, 0), (1, 4, 6), (2, 8, 11), (1, 2, 9), (0, 7, 1)]
    np.testing.assert_allclose(analysis.columns(psf, filters, voxels), dense_columns(psf, filters, voxels),
                               rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("spectral", [False, True])
def test_group_condition_matches_numpy_cond_of_the_explicit_submatrix(spectral):
    psf, filters = RNG.random(SHAPE), RNG.random((3,) + SHAPE)
    voxels = [(k, y, x) for k in ((1, 2) if spectral else (1,)) for y, x in [(2, 3), (2, 6), (5, 3), (5, 6)]]
    expected = np.linalg.cond(dense_columns(psf, filters, voxels))
    assert analysis.group_condition(psf, filters, 4, 3, 1, (2, 3), spectral) == pytest.approx(expected, rel=1e-8)


def test_condition_sweep_is_the_geometric_mean_over_placements_of_brute_force_conditions():
    shape, separations, trials = (16, 20), (1, 2, 4), 3
    psf, filters = sim.caustic_psf(shape, 1), RNG.random((4,) + shape)
    places = analysis.placements(np.random.default_rng(5), filters.shape, 4 * 2, True, trials)
    expected = [np.exp(np.mean([np.log(np.linalg.cond(dense_columns(psf, filters, analysis.group_voxels(
        9, d, band, origin, True)))) for band, origin in places])) for d in separations]
    got = analysis.condition_sweep(psf, filters, separations, n=9, spectral=True, trials=trials, seed=5)
    np.testing.assert_allclose(got, expected, rtol=1e-6)


def test_singular_groups_are_capped_and_rank_deficient_ones_flagged():
    assert analysis.local_condition(np.ones((5, 2))) == analysis.SINGULAR
    assert analysis.local_condition(np.eye(6)[:, :3] + np.eye(6)[:, 3:]) == pytest.approx(1.0)
    tall_zero_rows = np.zeros((50, 3))
    tall_zero_rows[:2] = RNG.random((2, 3))
    assert analysis.local_condition(tall_zero_rows) == analysis.SINGULAR


def test_separation_below_needs_every_larger_separation_below_the_limit():
    assert analysis.separation_below([1, 2, 3, 4], [100, 30, 50, 20]) == 4
    assert analysis.separation_below([1, 2, 3], [10, 20, 30]) == 1
    assert analysis.separation_below([1, 2], [100, np.inf]) is None


def test_high_na_lens_lights_one_filter_pixel_and_low_na_lens_one_superpixel():
    shape = (64, 80)
    filters = aligned_filters(shape)
    high, low = sim.lens_psf(shape, 2), sim.lens_psf(shape, 16)
    assert np.linalg.norm(high) == pytest.approx(1) and np.linalg.norm(low) == pytest.approx(1)
    assert sorted(zip(*np.nonzero(high))) == [(32, 40), (32, 41), (33, 40), (33, 41)]
    for y, x in [(10, 20), (34, 52)]:  # a point on a filter pixel's corner: its 2×2 area, one filter
        lit = np.nonzero(analysis.point_image(high, y, x))
        assert sorted(zip(*lit)) == [(y, x), (y, x + 1), (y + 1, x), (y + 1, x + 1)]
        assert len(np.unique(filters[:, lit[0], lit[1]], axis=1).T) == 1
    for y, x in [(20, 30), (37, 45)]:  # any point: a 16×16 area, i.e. every one of the 64 filters 4 times
        lit = np.nonzero(analysis.point_image(low, y, x))
        responses, counts = np.unique(filters[:, lit[0], lit[1]], axis=1, return_counts=True)
        assert len(lit[0]) == 256 and responses.shape[1] == 64 and set(counts) == {4}
    assert set(sim.DESIGNS) == {"diffuser", "low-NA lens", "high-NA lens"}


def test_diffuser_is_better_conditioned_than_a_low_na_lens():
    shape = (64, 80)
    filters = sim.filter_array(shape, sim.band_wavelengths(16), 0)
    seps = (1, 2, 3)
    diffuser = analysis.condition_sweep(sim.caustic_psf(shape, 0), filters, seps, n=9, trials=3)
    lens = analysis.condition_sweep(sim.lens_psf(shape, 16), filters, seps, n=9, trials=3)
    assert np.all(diffuser < lens)


# ---- reconstruction analyses (the solver replaced by a known "reconstruction") ----------------------
def test_peak_wavelength_is_exact_for_a_sampled_gaussian():
    wavelengths = sim.band_wavelengths(64)
    for centre in (391.0, 517.3, 650.0, 893.0):
        spectrum = np.exp(-(wavelengths - centre) ** 2 / (2 * 6.0 ** 2))
        assert analysis.peak_wavelength(spectrum, wavelengths) == pytest.approx(centre, abs=1e-6)
    assert analysis.peak_wavelength([0.0, 1.0, 1.0, 0.0], [400, 410, 420, 430]) == pytest.approx(415.0)


def test_spectral_accuracy_with_a_perfect_reconstruction(monkeypatch):
    """With A⁻¹ exact the error is the band averaging's and the interpolation's only: < 0.5 nm at 8 nm bands."""
    monkeypatch.setattr(analysis, "simulate_and_reconstruct", lambda truth, *args: truth)
    result = analysis.spectral_accuracy((24, 32), 64, n_sources=9, iters=1)
    assert result["true_nm"][0] == pytest.approx(390.0) and result["true_nm"][-1] == pytest.approx(894.0)
    assert result["worst_abs_error_nm"] < 0.5
    assert len({tuple(p) for p in result["positions"]}) == 9


def test_dip_ratio_by_hand():
    assert analysis.dip_ratio([0, 1, 0.5, 0.8, 0], 1, 3) == pytest.approx(0.5 / 0.8)
    assert analysis.dip_ratio([0, 1, 0.9, 0], 1, 2) == 1.0
    assert analysis.dip_ratio([0.2, 1, 0.1, 0.3, 2, 0.5], 1, 4) == pytest.approx(0.1 / 1)


def test_two_point_resolution_of_a_gaussian_blur(monkeypatch):
    """The "reconstruction" blurs x by a sampled Gaussian g of σ = 1.2 px: for even d the dip of
    g(x) + g(x − d) at d/2 over the peak at 0 is 2g(d/2) / (1 + g(d)); resolved from d = 4 px
    (0.50; at 3 px the dip is (g(1) + g(2)) / (1 + g(3)) = 0.92)."""
    sigma = 1.2
    monkeypatch.setattr(analysis, "simulate_and_reconstruct",
                        lambda truth, *args: ndi.gaussian_filter1d(truth, sigma, axis=2, mode="constant", truncate=8))
    result = analysis.two_point_resolution((48, 64), 8, separations=(2, 3, 4, 5, 6), iters=1)

    def g(x):
        return np.exp(-x ** 2 / (2 * sigma ** 2))

    for line in ("618", "522", "466"):
        assert result[line]["resolved_px"] == 4
        for d, ratio in zip((2, 4, 6), result[line]["dip_ratio"][::2]):
            assert ratio == pytest.approx(2 * g(d / 2) / (1 + g(d)), rel=1e-6)


def test_design_comparison_on_a_tiny_camera():
    rows = analysis.design_comparison((24, 32), 4, iters=5)
    assert list(rows) == ["diffuser", "low-NA lens", "high-NA lens"]
    for row in rows.values():
        assert row["cube"].shape == row["truth"].shape == (4, 24, 32)
        assert row["psnr"] == pytest.approx(psnr(row["cube"], row["truth"]))


# ---- the command line ---------------------------------------------------------------------------
def parser():
    top = argparse.ArgumentParser(prog="clsdcam")
    cli_analyze.add_parser(top.add_subparsers(dest="command"))
    return top


def printed_figures(text: str, name: str) -> dict[str, str]:
    """The key figures ``analyze`` printed under analysis ``name`` (its lines ``  quantity: value``), by quantity."""
    block = re.search(rf"^{name}: .*\n((?:  .*\n)*)", text, re.M)[1]
    return dict(line[2:].split(": ", 1) for line in block.splitlines())


def numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", text)]


def check_printed_figures(text: str, out):
    """Each analysis' printed figures are its JSON's, as rounded when printed."""
    res, cond, spec, two, des = (json.loads((out / f"{n}.json").read_text())
                                 for n in ("resolution", "condition", "spectral", "twopoint", "designs"))
    caustic = res["psfs"]["simulated caustic"]
    assert numbers(printed_figures(text, "resolution")["autocorrelation resolution, simulated caustic"])[:2] == \
        [round(caustic["pixels"], 2), round(caustic["superpixels"], 2)]
    figures = printed_figures(text, "condition")
    assert len(figures) == 6
    for design in ("diffuser", "low-NA lens", "high-NA lens"):
        for mode in ("2-D", "3-D"):
            listed = re.search(r"\[px: (.*)\]", figures[f"separation at κ = 40, {design}, {mode}, 16 points"])[1]
            at = {n: cond["groups"][f"{design}|{mode}|{n}"]["separation_at_limit_px"] for n in cond["group_sizes"]}
            assert listed == ", ".join(f"n={n}: {'never' if d is None else d}" for n, d in at.items())
    median_worst = numbers(printed_figures(text, "spectral")["peak-wavelength error, median / worst"])[:3]
    assert median_worst == [round(spec["median_abs_error_nm"], 1), round(spec["worst_abs_error_nm"], 1),
                            len(spec["true_nm"])]
    for line, value in zip(analysis.TWO_POINT_WAVELENGTHS, printed_figures(text, "twopoint").values()):
        d = two[f"{line:g}"]["resolved_px"]
        assert value == (f"not within {two['separations_px'][-1]} px" if d is None else f"{d} px")
    for name, value in printed_figures(text, "designs").items():
        r = des["designs"][name.removeprefix("target reconstruction, ")]
        assert numbers(value) == [round(r["psnr"], 2), round(r["angle"], 1)]


def test_analyze_all_through_a_parser(tmp_path, capsys, monkeypatch):
    """Everything on tiny sizes; the measured PSFs are made absent, so they are skipped cleanly. Each analysis
    prints its key figures, the JSON's."""
    monkeypatch.setenv("CLSDCAM_DATA", str(tmp_path / "no-data"))
    out = tmp_path / "an"
    args = parser().parse_args(["analyze", "all", str(out), "--size", "32x40", "--recon-size", "24x32",
                                "--bands", "8", "--iters", "5", "--trials", "1"])
    assert cli_analyze.run(args) == 0
    table = capsys.readouterr().out
    assert "| autocorrelation resolution, simulated caustic |" in table and "within 5 nm" in table
    assert "skipped: psf/spectraldiffuserscope_psf.npy not present" in table
    check_printed_figures(table, out)
    assert cli_analyze.ANALYSES == analyses.ANALYSES
    for name in cli_analyze.ANALYSES:
        assert (out / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
        assert json.loads((out / f"{name}.json").read_text())["seconds"] >= 0
    condition = json.loads((out / "condition.json").read_text())
    assert condition["shape"] == [32, 40] and condition["separations_px"] == [1, 2, 3, 4, 5]
    assert "<table" in (out / "report.html").read_text() and (out / "summary.md").read_text().startswith("| quantity")
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_each_analysis_is_a_sub_choice_with_its_own_options(tmp_path, capsys):
    args = parser().parse_args(["analyze", "resolution", str(tmp_path), "--size", "40x48"])
    assert (args.what, args.size) == ("resolution", (40, 48)) and not hasattr(args, "recon_size")
    assert cli_analyze.run(args) == 0
    result = json.loads((tmp_path / "resolution.json").read_text())["psfs"]
    printed = printed_figures(capsys.readouterr().out, "resolution")
    assert list(printed) == [f"autocorrelation resolution, {label}" + (f", binned {r['binning']}×" if
                                                                      r.get("binning", 1) > 1 else "")
                             for label, r in result.items()]
    for r, value in zip(result.values(), printed.values()):
        if "skipped" in r:
            assert value == f"skipped: {r['skipped']}"
        else:
            assert numbers(value)[:2] == [round(r["pixels"], 2), round(r["superpixels"], 2)]
    assert 2.0 <= result["simulated caustic"]["pixels"] <= 4.5
    tutorial = result["DiffuserCam tutorial (measured)"]
    if "skipped" not in tutorial:  # the real 1200×1600 frame, binned 4× to 300×400
        assert tutorial["binning"] == 4 and tutorial["shape"] == [300, 400] and 1.0 < tutorial["pixels"] < 6.0
    assert not (tmp_path / "condition.json").exists()
    with pytest.raises(SystemExit):
        parser().parse_args(["analyze", "condition", str(tmp_path), "--size", "4x4"])
    with pytest.raises(SystemExit):
        parser().parse_args(["analyze", "everything", str(tmp_path)])
