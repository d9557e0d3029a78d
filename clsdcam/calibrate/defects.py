"""The defect map of a filter sweep: pixels whose filter function cannot be trusted, left out of the data
term of every reconstruction (written as dataset ``dead_pixels`` (H, W) bool of the calibration).

With T(y, x) = max_i t_i(y, x) a pixel's peak transmission over the sweep and T̃ the median of T over pixels:

- dead: never responds, T ≤ DEAD_FRACTION · T̃;
- hot: responds everywhere, min_i t_i > HOT_FLOOR · T̃ (a real filter pixel falls near zero away from its
  pass band), or, with dark frames, responds in the dark: d − median(d) > HOT_DARK · S̃ (d the mean dark frame,
  S̃ the median over pixels of the brightest dark-subtracted signal each pixel saw);
- saturated: the raw value reached the saturation code (the largest value of the frames' integer type, or
  ``--saturation``) in some frame.

Raw-size findings (saturated, hot in the dark) are taken to the calibration's grid like the frames (crop, then
a binned pixel is defective when any of its raw pixels is).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera.raw import RawSteps, bin_pixels, crop_frame

DEAD_FRACTION = 0.02
HOT_FLOOR = 0.5
HOT_DARK = 0.1


@dataclass(frozen=True, eq=False)
class Defects:
    dead: np.ndarray        # (h, w) bool each
    hot: np.ndarray
    saturated: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        return self.dead | self.hot | self.saturated

    def describe(self) -> str:
        return (f"{int(self.dead.sum())} dead, {int(self.hot.sum())} hot, {int(self.saturated.sum())} saturated "
                f"pixels ({int(self.mask.sum())} left out)")


def on_grid(raw_mask: np.ndarray, steps: RawSteps) -> np.ndarray:
    """A raw-size pixel map taken to the calibration's grid: cropped, then any raw pixel of a bin marks it."""
    return bin_pixels(crop_frame(raw_mask.astype(np.float64), steps.crop), steps.bin) > 0


def find_defects(transmission: np.ndarray, peak_signal: np.ndarray, saturated_raw: np.ndarray,
                 steps: RawSteps) -> Defects:
    """The map of the module docstring from the sweep's t_i (N, h, w), its brightest signal per pixel (h, w),
    the raw pixels at the saturation code (H, W) and the raw steps (their dark frame, crop and bin)."""
    peak = transmission.max(axis=0)
    typical = np.median(peak)
    hot = transmission.min(axis=0) > HOT_FLOOR * typical
    if steps.dark_frame is not None:
        dark = steps.dark_frame
        hot |= on_grid(dark - np.median(dark) > HOT_DARK * np.median(peak_signal), steps)
    return Defects(peak <= DEAD_FRACTION * typical, hot, on_grid(saturated_raw, steps))
