"""The camera: its field geometry, the forward model A, the calibration (PSF, filters, wavelengths) and the
raw steps it records, and the prototype's numbers."""
