"""The independent check of the minimum-energy optimum the tests use: ``locoplan.ocp.trapezoid``."""

from locoplan.ocp.trapezoid import trapezoid_min_energy  # noqa: F401
