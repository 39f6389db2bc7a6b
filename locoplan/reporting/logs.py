"""Drivers' logs, the writing: the text of a log CSV and of a manifest (the formats ``io/logs.py``
reads), and the log folder ``locoplan drivers simulate`` makes, written whole or not at all."""

from __future__ import annotations

import fcntl
import io
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import yaml

from ..errors import InputError, Problem
from .files import existing_folder, make_folder
from ..learn.drivers import SimulatedLogs, SimulationSpec, simulate_logs
from ..model.consist import Consist
from ..model.logs import MANIFEST_NAME, REQUIRED_COLUMNS, LogData


# ------------------------------------------------------------------------------------------ texts
def log_csv_text(data: LogData) -> str:
    """The CSV text of a log (the format ``read_log_csv`` reads)."""
    cols = list(REQUIRED_COLUMNS) + (["notch"] if data.notch is not None else []) + (["action"] if data.action is not None else [])
    out = io.StringIO()
    out.write(",".join(cols) + "\n")
    for i in range(len(data.time_s)):
        row = [f"{data.time_s[i]:.1f}", f"{data.position_m[i]:.2f}", f"{data.speed_kmh[i]:.3f}", f"{data.force_kn[i]:.2f}"]
        if data.notch is not None:
            row.append(str(int(data.notch[i])))
        if data.action is not None:
            row.append(str(data.action[i]))
        out.write(",".join(row) + "\n")
    return out.getvalue()


def manifest_text(model: dict, header: str = "") -> str:
    """YAML text of a manifest dict (``schema`` first, one run per line)."""
    runs = model.get("runs", [])
    head = {k: v for k, v in model.items() if k != "runs"}
    text = header
    for k, v in head.items():
        flow = isinstance(v, (dict, list))
        text += f"{k}: " + yaml.safe_dump(v, default_flow_style=flow, width=10_000).strip().removesuffix("\n...").strip() + "\n"
    if runs:
        text += "runs:\n"
        for r in runs:
            text += "  - " + yaml.safe_dump(r, sort_keys=False, default_flow_style=True, width=10_000).strip() + "\n"
    return text


def consist_yaml(consist: Consist) -> str:
    """YAML text of a consist resized by ``drivers simulate`` (the consist file format)."""
    data = {"schema": "locoplan/consist@1", "name": consist.name,
            "vehicles": [{"type": e.type, "count": e.count, **({"load_t": e.load_t} if e.load_t else {})} for e in consist.vehicles],
            "service_brake_coefficient": consist.service_brake_coefficient}
    if consist.brake_deceleration_ms2 is not None:
        data["brake_deceleration_ms2"] = consist.brake_deceleration_ms2
    return ("# written by locoplan drivers simulate: the base consist resized to this mass\n"
            + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=200))


def drivers_csv_text(ids: list[str], rows: list[dict]) -> str:
    """``drivers.csv``: each simulated driver's habits, one row per driver."""
    import csv

    from .writers import csv_cell

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["driver_id", *rows[0]])
    writer.writerows([ids[i], *(csv_cell(x) for x in row.values())] for i, row in enumerate(rows))
    return buf.getvalue()


# ------------------------------------------------------------------------------------------ the log folder
@dataclass(frozen=True)
class SimulationSummary:
    out_dir: Path
    n_runs: int
    groups: list[dict]  # per mass and time: drivers' mean / min / max energy and time, late runs
    drivers: list[dict]
    removed: list[Path]  # folders left by runs that were killed, removed before this one (PartialFolder)


def check_out_dir(out_dir: Path) -> None:
    """Refuse an output folder that holds anything (logs are written whole or not at all)."""
    if out_dir.exists() and (not out_dir.is_dir() or any(out_dir.iterdir())):
        raise InputError(Problem(str(out_dir), "--out", "exists and is not an empty folder: choose a new folder "
                                 "(logs are never written over or mixed)"))
    # a missing parent is created when the logs are written (the one rule for output folders)
    parent = existing_folder(out_dir.parent if str(out_dir.parent) else Path("."), str(out_dir), "--out")
    try:  # the logs go into a temporary folder beside it first: can one be made there?
        os.rmdir(tempfile.mkdtemp(prefix=".locoplan-probe-", dir=parent))
    except OSError as exc:
        raise InputError(Problem(str(out_dir), "--out", f"cannot write into {parent}: {exc.strerror or exc}")) from None


def log_folder_head(spec: SimulationSpec) -> dict[str, str]:
    """The files of the log folder known before any run: the route and rolling-stock files as given."""
    files: dict[str, str] = {"route.yaml": spec.route_file.read_text(encoding="utf-8")}
    for path in spec.vehicle_files.values():
        files[f"rolling_stock/{path.name}"] = path.read_text(encoding="utf-8")
    return files


def log_folder_tail(sim: SimulatedLogs) -> dict[str, str]:
    """The files of the log folder made after the runs: a consist file per mass, manifest.yaml, drivers.csv
    (and the logs, when ``sim`` holds them)."""
    files: dict[str, str] = {}
    for name, consist in sim.consists.items():
        files[name] = consist_yaml(consist)
    for name, log in sim.logs.items():
        files[name] = log_csv_text(log)
    files[MANIFEST_NAME] = manifest_text(sim.manifest, "# Driver logs made by a simulator: synthetic, not real driving.\n")
    files["drivers.csv"] = drivers_csv_text(sim.driver_ids, sim.driver_rows)
    return files


def simulate_drivers(spec: SimulationSpec, out_dir: Path, progress=None) -> SimulationSummary:
    """Simulate the drivers (``learn.drivers.simulate_logs``) and write the log folder (manifest.yaml,
    route.yaml, consists/, rolling_stock/, logs/, drivers.csv) whole or not at all: each log is written as
    it is made (memory does not grow with the number of logs) into ``PartialFolder``, a sibling renamed
    into place when complete. The folder is checked before any run is simulated."""
    out_dir = Path(out_dir)
    spec.check()
    check_out_dir(out_dir)
    with PartialFolder(out_dir) as folder:
        for rel, text in log_folder_head(spec).items():
            folder.write(rel, text)
        sim = simulate_logs(spec, progress, sink=lambda rel, log: folder.write(rel, log_csv_text(log)))
        for rel, text in log_folder_tail(sim).items():
            folder.write(rel, text)
        folder.commit()
    return SimulationSummary(out_dir, sim.n_runs, sim.groups,
                             [{"driver_id": i, **r} for i, r in zip(sim.driver_ids, sim.driver_rows)], folder.removed)


INCOMPLETE_MARK = "INCOMPLETE.txt"
"""The file inside a log folder still being written (``PartialFolder``)."""


class PartialFolder:
    """A log folder being written: ``NAME.incomplete-PID`` beside the folder ``NAME`` it becomes, renamed into
    place by ``commit`` (a rename is whole or not at all). On an error it is removed; a process killed
    outright (``kill -9``, a power cut) cannot remove it, so it has a name that says what it is, holds
    ``INCOMPLETE.txt`` saying so, and is locked (``flock``) while its process lives: the next
    ``drivers simulate --out NAME`` removes every unlocked ``NAME.incomplete-*`` that holds that file."""

    def __init__(self, out_dir: Path):
        self.out_dir = Path(out_dir)
        self.parent = self.out_dir.parent if str(self.out_dir.parent) else Path(".")
        self.stem = f"{self.out_dir.name[:200]}.incomplete-"
        self.path = self.parent / f"{self.stem}{os.getpid()}"
        self.removed: list[Path] = []
        self._fd: int | None = None
        self._made: set[Path] = set()

    def __enter__(self) -> "PartialFolder":
        make_folder(self.parent, str(self.out_dir), "--out")
        try:
            self.removed = self._remove_stale()
            os.mkdir(self.path)  # 0777 less the umask, as any folder
            self._fd = os.open(self.path, os.O_RDONLY | os.O_DIRECTORY)
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            self.write(INCOMPLETE_MARK, f"This folder is being written by 'locoplan drivers simulate --out {self.out_dir}' "
                       f"(process {os.getpid()}).\nWhen complete it is renamed to {self.out_dir.name}. If that process no "
                       "longer runs, it was stopped before it finished:\ndelete this folder, or run drivers simulate with "
                       f"--out {self.out_dir} again, which removes it.\n")
        except BaseException as exc:
            self._abandon(exc)
            raise
        return self

    def write(self, rel: str, text: str) -> None:
        f = self.path / rel
        if f.parent not in self._made:
            f.parent.mkdir(parents=True, exist_ok=True)
            self._made.add(f.parent)
        f.write_text(text, encoding="utf-8")

    def commit(self) -> None:
        os.unlink(self.path / INCOMPLETE_MARK)
        if self.out_dir.exists():
            self.out_dir.rmdir()  # empty (checked): replaced by the complete folder
        os.rename(self.path, self.out_dir)
        self._close()

    def __exit__(self, kind, exc, tb) -> None:
        if exc is not None:
            self._abandon(exc)

    def _abandon(self, exc: BaseException) -> None:
        """Remove the folder; an OSError (a full disk, a file-size limit) becomes the message."""
        self._close()
        shutil.rmtree(self.path, ignore_errors=True)
        if isinstance(exc, OSError):
            raise InputError(Problem(str(self.out_dir), "--out", f"cannot write the logs: {exc.strerror or exc} "
                                     "(nothing was written)")) from None

    def _close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # the lock goes with it
            self._fd = None

    def _remove_stale(self) -> list[Path]:
        """Remove the ``NAME.incomplete-*`` folders left by runs that were killed (unlocked, marked)."""
        removed = []
        for entry in self.parent.iterdir():
            if not (entry.name.startswith(self.stem) and entry.name[len(self.stem):].isdigit()) or entry.is_symlink() \
                    or not entry.is_dir() or not (entry / INCOMPLETE_MARK).is_file():
                continue
            fd = os.open(entry, os.O_RDONLY | os.O_DIRECTORY)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                shutil.rmtree(entry)  # under the lock
                removed.append(entry)
            except BlockingIOError:
                pass  # another drivers simulate is writing it now
            finally:
                os.close(fd)
        return removed
