"""Importers of public track and train formats. A new format is one module with a ``Reader`` and one
line in ``FORMATS``; ``importer.run_import`` does the rest (checks, validation, writing).

``FORMATS`` is plain data (``locoplan import --help`` lists it without loading a reader); ``READERS``
imports every reader module on first use."""

from __future__ import annotations

import importlib
from typing import NamedTuple

from .base import Imported, ImportedFile, ImportOptions, Reader


class Format(NamedTuple):
    """One source format: ``reader``, its class as ``"module:Class"`` in this package; ``description``,
    what it reads (the help of ``locoplan import``)."""

    reader: str
    description: str


FORMATS: dict[str, Format] = {
    "ttobench": Format("ttobench:TTOBenchReader", "TTOBench track (JSON): one route file per stop-to-stop leg"),
    "railtoolkit": Format("railtoolkit:RailtoolkitReader", "railtoolkit running paths and rolling stock (YAML, schema "
                          "2022.05): routes, vehicles, consists"),
    "osrd": Format("osrd:OsrdInfraReader", "OSRD RailJSON infrastructure: the path between two operational points, as "
                   "a route and a journey"),
    "osrd-train": Format("osrd:OsrdTrainReader", "OSRD RailJSON rolling stock: a vehicle and a consist file each"),
    "railml": Format("railml:RailmlReader", "railML 2.x infrastructure (XML): tracks, or the path between two "
                     "operational points, as a route and a journey"),
}
"""Format name (``locoplan import FORMAT``) -> its reader and description, in the order the help lists them."""


def _reader(fmt: Format) -> Reader:
    module, _, cls = fmt.reader.partition(":")
    return getattr(importlib.import_module(f".{module}", __name__), cls)()


def __getattr__(name: str):
    if name == "READERS":  # format name -> its Reader, the reader modules imported now
        readers = {key: _reader(fmt) for key, fmt in FORMATS.items()}
        globals()["READERS"] = readers
        return readers
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["FORMATS", "READERS", "Format", "Imported", "ImportedFile", "ImportOptions", "Reader"]
