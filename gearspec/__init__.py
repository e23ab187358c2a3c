"""gearspec: spectral analysis and modelling of friction in robot gear drives."""

__version__ = "0.4.1"
