"""A real camera's frames and honest messages (issue 48): saturated pixels excluded by default and said so, frames
with nothing to reconstruct refused, a short ``--tv auto`` solve that says what it used, errors that name what the
user gave. Everything through ``clsdcam.cli.main`` in-process, at the smallest sizes."""
import re
from pathlib import Path

import numpy as np
import pytest
import tifffile

from clsdcam.cli import main
from conftest import TINY

SIZE = TINY


@pytest.fixture(scope="module")
def sim(tiny_sim) -> Path:
    return tiny_sim


def reconstruct(sim: Path, measurement: Path, *extra: str) -> int:
    return main(["reconstruct", str(measurement), "--calibration", str(sim / "calibration.h5"),
                 "-o", str(measurement.with_suffix(".cube.h5")), "--iters", "3", "--quiet", *extra])


def one_line_error(capsys) -> str:
    """The command's stderr, checked to be one 'clsdcam: error:' line."""
    err = capsys.readouterr().err.strip()
    assert err.startswith("clsdcam: error:") and "\n" not in err, err
    return err


def exposed(sim: Path, tmp_path: Path, gain: float) -> Path:
    """The simulated measurement as a 16-bit TIFF, ``gain`` × full scale at its peak (clipped at 65535)."""
    b = np.load(sim / "measurement.npy")
    path = tmp_path / f"gain{gain:g}.tif"
    tifffile.imwrite(path, np.clip(b / b.max() * 65535 * gain, 0, 65535).astype(np.uint16))
    return path


# ---- saturation ---------------------------------------------------------------------------------------------
def saturation_line(out: str) -> str:
    lines = [line for line in out.splitlines() if line.startswith("saturation:")]
    assert len(lines) == 1, out
    return lines[0]


def test_pixels_at_the_integer_maximum_are_excluded_by_default_and_said(sim, tmp_path, capsys):
    frame = exposed(sim, tmp_path, 3.0)
    fraction = np.mean(tifffile.imread(frame) == 65535)
    assert 0.02 < fraction < 0.5
    assert reconstruct(sim, frame) == 0
    assert saturation_line(capsys.readouterr().out).startswith(f"saturation: {100 * fraction:.2g}% of the pixels")


def test_one_pixel_at_the_integer_maximum_is_saturated(sim, tmp_path, capsys):
    frame = exposed(sim, tmp_path, 1.0)
    assert np.sum(tifffile.imread(frame) == 65535) == 1
    assert reconstruct(sim, frame) == 0
    assert "≥ 65535" in saturation_line(capsys.readouterr().out)


def test_a_flat_plateau_at_the_maximum_of_a_float_frame_is_saturated(sim, tmp_path, capsys):
    b = np.load(sim / "measurement.npy")
    clipped = tmp_path / "clipped.npy"
    np.save(clipped, np.minimum(b, np.quantile(b, 0.9)))
    assert reconstruct(sim, clipped) == 0
    assert saturation_line(capsys.readouterr().out).startswith("saturation: 10% of the pixels")


def test_an_unclipped_frame_says_nothing_and_saturation_none_keeps_the_pixels(sim, tmp_path, capsys):
    assert reconstruct(sim, sim / "measurement.npy") == 0
    assert "saturation:" not in capsys.readouterr().out
    assert reconstruct(sim, exposed(sim, tmp_path, 3.0), "--saturation", "none") == 0
    assert "saturation:" not in capsys.readouterr().out


def test_a_frame_more_than_half_saturated_is_refused(sim, tmp_path, capsys):
    frame = exposed(sim, tmp_path, 400.0)
    assert np.mean(tifffile.imread(frame) == 65535) > 0.5
    assert reconstruct(sim, frame) == 2
    assert f"measurement {frame}: " in one_line_error(capsys) and not frame.with_suffix(".cube.h5").exists()


# ---- frames with nothing to reconstruct ---------------------------------------------------------------------
@pytest.mark.parametrize("value, says", [(0.0, "every pixel is 0 (an all-zero frame)"),
                                         (3.0, "every pixel is 3 (a constant frame)"),
                                         (65535, "every pixel is 65535 (a constant frame)")])
def test_an_all_zero_or_constant_frame_is_refused(sim, tmp_path, capsys, value, says):
    frame = tmp_path / "flat.npy"
    np.save(frame, np.full((24, 32), value, np.uint16 if value == 65535 else np.float32))
    assert reconstruct(sim, frame) == 2
    assert one_line_error(capsys) == f"clsdcam: error: measurement {frame}: {says}: nothing to reconstruct"
    assert not frame.with_suffix(".cube.h5").exists()


# ---- --tv auto on a short solve -----------------------------------------------------------------------------
def test_a_short_auto_solve_says_it_used_the_rules_start(sim, tmp_path, capsys):
    import h5py

    from clsdcam.solve.auto_weights import AUTO_AT
    from clsdcam.solve.priors import TotalVariation as TV

    output = tmp_path / "short.h5"
    assert main(["reconstruct", str(sim / "measurement.npy"), "--calibration", str(sim / "calibration.h5"),
                 "-o", str(output), "--iters", str(AUTO_AT - 10), "--tv", "auto", "--quiet"]) == 0
    line = (f"tv: auto needs {AUTO_AT} iterations to read the noise; this {AUTO_AT - 10}-iteration solve used the "
            f"rule's start {TV.auto_weight.start:.3g}")
    assert line in capsys.readouterr().out
    with h5py.File(output) as f:
        assert line in f.attrs["skips"] and f.attrs["tv_chosen"] == TV.auto_weight.start


# ---- errors name what the user gave -------------------------------------------------------------------------
def test_a_missing_dark_is_called_a_dark(sim, tmp_path, capsys):
    assert reconstruct(sim, sim / "measurement.npy", "--dark", str(tmp_path / "nodark.tif")) == 2
    assert one_line_error(capsys) == f"clsdcam: error: dark {tmp_path / 'nodark.tif'}: no such file"


def test_a_colour_psf_frame_is_called_a_psf_frame(tmp_path, capsys):
    from PIL import Image

    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "rgb.png")
    assert main(["calibrate", "psf", str(tmp_path / "rgb.png"), "-o", str(tmp_path / "psf.h5")]) == 2
    assert one_line_error(capsys).startswith(f"clsdcam: error: psf frame {tmp_path / 'rgb.png'}: expected a 2-D")


def test_exporting_a_calibration_says_it_holds_no_cube_not_that_it_is_unreadable(sim, tmp_path, capsys):
    assert main(["export", str(sim / "calibration.h5"), "-o", str(tmp_path / "cube.tif")]) == 2
    assert one_line_error(capsys) == (f"clsdcam: error: cube {sim / 'calibration.h5'}: no dataset 'cube' "
                                      "(found: filters, psf, wavelength)")


def test_a_videos_truth_is_not_called_a_batch_output(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "video"), *SIZE, "--frames", "3"]) == 0
    capsys.readouterr()
    assert main(["show", str(tmp_path / "video" / "truth.h5"), "--frame", "99"]) == 2
    assert one_line_error(capsys) == (f"clsdcam: error: cube file {tmp_path / 'video' / 'truth.h5'}: no frame 99 "
                                      "(its cubes are frames 0 to 2)")


def test_an_option_that_took_the_measurement_says_so(sim, tmp_path, capsys):
    measurement = str(sim / "measurement.npy")
    assert main(["reconstruct", "--dark", "3", measurement, "--calibration", str(sim / "calibration.h5"),
                 "-o", str(tmp_path / "cube.h5")]) == 2
    assert one_line_error(capsys) == ("clsdcam: error: the following arguments are required: MEASUREMENT "
                                      f"(--dark took '3 {measurement}': give --dark after them)")


# ---- demo --quick ---------------------------------------------------------------------------------------------
def test_demo_quick_writes_its_own_folder_and_help_names_both(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--quick", *SIZE, "--iters", "3", "--quiet"]) == 0
    assert (tmp_path / "clsdcam-out" / "demo-quick" / "cube.h5").exists()
    assert not (tmp_path / "clsdcam-out" / "demo").exists()
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "default clsdcam-out/demo/; with --quick clsdcam-out/demo-quick/" in text


# ---- help text ------------------------------------------------------------------------------------------------
def parsers(parser, name="clsdcam"):
    """(name, parser) for the command line and every sub-command, sub-sub-commands included."""
    import argparse

    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, child in action.choices.items():
                yield from parsers(child, f"{name} {sub}")


def test_every_argument_of_every_command_has_help():
    """Options and positional arguments; a list of sub-commands through each sub-command's own help."""
    import argparse

    from clsdcam.cli.options import build_parser

    arguments = [(f"{name} {'/'.join(action.option_strings) or action.dest}", action)
                 for name, parser in parsers(build_parser()) for action in parser._actions]
    arguments = [(f"{name} {choice.dest}", choice) for name, action in arguments
                 for choice in getattr(action, "_choices_actions", ())] + \
        [(name, action) for name, action in arguments if not isinstance(action, argparse._SubParsersAction)]
    assert not [name for name, action in arguments if not (action.help or "").strip()]


def test_commands_describe_themselves_and_help_states_every_default_in_words(capsys):
    """Every command and sub-command has a description; every option with a default states it, never as a
    Python value ('()', 'None', a list)."""
    import argparse
    import inspect

    from clsdcam.cli.options import build_parser
    from clsdcam.sim import simulate

    for name, parser in parsers(build_parser()):
        assert len(parser.description or "") > (100 if name.count(" ") == 1 else 40), name
        text = parser.format_help()
        assert not re.search(r"\(default: [(\[{<]|\(default: None\)", text), name
        formatter = parser._get_formatter()
        stated = [formatter._expand_help(a) for a in parser._actions if a.option_strings
                  and not any(a.default is unset for unset in (None, False, argparse.SUPPRESS))]
        assert all("default" in help_ for help_ in stated), name
    noise = next(a for a in dict(parsers(build_parser()))["clsdcam simulate"]._actions if a.dest == "noise")
    assert float(re.search(r"\(default (\S+)\)", noise.help)[1]) == inspect.signature(simulate).parameters["noise_var"].default


def test_path_help_says_the_device_path_is_slow_on_a_cpu_device():
    from clsdcam.cli.options import build_parser

    path = next(a for a in dict(parsers(build_parser()))["clsdcam reconstruct"]._actions if a.dest == "path")
    assert "on a CPU device such as PoCL it is ten to a hundred times slower than host" in " ".join(path.help.split())
