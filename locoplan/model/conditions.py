"""Driving conditions (seed 002): the four things a driver does, and their codes in every array."""

from __future__ import annotations

CONDITIONS = ("T", "K", "C", "B")
"""T traction (max effort, held at the limit), K cruise (hold speed), C coast (no force), B brake (max
braking). Index = the code used in arrays (the calculator's profile, its compiled kernel, the DP)."""
CODE = {c: i for i, c in enumerate(CONDITIONS)}
T, K, C, B = 0, 1, 2, 3
"""The codes as constants (for the compiled kernels, which read them at compile time)."""
assert (T, K, C, B) == tuple(CODE[c] for c in CONDITIONS)
