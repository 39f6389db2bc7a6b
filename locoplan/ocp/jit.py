"""Compiled point functions for the LGR transcription, built in the background and cached on disk.

The transcription (``radau.py``) evaluates a few small CasADi ``SX`` functions (constraints, their
Jacobian, the objective, the Lagrangian's Hessian at one collocation point) over every point of the
mesh in every IPOPT iteration. CasADi's ``SX`` virtual machine runs them at a few ns per instruction;
compiled to C they run 4-6x faster, which on a 50 km line with ~2000 points is a third of the solve.

Compiling costs ~0.5-0.8 s of gcc, so it is done *beside* the solve, never in front of it:
:func:`start` writes the functions' C code, and, unless a shared library of the same code (same
hash) is already in the cache folder (``$LOCOPLAN_CACHE_DIR/jit``, default ``~/.cache/locoplan/jit``),
starts gcc in a background thread (a separate process: it runs on the other core while IPOPT works).
The job's ``ready()`` returns the compiled functions once the library is there, ``None`` until then;
the caller keeps using the ``SX`` functions meanwhile. No compiler, a failed compile or
``LOCOPLAN_JIT=0``: ``None`` for good, and everything runs as before (same numbers to rounding).
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path

COMPILE_FLAGS = ("-O1", "-shared", "-fPIC")
"""-O1: compiles in ~0.7 s and runs as fast as -O2 here (measured, benchmarks/bench_mpoc.py)."""
COMPILE_TIMEOUT_S = 120.0

_JOBS: dict[str, "_Job"] = {}
_LOCK = threading.Lock()


def _cache_dir() -> Path:
    root = os.environ.get("LOCOPLAN_CACHE_DIR", str(Path.home() / ".cache" / "locoplan"))
    return Path(root) / "jit" if root else Path(tempfile.gettempdir()) / f"locoplan-jit-{os.getuid()}"


def enabled() -> bool:
    return os.environ.get("LOCOPLAN_JIT", "1").strip().lower() not in ("0", "no", "off", "false") and \
        shutil.which(os.environ.get("CC", "gcc")) is not None


class _Job:
    """One shared library: compiled in a thread unless it was already on disk."""

    def __init__(self, digest: str, source: str, names: tuple[str, ...]):
        self.names = names
        self.lib = _cache_dir() / f"points_{digest}.so"
        self.failed = False
        self.functions = None
        self.thread = None
        if not self.lib.is_file():
            self.thread = threading.Thread(target=self._compile, args=(source,), daemon=True)
            self.thread.start()

    def _compile(self, source: str) -> None:
        try:
            self.lib.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=self.lib.parent) as tmp:
                src = Path(tmp) / "points.c"
                src.write_text(source)
                out = Path(tmp) / "points.so"
                subprocess.run([os.environ.get("CC", "gcc"), *COMPILE_FLAGS, str(src), "-o", str(out), "-lm"],
                               check=True, capture_output=True, timeout=COMPILE_TIMEOUT_S)
                os.replace(out, self.lib)  # atomic: another process never loads half a library
        except (OSError, subprocess.SubprocessError):
            self.failed = True

    def wait(self) -> None:
        if self.thread is not None:
            self.thread.join()

    def ready(self):
        if self.functions is not None or self.failed:
            return self.functions
        if self.thread is not None and self.thread.is_alive():
            return None
        if not self.lib.is_file():
            self.failed = True
            return None
        import casadi as ca

        try:
            self.functions = tuple(ca.external(n, str(self.lib)) for n in self.names)
        except RuntimeError:
            self.failed = True
        return self.functions


@atexit.register
def _finish_compiles() -> None:
    """A short command may end while gcc still runs: let it finish (a second or so) so that the next
    command finds the library, rather than leave a half-made folder behind."""
    for job in list(_JOBS.values()):
        if job.thread is not None:
            job.thread.join(timeout=10.0)


def forget() -> None:
    """Forget this process's compile jobs (a benchmark timing a first solve, compile included, again)."""
    with _LOCK:
        _JOBS.clear()


def start(functions, helpers=()) -> "_Job | None":
    """Start compiling the CasADi ``functions`` (or find them compiled on disk); None when there is
    no compiler or compiling is off. ``job.ready()`` gives the compiled functions (same names,
    inputs and outputs) once they are there, None until then or when the compile failed.
    ``helpers`` go into the library without being loaded: CasADi finds ``jac_NAME`` there and
    differentiates the compiled ``NAME`` with it."""
    if not enabled():
        return None
    import casadi as ca

    names = tuple(f.name() for f in functions)
    cg = ca.CodeGenerator("points.c", {"with_header": False})
    for f in (*functions, *helpers):
        cg.add(f)
    source = cg.dump()
    digest = hashlib.sha256(("\0".join(COMPILE_FLAGS) + source).encode()).hexdigest()[:24]
    with _LOCK:
        job = _JOBS.get(digest)
        if job is None:
            job = _JOBS[digest] = _Job(digest, source, names)
    return job
