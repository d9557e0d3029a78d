"""CIE 1931 colour for the pictures from a shipped table and three published matrices (no colour-science needed).

- Colour matching functions x̄, ȳ, z̄ (λ): the CIE 1931 2° standard colorimetric observer, 360–830 nm at 1 nm
  (CIE 015:2018), in ``cie1931_2deg.csv`` beside this module, written once from colour-science by
  ``tools/cie_table.py``.
- CIE XYZ → linear sRGB with the equal-energy illuminant E as the source white: M = M_sRGB · M_CAT, where M_sRGB
  is the XYZ-to-RGB matrix of IEC 61966-2-1 (its four-decimal form) and M_CAT = M_CAT02⁻¹ · diag(ρ_D65 / ρ_E) ·
  M_CAT02 the von Kries adaptation in CAT02's cone space (CIE 159:2004), ρ_W = M_CAT02 · XYZ_W for the whites'
  XYZ with Y = 1: E (x = y = 1/3) and sRGB's D65 (x, y) = (0.3127, 0.3290). So XYZ ∝ E's (a spectrally flat
  scene) maps to R = G = B: neutral grey.
- The sRGB encoding (IEC 61966-2-1): V = 12.92 L for L ≤ 0.0031308, else 1.055 L^(1/2.4) − 0.055.

These are what ``colour.MSDS_CMFS``, ``colour.XYZ_to_sRGB(…, illuminant=E)`` (CAT02) and
``colour.cctf_encoding(…, function="sRGB")`` give; tests/test_colorimetry.py checks all three against
colour-science wherever it is installed (the test extra installs it).
"""
from __future__ import annotations

from functools import lru_cache
from importlib import resources

import numpy as np

CMF_FILE = "cie1931_2deg.csv"
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986],       # IEC 61966-2-1, D65 white
                        [-0.9689, 1.8758, 0.0415],
                        [0.0557, -0.2040, 1.0570]])
CAT02 = np.array([[0.7328, 0.4296, -0.1624],             # XYZ → the CAT02 cone space (CIE 159:2004)
                  [-0.7036, 1.6975, 0.0061],
                  [0.0030, 0.0136, 0.9834]])
WHITE_E, WHITE_D65 = (1 / 3, 1 / 3), (0.3127, 0.3290)    # CIE 1931 chromaticities (x, y)
SRGB_KNEE = 0.0031308                                    # the encoding's linear segment ends here


@lru_cache(maxsize=1)
def colour_matching_functions() -> tuple[np.ndarray, np.ndarray]:
    """(λ (471,) nm, [x̄ ȳ z̄] (471, 3)) of the CIE 1931 2° observer, from the shipped table (read-only)."""
    text = resources.files(__package__).joinpath(CMF_FILE).read_text(encoding="ascii")
    rows = [line for line in text.splitlines() if line and not line.startswith("#")][1:]   # after the column names
    table = np.loadtxt(rows, delimiter=",", ndmin=2)
    table.setflags(write=False)
    return table[:, 0], table[:, 1:]


def white_xyz(xy) -> np.ndarray:
    """The XYZ (Y = 1) of chromaticity (x, y): (x/y, 1, (1 − x − y)/y)."""
    x, y = xy
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def xyz_to_linear_srgb() -> np.ndarray:
    """The 3×3 matrix whose rows are the linear sRGB of X, Y and Z (``xyz @ matrix`` converts rows of XYZ):
    (M_sRGB · M_CAT)ᵀ, adapting the equal-energy white E to sRGB's D65 (see the module docstring)."""
    gains = (CAT02 @ white_xyz(WHITE_D65)) / (CAT02 @ white_xyz(WHITE_E))
    adaptation = np.linalg.solve(CAT02, gains[:, None] * CAT02)
    return (XYZ_TO_SRGB @ adaptation).T


def srgb_encode(linear) -> np.ndarray:
    """Linear sRGB in [0, 1] → the encoded (display) values, IEC 61966-2-1's curve."""
    linear = np.asarray(linear, dtype=np.float64)
    return np.where(linear <= SRGB_KNEE, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
