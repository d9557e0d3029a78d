"""OpenCL C sources of clsdcam, installed as package data of ``clsdcam.kernels``."""
