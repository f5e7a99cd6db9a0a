"""biso_cosim: closed-loop tests of MEMS attitude estimation on a simulated vehicle."""

__version__ = "0.1.0"
