"""The pictures' colour without colour-science: the shipped CIE 1931 table, the XYZ → sRGB matrix and the sRGB
encoding are colour-science's (checked where it is installed, as the test extra installs it), and a flat
spectrum still renders grey."""
import numpy as np
import pytest

from clsdcam import colorimetry

OBSERVER = "CIE 1931 2 Degree Standard Observer"


@pytest.fixture(scope="module")
def colour():
    return pytest.importorskip("colour", reason="colour-science is not installed (pip install 'clsdcam[test]')")


def test_the_shipped_table_is_colour_sciences(colour):
    nm, cmf = colorimetry.colour_matching_functions()
    reference = colour.MSDS_CMFS[OBSERVER]
    np.testing.assert_array_equal(nm, reference.wavelengths)
    np.testing.assert_array_equal(cmf, reference.values)


def test_the_xyz_to_srgb_matrix_is_colour_sciences_with_white_e(colour):
    white_e = colour.CCS_ILLUMINANTS[OBSERVER]["E"]
    reference = colour.XYZ_to_sRGB(np.eye(3), illuminant=white_e, apply_cctf_encoding=False)
    np.testing.assert_allclose(colorimetry.xyz_to_linear_srgb(), reference, rtol=1e-13, atol=1e-14)


def test_the_srgb_encoding_is_colour_sciences(colour):
    linear = np.concatenate([np.linspace(0, 0.01, 1001), np.linspace(0, 1, 1001)])
    np.testing.assert_allclose(colorimetry.srgb_encode(linear), colour.cctf_encoding(linear, function="sRGB"),
                               rtol=1e-14, atol=1e-15)


def test_the_table_spans_the_visible_at_1_nm_and_peaks_where_the_cie_says():
    """360–830 nm at 1 nm; ȳ peaks at 1 at 555 nm; x̄, z̄ peak at 599 and 446 nm (CIE 015:2018)."""
    nm, cmf = colorimetry.colour_matching_functions()
    np.testing.assert_array_equal(nm, np.arange(360.0, 831.0))
    assert cmf.shape == (471, 3) and cmf.min() >= 0 and cmf[nm == 555, 1] == 1.0
    assert list(nm[np.argmax(cmf, axis=0)]) == [599.0, 555.0, 446.0]
    assert not cmf.flags.writeable, "the cached table must not be changed by a caller"


def test_equal_energy_white_maps_to_grey():
    """XYZ of E (1, 1, 1) → R = G = B = 1, to the rounding of the standard's four-decimal matrix (which takes D65
    to 1 ± 2e-4; without the adaptation E would be (1.20, 0.95, 0.91)); the encoding takes 0 → 0 and 1 → 1."""
    np.testing.assert_allclose(np.ones(3) @ colorimetry.xyz_to_linear_srgb(), 1.0, rtol=5e-4)
    np.testing.assert_allclose(colorimetry.srgb_encode([0.0, 1.0]), [0.0, 1.0], atol=1e-12)
