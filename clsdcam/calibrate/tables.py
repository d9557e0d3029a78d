"""Small CSV tables of numbers (wavelengths, source power, exposures, band edges).

A table is text (UTF-8, a byte-order mark allowed) of rows of numbers separated by commas or white space;
blank lines and lines starting with ``#`` are skipped, and a first line that is not numbers is a header
(e.g. ``Cornerstone Wavelength  (nm),uW output``).
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..io import existing_file


def read_table(path, what: str, columns: int) -> np.ndarray:
    """(rows, ``columns``) float64 from a CSV file; InputError (one line naming the file) when it cannot be read,
    a row is not numbers, or a row has fewer columns (extra columns are ignored)."""
    path = existing_file(path, what)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{what} {path}: not a readable text file ({exc})") from None
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1)
             if line.strip() and not line.lstrip().startswith("#")]
    rows = [_numbers(line) for _, line in lines]
    if rows and rows[0] is None:          # a header
        lines, rows = lines[1:], rows[1:]
    for (n, line), row in zip(lines, rows):
        if row is None or len(row) < columns or not np.isfinite(row[:columns]).all():
            raise InputError(f"{what} {path}: line {n} is not {columns} number{'s' * (columns > 1)}: {line.strip()!r}")
    if not rows:
        raise InputError(f"{what} {path}: no rows of numbers")
    return np.array([row[:columns] for row in rows], np.float64)


def _numbers(line: str) -> list[float] | None:
    try:
        return [float(v) for v in line.replace(",", " ").split()]
    except ValueError:
        return None


def interpolated(path, wavelengths: np.ndarray, what: str) -> np.ndarray:
    """A table (wavelength nm, value) linearly interpolated at ``wavelengths``; InputError when it does not
    cover them (no extrapolation) or its wavelengths do not increase."""
    table = read_table(path, what, 2)
    lam, values = table[:, 0], table[:, 1]
    if np.any(np.diff(lam) <= 0):
        raise InputError(f"{what} {path}: the wavelengths (first column) must increase")
    if wavelengths.min() < lam[0] or wavelengths.max() > lam[-1]:
        raise InputError(f"{what} {path}: covers {lam[0]:g}–{lam[-1]:g} nm, the sweep needs "
                         f"{wavelengths.min():g}–{wavelengths.max():g} nm")
    return np.interp(wavelengths, lam, values)
