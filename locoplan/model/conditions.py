"""Driving conditions: the ISSA paper's four things a driver does (T, K, C, B) and the electric brake alone (E), and their
codes in every array."""

from __future__ import annotations

CONDITIONS = ("T", "K", "C", "B", "E")
"""T traction (max effort, held at the limit), K cruise (hold speed), C coast (no force), B brake (max
braking), E the electric brake alone (at full; the wagons' air brake is not applied for it, only where the
train must follow a limit or a braking curve the electric brake cannot: a heavy train slowing for a lower limit
ahead, or for a neutral section on a descent, without an application and its least hold. Where the model has no
separate air brake (the papers' point mass, ``--no-air-brake``) it is B). Index = the code used in arrays (the
calculator's profile, its compiled kernel, the DP)."""
CODE = {c: i for i, c in enumerate(CONDITIONS)}
T, K, C, B, E = 0, 1, 2, 3, 4
"""The codes as constants (for the compiled kernels, which read them at compile time)."""
assert (T, K, C, B, E) == tuple(CODE[c] for c in CONDITIONS)
N_CONDITIONS = len(CONDITIONS)
CONDITION_NAMES = {"T": "traction", "K": "cruise", "C": "coast", "B": "brake", "E": "electric brake"}
"""Each condition's name in tables, plots and help."""
