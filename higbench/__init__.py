"""higbench: half-inverse gradients and friends on physics-based deep learning problems."""

__version__ = "0.1.0"
