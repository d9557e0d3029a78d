"""Fuzzed files: every loader either reads a file or raises InputError (one line) — never another
exception, never a hang. Seeds are valid files; hypothesis truncates them, overwrites bytes,
prepends garbage, or writes random bytes, 2 000 files per loader."""
import io
from datetime import timedelta

import h5py
import numpy as np
import pytest
import scipy.io
import tifffile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from clsdcam.camera.calibration import Calibration
from clsdcam.cli import main
from clsdcam.errors import InputError
from clsdcam.io import load_measurement

FRAME = (np.arange(48, dtype=np.uint16).reshape(6, 8) * 911)
RNG = np.random.default_rng(0)


def npy_bytes():
    buffer = io.BytesIO()
    np.save(buffer, FRAME.astype(np.float32))
    return buffer.getvalue()


def png_bytes():
    buffer = io.BytesIO()
    Image.fromarray(FRAME).save(buffer, format="PNG")
    return buffer.getvalue()


def tiff_bytes():
    buffer = io.BytesIO()
    tifffile.imwrite(buffer, FRAME)
    return buffer.getvalue()


def h5_bytes(datasets: dict):
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        for key, value in datasets.items():
            f[key] = value
    return buffer.getvalue()


def mat_bytes():
    buffer = io.BytesIO()
    scipy.io.savemat(buffer, {"psf": RNG.random((6, 8)), "mask": RNG.random((6, 8, 3)), "wavs": [[450, 550, 650]]})
    return buffer.getvalue()


SEEDS = {  # loader name -> (file suffix, seed bytes, loader)
    "npy": (".npy", npy_bytes(), load_measurement),
    "png": (".png", png_bytes(), load_measurement),
    "tiff": (".tif", tiff_bytes(), load_measurement),
    "h5 measurement": (".h5", h5_bytes({"measurement": FRAME}), load_measurement),
    "mat calibration": (".mat", mat_bytes(), Calibration.load),
    "h5 calibration": (".h5", h5_bytes({"psf": RNG.random((6, 8)), "filters": RNG.random((3, 6, 8)),
                                        "wavelengths": [450.0, 550.0, 650.0]}), Calibration.load),
}


@st.composite
def mutated(draw, seed: bytes):
    """A damaged copy of ``seed``: truncated, bytes overwritten (header fields included), prefixed, or random."""
    kind = draw(st.sampled_from(["truncate", "overwrite", "prefix", "random", "huge"]))
    if kind == "truncate":
        return seed[:draw(st.integers(0, len(seed) - 1))]
    if kind == "random":
        return draw(st.binary(max_size=256))
    if kind == "prefix":
        return draw(st.binary(min_size=1, max_size=32)) + seed
    data = bytearray(seed)
    limit = min(len(data), 600)  # headers live at the start: damage them most
    for _ in range(draw(st.integers(1, 8))):
        position = draw(st.integers(0, limit - 1))
        data[position] = 0xFF if kind == "huge" else draw(st.integers(0, 255))
    return bytes(data)


def check_loader(tmp_path, name, content):
    suffix, _, loader = SEEDS[name]
    path = tmp_path / f"fuzz{suffix}"
    path.write_bytes(content)
    try:
        loader(path)
    except InputError as exc:
        assert "\n" not in str(exc) and str(path) in str(exc)


@pytest.mark.stress
@pytest.mark.parametrize("name", sorted(SEEDS))
def test_fuzzed_files_are_read_or_rejected_with_one_line(tmp_path_factory, name):
    tmp_path = tmp_path_factory.mktemp("fuzz")

    @settings(max_examples=2000, deadline=timedelta(seconds=5), database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(content=mutated(SEEDS[name][1]))
    def run(content):
        check_loader(tmp_path, name, content)

    run()


@pytest.mark.stress
@settings(max_examples=60, deadline=None, database=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(content=mutated(npy_bytes()))
def test_fuzzed_measurement_through_the_cli_exits_0_or_2_and_leaves_no_partial_file(tmp_path_factory, content):
    tmp_path = tmp_path_factory.mktemp("cli")
    cal = tmp_path / "cal.h5"
    cal.write_bytes(SEEDS["h5 calibration"][1])
    meas = tmp_path / "m.npy"
    meas.write_bytes(content)
    output = tmp_path / "out.h5"
    code = main(["reconstruct", str(meas), "--calibration", str(cal), "-o", str(output), "--iters", "2", "--quiet"])
    assert code in (0, 2)
    assert output.exists() == (code == 0)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
