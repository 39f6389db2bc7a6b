"""Drivers' logs, the data: the file schemas and the plain data classes (reading in ``io/logs.py``,
writing in ``reporting/logs.py``). One CSV per run plus a YAML manifest (SPEC section 1, "Driver log").

**Log CSV**, one run per file, a header row, then one row per sample (any sampling rate; rows in time
order)::

    time_s,position_m,speed_kmh,force_kn,notch,action
    0.0,0.00,0.000,760.00,8,T
    1.0,0.07,0.529,760.00,8,T

- ``time_s`` [s], strictly rising; ``position_m`` [m] of the train's head from the route's start,
  never falling; ``speed_kmh`` [km/h] >= 0; ``force_kn`` [kN] at the wheel, + traction, - braking,
  the force applied from this row until the next (zero-order hold, as recorders log it).
- optional ``notch``: the handle position, an integer (+ traction notches, - braking notches, 0 off);
  optional ``action``: what the driver did, one of T (traction), K (holding a speed), C (coasting),
  B (braking).
- Units live in the column names, as in every locoplan file: a column in other units (``speed_mph``,
  ``position_ft``, ``force_lbf`` ...) is refused with the conversion to use.

**Manifest** ``manifest.yaml`` in the log folder (or a sidecar ``<log>.yaml`` per run, schema
``locoplan/driver-run@1``, same keys as one run plus ``synthetic``)::

    schema: locoplan/driver-logs@1
    route: route.yaml                # default for every run; paths relative to this file
    consist: consists/m5200.yaml     # default for every run
    synthetic: true                  # required: is this data made by a simulator?
    generator: {name: locoplan drivers simulate, version: 0.2.0, seed: 1}   # optional
    runs:
      - {log: logs/r0001.csv, driver_id: D01, mass_t: 5200, scheduled_time_s: 1500,
         actual_time_s: 1502.0, date: 2024-03-01}

Every problem is reported as ``file:line: column N (name): why`` (CSV) or ``file:line: field: why``
(manifest); a log set with any problem is refused as a whole (exit 2).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Literal

import numpy as np
from pydantic import Field

from ..physics.units import KJ_PER_KWH
from .common import Strict
from .conditions import CONDITIONS
from .route import Route
from .train import Train

REQUIRED_COLUMNS = ("time_s", "position_m", "speed_kmh", "force_kn")
OPTIONAL_COLUMNS = ("notch", "action")
ACTIONS = CONDITIONS[:4]  # what the driver did: the ISSA paper's four conditions (a log tells no brake apart)


# ------------------------------------------------------------------------------------------ manifest
class Generator(Strict):
    """What made synthetic logs: program, version and random seed."""

    name: str
    version: str
    seed: int | None = None


class RunEntry(Strict):
    """One run in a manifest. Paths are relative to the manifest's folder."""

    log: str = Field(min_length=1, description="the run's CSV file")
    driver_id: str = Field(min_length=1)
    route: str | None = Field(default=None, description="route file (default: the manifest's)")
    consist: str | None = Field(default=None, description="consist file or catalogue name (default: the manifest's)")
    mass_t: float = Field(gt=0, le=100_000, description="total train mass [t] (at most 100,000 t, as a consist)")
    scheduled_time_s: float = Field(gt=0, le=604_800, description="planned running time [s] (at most a week)")
    actual_time_s: float = Field(gt=0, le=604_800, description="running time as driven [s] (at most a week)")
    date: dt.date = Field(strict=False, description="date of the run, YYYY-MM-DD")


class DriverLogs(Strict):
    """A folder's manifest: defaults for its runs and the runs."""

    schema_: Literal["locoplan/driver-logs@1"] = Field(alias="schema")
    route: str | None = None
    consist: str | None = None
    synthetic: bool
    generator: Generator | None = None
    notes: str | None = None
    runs: list[RunEntry] = Field(min_length=1)


class DriverRun(RunEntry):
    """A per-run sidecar ``<log>.yaml``: one run with its own route, consist and ``synthetic`` flag."""

    schema_: Literal["locoplan/driver-run@1"] = Field(alias="schema")
    synthetic: bool
    generator: Generator | None = None
    notes: str | None = None


MANIFEST_SCHEMAS = {"locoplan/driver-logs@1": DriverLogs, "locoplan/driver-run@1": DriverRun}
MANIFEST_NAME = "manifest.yaml"


# ------------------------------------------------------------------------------------------ one log
@dataclass(frozen=True)
class LogData:
    """The columns of one log CSV (arrays of equal length, one entry per row)."""

    time_s: np.ndarray
    position_m: np.ndarray
    speed_kmh: np.ndarray
    force_kn: np.ndarray
    notch: np.ndarray | None = None
    action: np.ndarray | None = None  # str array of T/K/C/B

    @property
    def running_time_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    @property
    def traction_energy_kwh(self) -> float:
        """Traction work sum F+ ds at the wheel [kWh] (each row's force held until the next row)."""
        ds = np.diff(self.position_m)
        return float(np.sum(np.maximum(self.force_kn[:-1], 0.0) * ds)) / KJ_PER_KWH


# ------------------------------------------------------------------------------------------ log sets
@dataclass(frozen=True)
class LoggedRun:
    """One run: what the manifest says about it, the route and train it ran with, and its log's running
    time and traction energy. The log's rows are not held: ``data`` reads them again from the file each
    time (``read``, given by the reader), so that a log set of 20,000 runs costs its summaries in memory,
    not its rows."""

    log_file: Path
    manifest_file: Path
    manifest_line: int | None
    driver_id: str
    route_file: Path
    route: Route
    consist_file: Path
    train: Train
    mass_t: float
    scheduled_time_s: float
    actual_time_s: float
    date: dt.date
    synthetic: bool
    running_time_s: float  # the log's, LogData.running_time_s
    traction_energy_kwh: float  # the log's, LogData.traction_energy_kwh
    read: Callable[[], LogData] = field(repr=False, compare=False)

    @property
    def data(self) -> LogData:
        """The log's rows, read again (the same rows as checked when the log set was read)."""
        return self.read()
