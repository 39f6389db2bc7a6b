"""The shipped catalogue: consists, rolling stock, optimiser parameter files and example routes."""

DEFAULT_CONSIST = "HXD1-C80x50"
"""The consist a run uses when none is named: a catalogue name (``consists/HXD1-C80x50.yaml``)."""
DEFAULT_CONSIST_FILE = f"configs/consists/{DEFAULT_CONSIST}.yaml"
"""The same consist as the command line names it by default: the project's file (outside a checkout
``io.load.resolve_consist_path`` finds the catalogue's identical copy by its name)."""
