"""Rendering: tables, plots and the writers of output files (JSON, CSV); nothing here computes a result."""
