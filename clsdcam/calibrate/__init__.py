"""From lab measurements to a calibration file (``clsdcam calibrate``).

``calibrate psf``: point-source frames → averaged (:mod:`.frames`), dark removed (:mod:`.dark`), cropped,
binned, centred and normalised (:mod:`.psf`); the steps are recorded (:mod:`clsdcam.camera.raw`) so that a raw
measurement
gets the same ones. ``calibrate filters``: a monochromator sweep of the filter array (:mod:`.frames`),
divided by the source power and exposure (:mod:`.sweep`), integrated into bands (:mod:`.bands`), with a map
of dead, hot and saturated pixels (:mod:`.defects`); :mod:`.filters` runs it, :mod:`.pictures` draws it.
Nothing heavy is imported here: the command line imports the modules it needs inside its ``run``.
"""
