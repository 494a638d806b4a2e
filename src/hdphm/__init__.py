"""hdphm: physics-informed health monitoring and prognostics for harmonic drives."""

__version__ = "0.1.0"
