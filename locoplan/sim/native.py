"""The compiled loops, loaded without numba's start-up cost.

The calculator's distance loop (``sim/kernel.py``) and the DP drive (``optimize/dp_kernel.py``) are
numba functions. Even from numba's on-disk cache, using them imports numba and initialises its
compiler in every process: about 0.5-0.7 s on the reference machine, more than all the work of
``locoplan optimize routes/freight-20km.yaml``. So the first time they are needed on a machine, their
entry points are compiled *ahead of time* (``numba.pycc``, same source, same compiler) into one
extension module in the cache folder; every later process imports that module, which needs numpy only.

- Folder: ``$LOCOPLAN_NATIVE_DIR``, else ``$LOCOPLAN_CACHE_DIR/native``, else
  ``~/.cache/locoplan/native``. The module's name holds a hash of the kernels' source, the Python
  version and numpy's version: an edit or an upgrade builds a new one, never loads a stale one.
- The build runs once, in a subprocess (its compiler output never reaches a command's stdout), under a
  file lock (parallel workers wait for one build instead of racing), and lands by an atomic rename.
- No C compiler, no setuptools, a numba without ``pycc``, or ``LOCOPLAN_NATIVE=0``: the numba JIT
  functions (``cache=True``) are used instead; same code, same results (``tests/test_native.py``). A
  failed build leaves a ``.failed`` file with its log and is not retried until that file is removed; a build
  that failed for a passing cause (killed, out of memory, out of room, past its time) leaves none and is
  tried again by the next command. The build's process ends with the process that started it.
- Beside the module, ``<name>.sha256`` records its size and content hash (written by the build). A module
  whose record is missing or differs (truncated, a flipped bit, another file put there) is never loaded: it
  is removed and built again. (A damaged extension module would crash every process that imports it.)

The entry points take records (``sim/records.py``); their signatures are built from the records' field
types, written once there. The ahead-of-time functions check nothing about their arguments (a float32
array would be read as float64), so every call goes through :class:`_Checked`, which verifies each
array's dtype, rank and contiguity first, inside records too.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import importlib.machinery
import importlib.util
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from .records import FIELD_TYPES, CellModel, Cells, CycleCells, CycleTables, DPCells, Forces, IPMLayout, Outputs, Plans

_F, _I, _A1, _A2, _A3, _A4 = "f8", "i8", "f8[:]", "f8[:, :]", "f8[:, :, :]", "f8[:, :, :, :]"

ENTRY_POINTS: dict[str, tuple[str, str, str, tuple]] = {
    # name: (module, function, return type, argument types: a type string or a record class)
    "run_plans": ("locoplan.sim.kernel", "run_plans", "void", (Cells, Forces, Plans, Outputs)),
    "braking_envelope": ("locoplan.sim.kernel", "braking_envelope", "i8", (Cells, Forces, _I, _A1, _A1, "i8[:]")),
    "cycle_speeds": ("locoplan.sim.kernel", "cycle_speeds", "UniTuple(f8, 2)", (_F, _F, _F, _F, _F, _F, Forces)),
    "stall_boundary": ("locoplan.optimize.dp_kernel", "_stall_boundary", "void", (DPCells, Forces, _A1)),
    "backward": ("locoplan.optimize.dp_kernel", "_backward", "void", (DPCells, Forces, _F, _F, _F, _A4, _A1)),
    "forward": ("locoplan.optimize.dp_kernel", "_forward", "UniTuple(f8, 2)",
                (DPCells, Forces, _F, _F, _F, _A4, _A1, "i8[:]", _A1)),
    "replan_forward": ("locoplan.optimize.replan_kernel", "forward_from", "UniTuple(f8, 2)",
                       (DPCells, Forces, _A1, "f8[:, :, :, :, :]", _A1, _I, _I, _I, _I, _F, _F, _F, _I, _F, "i8[:]",
                        _A1, _A1, _A1)),
    "replan_step": ("locoplan.optimize.replan_kernel", "capped_step", "UniTuple(f8, 2)",
                    (_F, _I, _F, _F, _F, _F, _I, Forces)),
    "cycle_prepare": ("locoplan.optimize.cycle_kernel", "cycle_prepare", "void", (CycleCells, Forces, CycleTables)),
    "cycle_backward": ("locoplan.optimize.cycle_kernel", "cycle_backward", "void",
                       (CycleCells, Forces, _F, _A3, CycleTables)),
    "cycle_forward": ("locoplan.optimize.cycle_kernel", "cycle_forward", "UniTuple(f8, 3)",
                      (CycleCells, Forces, _F, _A3, CycleTables, "i8[:]", "i8[:]", _A1, _A1, _A2, "i8[:]")),
    "cycle_forward_from": ("locoplan.optimize.cycle_kernel", "cycle_forward_from", "UniTuple(f8, 3)",
                           (CycleCells, Forces, _F, _A3, CycleTables, _F, _A3, CycleTables, _I, _I, _F, _F, _I, _F, _F,
                            _I, "i8[:]", "i8[:]", _A1, _A1, _A1, _A2, _A2, "i8[:]")),
    "band_assemble": ("locoplan.ocp.band_kernel", "band_assemble", "void",
                      ("f8[:, :]", _I, "i8[:, :]", "f8[:, :, :]", "f8[:, :, :]", "f8[:, :]", "f8[:, :]", "i8[:]", _A1,
                       "i8[:]", _A1, "i8[:]")),
    "band_factor": ("locoplan.ocp.band_kernel", "band_factor", "i8", ("f8[:, :]", _I, _I, "i8[:]")),
    "band_solve": ("locoplan.ocp.band_kernel", "band_solve", "void", ("f8[:, :]", _I, _I, "i8[:]", "f8[:, :]")),
    "cell_values": ("locoplan.ocp.cell_kernel", "cell_values", "f8", (CellModel, _A1, _A1, _A2, _A1, _A3)),
    "cell_derivatives": ("locoplan.ocp.cell_kernel", "cell_derivatives", "void",
                         (CellModel, _A1, _A3, _A2, _A2, _A3, _A3)),
    "cell_hessian": ("locoplan.ocp.cell_kernel", "cell_hessian", "void", (CellModel, _A1, _A3, _A1, _A2, _A1, _A3)),
    "ipm_errors": ("locoplan.ocp.ipm_kernel", "ipm_errors", "UniTuple(f8, 6)",
                   (IPMLayout, _A2, _A2, _A1, _A3, _A2, _A3, _A1, _A1, _A1, _A1, _A2, _A2, _A1, _A1, _A1, _A1, _A1)),
    "ipm_newton": ("locoplan.ocp.ipm_kernel", "ipm_newton", "void",
                   (IPMLayout, _A2, _A2, _A1, _A3, _A2, _A2, _A1, _A1, _A1, _A1, _A1, _A1, _A2, _A1, _A1, _A1, _A1, _A1,
                    _A2, _A2)),
    "ipm_rhs": ("locoplan.ocp.ipm_kernel", "ipm_rhs", "void",
                (IPMLayout, _A1, _A1, _A3, _A2, _A2, _A2, _A2, _A1, _A1, _A1, _A1, _F, _A1)),
    "ipm_curvature": ("locoplan.ocp.ipm_kernel", "ipm_curvature", "UniTuple(f8, 2)",
                      (IPMLayout, _A1, _A3, _A3, _A2, _A1, _F, _A1, _A2)),
    "ipm_steps": ("locoplan.ocp.ipm_kernel", "ipm_steps", "UniTuple(f8, 3)",
                  (IPMLayout, _A1, _A3, _A2, _A1, _A2, _A2, _A1, _A2, _A1, _A1, _A1, _A1, _A1, _A2, _A1, _A1, _F, _F,
                   "b1", _A1, _A1, _A2, _A1, _A2, _A1, _A1, _A1)),
    "ipm_merit": ("locoplan.ocp.ipm_kernel", "ipm_merit", "UniTuple(f8, 2)", (IPMLayout, _A1, _A2, _A1, _A1, _A2, _A1)),
    "ipm_mean_complementarity": ("locoplan.ocp.ipm_kernel", "ipm_mean_complementarity", "f8",
                                 (IPMLayout, _F, _F, _A1, _A1, _A2, _A2, _A1, _A1, _A2, _A2, _A1, _A1, _A1, _A1, _A1,
                                  _A1)),
    "ipm_update": ("locoplan.ocp.ipm_kernel", "ipm_update", "void",
                   (IPMLayout, _A1, _A2, _A1, _F, _A1, _F, _A2, _A1, _A1, _A1, _F, _A1, _A2, _A1, _A1, _A1, _A1, _A1)),
}
_SOURCES = ("sim/constants.py", "sim/records.py", "sim/kernel.py", "optimize/dp_kernel.py", "optimize/cycle_kernel.py",
            "optimize/replan_kernel.py",
            "ocp/band_kernel.py",
            "ocp/cell_kernel.py", "ocp/ipm_kernel.py", "sim/native.py",
            "model/conditions.py", "physics/units.py", "physics/resistance.py", "physics/braking.py",
            "physics/backend.py")
BUILD_TIMEOUT_S = 900.0

_kernels = None


def enabled() -> bool:
    return os.environ.get("LOCOPLAN_NATIVE", "1").strip().lower() not in ("0", "no", "off", "false")


def native_dir() -> Path:
    if os.environ.get("LOCOPLAN_NATIVE_DIR"):
        return Path(os.environ["LOCOPLAN_NATIVE_DIR"])
    root = os.environ.get("LOCOPLAN_CACHE_DIR") or str(Path.home() / ".cache" / "locoplan")
    return Path(root) / "native"


def module_name() -> str:
    """``locoplan_kernels_<hash>``: the kernels' source, this file's signatures, Python and numpy."""
    digest = hashlib.sha256()
    here = Path(__file__).resolve().parents[1]  # the locoplan package
    for rel in _SOURCES:
        digest.update((here / rel).read_bytes())
    digest.update(f"{sys.version}|{np.__version__}|{sys.platform}".encode())
    return f"locoplan_kernels_{digest.hexdigest()[:16]}"


class _Checked:
    """An ahead-of-time function behind a check of its arguments' types (it makes none itself)."""

    _DTYPES = {"f8": np.float64, "i8": np.int64, "i4": np.int32, "i1": np.int8, "b1": np.bool_}

    def __init__(self, name: str, fn, arg_types: tuple):
        self.name, self.fn = name, fn
        self.spec = [self._spec(a) for a in arg_types]
        self._checked: dict[int, tuple] = {}  # id -> (record, its checked copy): the records last passed

    RECORDS_KEPT = 16
    """Records (immutable tuples of arrays) checked once and kept, with a reference so that their ids stay theirs:
    a re-planner passes the same cells, forces and tables to thousands of calls."""

    @classmethod
    def _spec(cls, a):
        if isinstance(a, type):  # a record: the spec of each field
            return (a, [cls._spec(f) for f in FIELD_TYPES[a]])
        base = a.split("[")[0]
        return (cls._DTYPES[base], a.count(":") if "[" in a else 0)

    def __call__(self, *args):
        if len(args) != len(self.spec):
            raise TypeError(f"{self.name}: expected {len(self.spec)} arguments, got {len(args)}")
        return self.fn(*(self._convert(a, spec, f"argument {i}") for i, (a, spec) in enumerate(zip(args, self.spec))))

    def _convert(self, a, spec, where: str):
        kind, rank = spec
        if isinstance(rank, list):  # a record
            kept = self._checked.get(id(a))
            if kept is not None and kept[0] is a:
                return kept[1]
            if type(a) is not kind:
                raise TypeError(f"{self.name}: {where} must be a {kind.__name__}, not {type(a).__name__}")
            out = kind(*(self._convert(x, s, f"{where}.{f}") for x, s, f in zip(a, rank, kind._fields)))
            if len(self._checked) >= self.RECORDS_KEPT:
                self._checked.pop(next(iter(self._checked)))
            self._checked[id(a)] = (a, out)
            return out
        if rank:
            if not (isinstance(a, np.ndarray) and a.dtype == kind and a.ndim == rank and a.flags.c_contiguous
                    and a.flags.aligned):
                got = f"{a.dtype} rank {a.ndim}" if isinstance(a, np.ndarray) else type(a).__name__
                raise TypeError(f"{self.name}: {where} must be a C-contiguous {np.dtype(kind)} array of "
                                f"rank {rank}, not {got}")
            return a
        return kind(a).item()


class _Namespace:
    def __init__(self, functions: dict, source: str):
        self.__dict__.update(functions)
        self.source = source  # "native <path>" or "numba-jit (<why>)"


def kernels() -> _Namespace:
    """The compiled entry points (``run_plans``, ``braking_envelope``, ``stall_boundary``, ``backward``,
    ``forward``, the cycle DP's ``cycle_prepare``, ``cycle_backward``, ``cycle_forward``, ``cycle_forward_from``, ``band_assemble``, ``band_factor``, ``band_solve``, E*'s
    ``cell_values``, ``cell_derivatives``, ``cell_hessian`` and the interior-point method's ``ipm_*``)."""
    global _kernels
    if _kernels is None:
        why = "LOCOPLAN_NATIVE=0"
        if enabled():
            try:
                _kernels = _load_native()
            except _Unavailable as exc:
                why = str(exc)
        if _kernels is None:
            _kernels = _jit(why)
    return _kernels


class _Unavailable(Exception):
    pass


def _jit(why: str) -> _Namespace:
    _tolerant_numba_cache()
    funcs = {}
    for name, (mod, fn, _, _) in ENTRY_POINTS.items():
        funcs[name] = getattr(importlib.import_module(mod), fn)
    return _Namespace(funcs, f"numba-jit ({why})")


def _tolerant_numba_cache() -> None:
    """numba saves each function it compiles (``cache=True``) beside its source or in ``NUMBA_CACHE_DIR``, and a
    save that fails (a full disk, a file-size limit, a read-only folder) raises from the call that compiled it,
    an OSError that names no file: a command would fail on a cache. The function is compiled and in use by then,
    so a failed save is only a cache lost (the next process compiles again) and is let go. numba removes its
    half-written file itself, and reads an index entry whose file is missing as no entry."""
    from numba.core import caching

    save = caching.Cache.save_overload
    if getattr(save, "locoplan_tolerant", False):
        return

    def save_overload(self, sig, data):
        try:
            save(self, sig, data)
        except OSError:
            pass
    save_overload.locoplan_tolerant = True
    caching.Cache.save_overload = save_overload


_NO_ROOM = ("[Errno 27]", "[Errno 28]", "[Errno 122]", "File too large", "No space left on device", "Disk quota exceeded")
"""A build log with one of these failed for want of room, not for the code: no ``.failed`` is kept for it."""


_PASSING = ("MemoryError", "Cannot allocate memory", "std::bad_alloc", "out of memory", "[Errno 12]", "Killed")
"""A build log with one of these failed for want of memory, not for the code: no ``.failed`` is kept for it."""


def record_path(path: Path) -> Path:
    """The record of a built module's size and content hash, beside it: ``<name>.sha256``."""
    return path.with_name(path.name.split(".")[0] + ".sha256")


def _digest(path: Path) -> dict:
    h = hashlib.sha256()
    size = 0
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
            size += len(chunk)
    return {"bytes": size, "sha256": h.hexdigest()}


def _intact(path: Path) -> bool:
    """The module at ``path`` is there and is the file its build recorded (size, then content hash)."""
    import json

    try:
        want = json.loads(record_path(path).read_text())
        if not isinstance(want, dict) or os.stat(path).st_size != want.get("bytes"):
            return False
        return _digest(path) == {"bytes": want["bytes"], "sha256": want.get("sha256")}
    except (OSError, ValueError):
        return False


def _load_native() -> _Namespace:
    folder = native_dir()
    name = module_name()
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    path = folder / f"{name}{suffix}"
    failed = folder / f"{name}.failed"
    if not _intact(path):
        if failed.is_file():
            raise _Unavailable(f"the ahead-of-time build failed before, see {failed}")
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _Unavailable(f"cannot create {folder}: {exc.strerror}") from None
        try:
            with _locked(folder / ".lock"):
                if not _intact(path) and not failed.is_file():
                    for old in (path, record_path(path)):  # damaged, or of a build that was cut short
                        with contextlib.suppress(FileNotFoundError):
                            old.unlink()
                    _remove_stale_builds(folder)
                    _build(folder, name, path, failed)
        except OSError as exc:  # a folder that cannot be written (read-only, full, not a folder)
            raise _Unavailable(f"cannot build in {folder}: {exc.strerror or exc}") from None
        if not _intact(path):
            raise _Unavailable(f"the ahead-of-time build failed, see {failed}")
    spec = importlib.util.spec_from_file_location(name, path)
    try:
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    except ImportError as exc:
        raise _Unavailable(f"cannot load {path}: {exc}") from None
    funcs = {n: _Checked(n, getattr(mod, n), args) for n, (_, _, _, args) in ENTRY_POINTS.items()}
    return _Namespace(funcs, f"native {path}")


@contextlib.contextmanager
def _locked(lock_path: Path):
    try:
        import fcntl
    except ImportError:  # not POSIX: the atomic rename alone keeps a half-written module out
        yield
        return
    with open(lock_path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _remove_stale_builds(folder: Path) -> None:
    """Remove the temporary folders of builds whose process was killed (called under the lock, which every build
    holds: no build is running)."""
    import shutil

    for stale in folder.glob(".build-*"):
        if stale.is_dir():
            shutil.rmtree(stale, ignore_errors=True)


def _die_with_parent() -> None:
    """In the build's process (Linux): the kernel kills it when the process that started it dies, so that a killed
    command leaves no compiler running."""
    try:
        import ctypes
        import signal

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _build(folder: Path, name: str, path: Path, failed: Path) -> None:
    """Compile in a subprocess into a temporary folder, then rename into place with its record of size and hash
    (or write ``.failed``; not for a passing cause)."""
    if sys.stderr is not None and sys.stderr.isatty():
        print("locoplan: compiling the kernels for this machine (once, about a minute)...",
              file=sys.stderr, flush=True)
    with tempfile.TemporaryDirectory(dir=folder, prefix=".build-") as tmp:
        cmd = [sys.executable, "-m", "locoplan.sim.native", tmp, name]
        try:
            # this very locoplan (the hash is of its source), whatever the child's sys.path would find first
            path_env = os.pathsep.join(p for p in (str(Path(__file__).resolve().parents[2]),
                                                   os.environ.get("PYTHONPATH", "")) if p)
            out = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S,
                                 env={**os.environ, "LOCOPLAN_NATIVE": "0", "PYTHONPATH": path_env},
                                 preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None)
            log, ok = out.stdout + out.stderr, out.returncode == 0
            passing = out.returncode < 0  # killed by a signal (the kernel's out-of-memory killer, a user)
            if passing:
                log += f"\nthe build was killed by signal {-out.returncode}"
        except subprocess.TimeoutExpired as exc:
            log, ok, passing = f"TimeoutExpired: {exc}", False, True  # a loaded machine: tried again next time
        except (OSError, subprocess.SubprocessError) as exc:
            log, ok = f"{type(exc).__name__}: {exc}", False
            passing = isinstance(exc, OSError) and exc.errno in (12, 11)  # ENOMEM, EAGAIN: no process could be made
        built = Path(tmp) / path.name
        if ok and built.is_file():
            import json

            record = record_path(path)
            staged = Path(tmp) / record.name
            staged.write_text(json.dumps(_digest(built)))
            os.replace(staged, record)
            os.replace(built, path)
        elif any(text in log for text in _NO_ROOM):  # a full disk or a file-size limit: tried again next time
            raise _Unavailable(f"the ahead-of-time build in {folder} had no room ({_no_room_line(log)}); "
                               "it is tried again by the next command")
        elif passing or any(text in log for text in _PASSING):  # memory, a kill, a timeout: tried again next time
            line = next((x.strip() for x in reversed(log.splitlines()) if x.strip()), "")[:200]
            raise _Unavailable(f"the ahead-of-time build in {folder} was cut short ({line}); it is tried again by "
                               "the next command")
        else:
            failed.write_text(f"{' '.join(cmd)}\n\n{log}")


def _no_room_line(log: str) -> str:
    """The line of a build log that says the disk or the file-size limit was in the way."""
    return next((line.strip() for line in reversed(log.splitlines()) if any(t in line for t in _NO_ROOM)), "")[:200]


def _compile_here(out_dir: str, name: str) -> None:
    """The build itself (``python -m locoplan.sim.native OUT_DIR NAME``): numba.pycc on the numba functions."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pycc's pending-deprecation notice
        from numba.pycc import CC
    from numba.pycc import compiler as pycc_compiler

    cc = CC(name)
    cc.output_dir = out_dir
    cc.verbose = False
    error_models = {}
    for export, (mod, fn, ret, args) in ENTRY_POINTS.items():
        func = getattr(importlib.import_module(mod), fn)
        error_models[func.py_func] = func.targetoptions.get("error_model", "python")
        cc.export(export, _signature(ret, args))(func.py_func)
    # pycc compiles every export with the same flags; each keeps its JIT function's error model here (the
    # E* kernels divide as numpy does, a division by zero giving inf, not an exception: same results as JIT)
    compile_extra = pycc_compiler.compile_extra

    def compile_with_error_model(typingctx, targetctx, func, args, return_type, flags, *rest, **kw):
        flags = flags.copy()
        flags.error_model = error_models.get(func, "python")
        return compile_extra(typingctx, targetctx, func, args, return_type, flags, *rest, **kw)
    pycc_compiler.compile_extra = compile_with_error_model
    try:
        cc.compile()
    finally:
        pycc_compiler.compile_extra = compile_extra


def _numba_type(a):
    """A numba type of an argument spec: a type string ("f8[:]" = a C-contiguous float64 vector) or a
    record class (a ``NamedTuple`` of its fields' types)."""
    from numba import types

    if isinstance(a, type):
        return types.NamedTuple([_numba_type(f) for f in FIELD_TYPES[a]], a)
    ty = eval(a, {}, vars(types))  # noqa: S307 (our own type strings: "f8", "f8[:, :]", ...)
    if isinstance(ty, types.Array):
        ty = ty.copy(layout="C")
    return ty


def _signature(ret: str, args: tuple):
    from numba import types
    from numba.core.typing import signature

    return signature(eval(ret, {}, vars(types)), *(_numba_type(a) for a in args))  # noqa: S307


if __name__ == "__main__":
    _compile_here(sys.argv[1], sys.argv[2])
