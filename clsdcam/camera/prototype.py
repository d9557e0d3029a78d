"""The published Spectral DiffuserCam prototype's numbers (Monakhova et al., Optica 2020), the defaults of the
simulator and the command line: one light module, so that building the command line imports nothing heavy."""

SENSOR_SHAPE = (320, 448)          # the sensor crop (rows, columns)
N_BANDS = 64                       # spectral bands
SPECTRAL_RANGE = (386.0, 898.0)    # nm, the calibrated range
