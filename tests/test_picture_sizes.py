"""Issue 48: the pictures are readable at every size the simulator makes, from 24×32 to the prototype's 320×448:
every title and label lies on the canvas, no legend hides a curve and every colour bar says its units (the spectra's
numbering, red, green, blue, white: tests/test_show.py)."""
import re

import numpy as np
import pytest

from clsdcam.input_pictures import Inputs, input_figure
from clsdcam.picks import spectrum_points
from clsdcam.render import false_colour, projections_figure, spectra_figure
from clsdcam.sim.scenes import make_scene
from clsdcam.sim.spectra import band_wavelengths

SIZES = [(24, 32), (48, 64), (96, 128), (320, 448)]


def labels(fig) -> list:
    """The titles and axis labels of every panel and colour bar of ``fig``, and its legends' texts, that are set."""
    texts = [text for ax in fig.axes for text in (ax.title, ax.xaxis.label, ax.yaxis.label)]
    texts += [text for ax in fig.axes if ax.get_legend() for text in ax.get_legend().get_texts()]
    return [text for text in texts if text.get_text()]


def off_canvas(fig) -> list[str]:
    """The labels of ``fig`` (:func:`labels`) that reach past the canvas once drawn."""
    fig.canvas.draw()
    renderer, canvas = fig.canvas.get_renderer(), fig.bbox
    return [text.get_text() for text in labels(fig) if not _within(text.get_window_extent(renderer), canvas)]


def _within(box, canvas) -> bool:
    return box.x0 >= canvas.x0 and box.y0 >= canvas.y0 and box.x1 <= canvas.x1 and box.y1 <= canvas.y1


def simulated_inputs(shape, bands=16) -> Inputs:
    """An input picture's parts of the sizes a simulation of ``shape`` makes (their values do not matter here)."""
    rng = np.random.default_rng(0)
    return Inputs(rng.random(shape), "measurement.npy", rng.random(shape), rng.random((bands, *shape)),
                  band_wavelengths(bands), "calibration.h5")


def target(shape, bands=16):
    wavelengths = band_wavelengths(bands)
    truth = make_scene("target", shape, wavelengths)
    return truth, wavelengths, false_colour(truth, wavelengths)


@pytest.mark.parametrize("shape", SIZES)
def test_the_input_pictures_titles_and_labels_lie_on_the_canvas(shape):
    fig = input_figure(simulated_inputs(shape))
    assert len(fig.axes[2].get_title().splitlines()) == 2       # the filter panel's title is drawn
    assert off_canvas(fig) == []


def legend_hides_a_curve(fig, ax) -> bool:
    """Whether ``ax``'s legend lies over its axes (a curve may run under it), once drawn."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    return ax.get_legend().get_window_extent(renderer).overlaps(ax.get_window_extent(renderer))


@pytest.mark.parametrize("shape", SIZES)
def test_the_spectra_legend_hides_no_curve_and_lies_on_the_canvas(shape):
    truth, wavelengths, image = target(shape)
    points = spectrum_points(truth, wavelengths)
    fig = spectra_figure(truth * 0.8, wavelengths, image, points, truth)
    assert not legend_hides_a_curve(fig, fig.axes[1])
    legend = [text.get_text() for text in fig.axes[1].get_legend().get_texts()]
    assert len(legend) == len(points) + 2 and "dashed: the truth" in legend     # a key per point, and the styles
    assert off_canvas(fig) == []


def test_the_profiles_legend_hides_no_curve():
    from clsdcam.render import profiles_figure

    grey = np.random.default_rng(1).random((48, 64))
    fig = profiles_figure(grey, grey, (20, 30), truth=grey)
    assert not legend_hides_a_curve(fig, fig.axes[1]) and off_canvas(fig) == []


def colour_bar_labels(fig) -> list[str]:
    """The label of each colour bar of ``fig``."""
    return [cax.get_ylabel() or cax.get_xlabel() for cax in fig.axes if cax.get_label() == "<colorbar>"]


@pytest.mark.parametrize("figure", ["input", "projections"])
def test_every_colour_bar_says_what_its_values_are_in(figure):
    truth, wavelengths, image = target((48, 64))
    fig = input_figure(simulated_inputs((48, 64))) if figure == "input" else \
        projections_figure(truth, wavelengths, image)
    found = colour_bar_labels(fig)
    assert len(found) == (3 if figure == "input" else 2)
    assert all(re.search(r"\(.+\)", label) for label in found), found      # the units, in brackets
