"""Importers of public track and train formats. A new format is one module with a ``Reader`` and one
line in ``READERS``; ``importer.run_import`` does the rest (checks, validation, writing)."""

from __future__ import annotations

from .base import Imported, ImportedFile, ImportOptions, Reader
from .osrd import OsrdInfraReader, OsrdTrainReader
from .railml import RailmlReader
from .railtoolkit import RailtoolkitReader
from .ttobench import TTOBenchReader

READERS: dict[str, Reader] = {
    "ttobench": TTOBenchReader(),
    "railtoolkit": RailtoolkitReader(),
    "osrd": OsrdInfraReader(),
    "osrd-train": OsrdTrainReader(),
    "railml": RailmlReader(),
}

__all__ = ["READERS", "Imported", "ImportedFile", "ImportOptions", "Reader"]
