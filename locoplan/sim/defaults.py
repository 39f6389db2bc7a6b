"""The calculator's defaults that the command line shows in its help: plain numbers, importable without
numpy (``locoplan --help`` does not load the calculator). :mod:`locoplan.sim.calculator` re-exports them."""

from __future__ import annotations

DEFAULT_STEP_M = 50.0
"""Default grid spacing [m]. Halving it changes time and energy on freight-20km by far less than
0.05 % / 0.1 % (tests/test_calculator.py::test_step_convergence; README, 'step size')."""
