"""locoplan: driving-strategy planner for heavy freight trains."""

__version__ = "0.1.0"
