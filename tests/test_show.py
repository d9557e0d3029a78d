"""The first pictures: the demo's spectra (one per lit region of the target), ``show --points``, ``show --frame`` on
batch outputs and video truths, the input picture (raw frame, PSF, filter layout), and the convergence plot's
curves (same units, each where it was evaluated)."""
import re

import h5py
import numpy as np
import pytest

from clsdcam.cli import main
from clsdcam.io import write_cube
from clsdcam.picks import spectrum_points
from clsdcam.render import convergence_figure
from clsdcam.sim.scenes import in_window, inner_shape, make_scene, quadrant_masks
from clsdcam.sim.spectra import band_wavelengths


def printed_points(text: str) -> list[tuple[int, int]]:
    """The (y, x) pixels of the "spectra at: 1 (y=…, x=…); …" line."""
    line = next(line for line in text.splitlines() if line.startswith("spectra at:"))
    return [(int(y), int(x)) for y, x in re.findall(r"\(y=(\d+), x=(\d+)\)", line)]


def quadrant_of(shape, point) -> int | None:
    """Which of the target's quadrants (0 TL red, 1 TR green, 2 BL blue, 3 BR white) lights ``point``."""
    masks = in_window(shape, quadrant_masks(inner_shape(shape)))
    lit = np.flatnonzero(masks[:, point[0], point[1]])
    return int(lit[0]) if lit.size else None


# ---- which spectra are drawn ----------------------------------------------------------------------------
@pytest.mark.parametrize("shape, bands", [((32, 40), 16), ((40, 48), 6), ((320, 448), 64)])
def test_spectrum_points_take_one_pixel_of_each_light_of_the_target(shape, bands):
    wavelengths = band_wavelengths(bands)
    points = spectrum_points(make_scene("target", shape, wavelengths), wavelengths)
    # red, green, blue, white: as the README names them
    assert [quadrant_of(shape, p) for p in points] == [0, 1, 2, 3]


@pytest.mark.parametrize("bands", [4, 16, 64])
def test_spectrum_points_number_narrow_lights_reddest_first_then_broad_ones(bands):
    """Narrow lights by the wavelength of their peak, the longest first, then broad ones (white) whatever their peak:
    the light in each of four squares, left to right, is broad (peak mid-range), at the bluest band, at the reddest
    and at a quarter of the range."""
    wavelengths = band_wavelengths(bands)
    lights = [1.0 - 0.5 * np.abs(np.linspace(-1, 1, bands)), *np.eye(bands)[[0, -1, bands // 4]]]
    cube = np.zeros((bands, 12, 40))
    for i, spectrum in enumerate(lights):
        cube[:, 2:10, 10 * i + 2:10 * i + 8] = spectrum[:, None, None]
    assert [x // 10 for _, x in spectrum_points(cube, wavelengths)] == [2, 3, 1, 0]


def test_spectrum_points_of_a_dark_cube_and_a_single_band():
    assert spectrum_points(np.zeros((4, 6, 7))) == []
    grey = np.zeros((1, 9, 9))
    grey[0, 2:7, 2:7] = 1.0
    assert spectrum_points(grey) == [(4, 4)]       # one light, its most central pixel


def test_demo_draws_one_spectrum_per_lit_region_and_its_input(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", str(out), "--size", "32x40", "--bands", "16", "--iters", "5", "--quiet"]) == 0
    printed = capsys.readouterr().out
    points = printed_points(printed)
    assert sorted(quadrant_of((32, 40), p) for p in points) == [0, 1, 2, 3]
    for name in ("falsecolour", "spectra", "convergence", "input"):
        assert (out / f"cube_{name}.png").stat().st_size > 0 and f"cube_{name}.png" in printed
    assert "Light of one narrow band reaches only the filters that pass" in printed


def test_show_finds_the_demos_inputs_from_the_cube(tmp_path, capsys):
    """The demo records its measurement and calibration in the cube; ``show`` finds them where recorded, or by name
    beside the cube once the folder has moved, and says which part it could not find."""
    assert main(["demo", str(tmp_path / "demo"), "--size", "24x32", "--bands", "4", "--iters", "2", "--quiet"]) == 0
    out = (tmp_path / "demo").rename(tmp_path / "moved")
    (out / "cube_input.png").unlink()
    capsys.readouterr()
    assert main(["show", str(out / "cube.h5")]) == 0
    assert (out / "cube_input.png").exists() and "input picture" not in capsys.readouterr().out
    (out / "measurement.npy").rename(out / "elsewhere.npy")         # the calibration alone is still drawn
    assert main(["show", str(out / "cube.h5"), "-o", str(tmp_path / "p")]) == 0
    assert (tmp_path / "p_input.png").exists()
    assert "input picture: no measurement: " in capsys.readouterr().out


def test_show_points_are_the_ones_given(tmp_path, capsys):
    cube = np.random.default_rng(0).random((5, 6, 7), dtype=np.float32)
    path = write_cube(tmp_path / "cube.h5", cube, np.linspace(450, 650, 5))
    assert main(["show", str(path), "--points", "1,2;5,6"]) == 0
    printed = capsys.readouterr().out
    assert printed_points(printed) == [(1, 2), (5, 6)]
    assert "input picture: no measurement: the cube records none; give --measurement" in printed
    assert not (tmp_path / "cube_input.png").exists()


@pytest.mark.parametrize("value, message", [("1,2;3", "y,x pairs"), ("a,b", "y,x pairs"), ("9,0", "outside")])
def test_show_bad_points_exit_2_with_one_line_and_write_nothing(tmp_path, capsys, value, message):
    path = write_cube(tmp_path / "cube.h5", np.ones((3, 6, 7), np.float32), [450.0, 550, 650])
    assert main(["show", str(path), "--points", value]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cube.h5"]


# ---- batch outputs and video truths ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """A simulated 3-frame video and its batch output (``cubes.h5``)."""
    folder = tmp_path_factory.mktemp("video")
    assert main(["simulate", str(folder), "--size", "24x32", "--bands", "4", "--frames", "3"]) == 0
    assert main(["batch", str(folder / "frames.npy"), "--calibration", str(folder / "calibration.h5"),
                 "-o", str(folder / "cubes.h5"), "--workers", "0", "--iters", "3", "--quiet"]) == 0
    return folder


def test_show_reads_a_frame_of_a_video_truth(video, tmp_path, capsys):
    assert main(["show", str(video / "truth.h5"), "--frame", "2", "-o", str(tmp_path / "t")]) == 0
    with h5py.File(video / "truth.h5") as f:
        truth = f["cubes"][2]
    assert (tmp_path / "t_spectra.png").exists()
    assert printed_points(capsys.readouterr().out) == spectrum_points(truth, band_wavelengths(4))


def test_show_of_a_video_truth_names_the_frames_and_calibration_beside_it(video, tmp_path, capsys):
    """A simulator's truth records no inputs: the note names the files beside it, and given, they are drawn."""
    assert main(["show", str(video / "truth.h5"), "--frame", "1", "-o", str(tmp_path / "t")]) == 0
    printed = capsys.readouterr().out
    assert (f"no measurement: the cube records none; give --measurement {video / 'frames.npy'}, beside it "
            "(the simulated video: --frame N draws its frame N)") in printed
    assert f"no calibration: the cube records none; give --calibration {video / 'calibration.h5'}" in printed
    assert main(["show", str(video / "truth.h5"), "--frame", "1", "--measurement", str(video / "frames.npy"),
                 "--calibration", str(video / "calibration.h5"), "-o", str(tmp_path / "t")]) == 0
    assert "input picture" not in capsys.readouterr().out and (tmp_path / "t_input.png").exists()


def test_show_reads_a_batch_frame_beside_its_truth_and_input(video, tmp_path, capsys):
    assert main(["show", str(video / "cubes.h5"), "--frame", "1", "--truth", str(video / "truth.h5"),
                 "-o", str(tmp_path / "b")]) == 0
    printed = capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        f"b_{n}.png" for n in ("falsecolour", "projections", "spectra", "input"))
    with h5py.File(video / "truth.h5") as f:
        assert printed_points(printed) == spectrum_points(f["cubes"][1], band_wavelengths(4))


def test_show_frame_out_of_range_exits_2(video, tmp_path, capsys):
    assert main(["show", str(video / "cubes.h5"), "--frame", "3", "-o", str(tmp_path / "b")]) == 2
    assert "no frame 3" in capsys.readouterr().err and not any(tmp_path.iterdir())


@pytest.mark.parametrize("option, message", [("--measurement", "frames not found"),
                                             ("--calibration", "no such file")])
def test_show_given_inputs_that_cannot_be_read_exit_2(video, tmp_path, capsys, option, message):
    assert main(["show", str(video / "cubes.h5"), option, str(tmp_path / "none.npy"), "-o", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and not any(tmp_path.iterdir())


def test_save_pictures_draws_the_spectra_of_each_light_by_default(monkeypatch, tmp_path):
    """``reconstruct --png`` draws with save_pictures' default points: those of the truth's lights."""
    import clsdcam.render as render

    drawn = []
    monkeypatch.setattr(render, "spectra_figure", lambda *args: drawn.append(args[3]) or render.new_figure())
    wavelengths = band_wavelengths(16)
    truth = make_scene("target", (32, 40), wavelengths)
    render.save_pictures(tmp_path / "p", truth * 0.5, wavelengths, truth=truth)
    assert sorted(quadrant_of((32, 40), p) for p in drawn[0]) == [0, 1, 2, 3]


# ---- the convergence plot --------------------------------------------------------------------------------
def test_convergence_plot_draws_each_curve_where_it_was_evaluated():
    """The data term of step k is f(y) at the point step k starts from (for k = 1 the start): drawn at k − 1, so
    that it does not sit above the objective F(x) after the step; both in the measurement's units squared."""
    history = [{"iteration": k, "data": 100.0 / k, "objective": 90.0 / k if k % 5 == 1 else np.nan,
                "seconds": 0.1 * k} for k in range(1, 12)]
    ax = convergence_figure(history).axes[0]
    lines = {line.get_label().split()[0]: line for line in ax.get_lines()}
    assert list(lines["data"].get_xdata()[:2]) == [0, 1] and list(lines["objective"].get_xdata()) == [1, 6, 11]
    assert "units²" in ax.get_ylabel()


# ---- the demo's quick variant ----------------------------------------------------------------------------
@pytest.mark.parametrize("words, size, iters", [([], (320, 448), "auto"), (["--quick"], (160, 224), 100),
                                                (["--quick", "--iters", "7"], (160, 224), 7),
                                                (["--size", "48x64", "--quick"], (48, 64), 100)])
def test_demo_quick_sets_what_is_not_given(words, size, iters):
    from clsdcam.cli.demo import fill_defaults
    from clsdcam.cli.options import build_parser

    args = build_parser().parse_args(["demo", *words])
    fill_defaults(args)
    assert (tuple(args.size), args.iters) == (size, iters)


def test_spectrum_points_of_a_scene_lit_in_fewer_pixels_than_the_percentile():
    cube = np.zeros((3, 100, 100))
    cube[:, 10, 20] = [1.0, 0.0, 0.0]
    cube[:, 70, 80] = [0.0, 0.0, 0.8]
    assert spectrum_points(cube, [650.0, 550.0, 450.0]) == [(10, 20), (70, 80)]


def test_each_spectrum_is_drawn_in_the_colour_of_its_light():
    from clsdcam.render import false_colour, spectra_figure

    wavelengths = band_wavelengths(16)
    truth = make_scene("target", (32, 40), wavelengths)
    points = spectrum_points(truth, wavelengths)                        # red, green, blue, white
    ax = spectra_figure(truth, wavelengths, false_colour(truth, wavelengths), points, truth).axes[1]
    colours = [np.array(line.get_color()) for line in ax.get_lines()[::2]]
    assert [int(np.argmax(c)) for c in colours[:3]] == [0, 1, 2]
    assert np.ptp(colours[3]) == 0                                      # white light: grey
