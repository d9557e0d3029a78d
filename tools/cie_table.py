#!/usr/bin/env python3
"""Write clsdcam/cie1931_2deg.csv, the colour matching functions the pictures use, from colour-science (run once).

    python tools/cie_table.py            # needs colour-science (pip install colour-science)

The numbers are the CIE 1931 2° standard colorimetric observer x̄(λ), ȳ(λ), z̄(λ), 360–830 nm at 1 nm, as CIE
015:2018 (Colorimetry, 4th edition) tabulates them; colour-science carries them as ``colour.MSDS_CMFS["CIE 1931 2
Degree Standard Observer"]`` (from CVRL, http://cvrl.ioo.ucl.ac.uk/cie.htm). Each value is written as Python's
shortest repr of colour-science's float, which reads back as the same float: tests/test_colorimetry.py checks the
shipped table against colour-science's wherever colour-science is installed.
"""
from __future__ import annotations

import argparse
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "clsdcam" / "cie1931_2deg.csv"
OBSERVER = "CIE 1931 2 Degree Standard Observer"
HEADER = ("# CIE 1931 2-degree standard colorimetric observer: colour matching functions, 360-830 nm at 1 nm\n"
          "# Source: CIE 015:2018 Colorimetry, 4th ed.; read from colour-science {version} "
          "(colour.MSDS_CMFS['" + OBSERVER + "'], from CVRL) by tools/cie_table.py\n"
          "wavelength_nm,x_bar,y_bar,z_bar\n")


def table_text() -> str:
    """The CSV: the two comment lines and the column names (HEADER), then one row per wavelength."""
    import colour

    cmfs = colour.MSDS_CMFS[OBSERVER]
    rows = (",".join(repr(float(v)) for v in (nm, *values)) for nm, values in zip(cmfs.wavelengths, cmfs.values))
    return HEADER.format(version=colour.__version__) + "\n".join(rows) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=OUT, help=f"the CSV to write (default {OUT})")
    args = parser.parse_args(argv)
    args.out.write_text(table_text(), encoding="ascii")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
