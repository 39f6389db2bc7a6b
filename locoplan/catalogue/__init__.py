"""The shipped catalogue: consists, rolling stock, optimiser parameter files and example routes."""

DEFAULT_CONSIST = "HXD1-C80x50"
"""The consist a run uses when none is named: a catalogue name (``consists/HXD1-C80x50.yaml``)."""
