"""The ahead-of-time compiled kernels (``locoplan.sim.native``) against numba's JIT functions they are built
from: the same source through the same compiler, so the calculator's and the DP's numbers agree to
1e-12 relative; arguments of the wrong type are refused with a TypeError (the compiled functions check
nothing themselves); a failed build falls back to the JIT functions and is not retried; parallel first
runs build the module once."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from locoplan.sim import native
from locoplan.optimize.dp import PricedDriveSolver
from locoplan.sim.calculator import TractionCalculator
from locoplan.sim.records import DPCells, Forces

ROOT = Path(__file__).resolve().parents[1]
RTOL = 1e-12


@pytest.fixture(scope="module")
def both():
    """(native, jit) namespaces; native is built in this session's cache folder if need be."""
    if not native.enabled():
        pytest.skip("LOCOPLAN_NATIVE=0")
    nat = native.kernels()
    assert nat.source.startswith("native "), nat.source  # the build works on this machine (gcc, setuptools)
    return nat, native._jit("test")


def _with(monkeypatch, ns):
    monkeypatch.setattr(native, "_kernels", ns)


def test_calculator_agrees_with_the_jit_kernel(freight, both, monkeypatch):
    route, train = freight
    calc = TractionCalculator(route, train)
    rng = np.random.default_rng(5)
    seq = tuple("TKTCTCKCB")
    X = np.sort(rng.uniform(0, route.length_m, (80, len(seq) - 1)), axis=1)
    cruise = rng.uniform(40, 80, 80)
    out = []
    for ns in both:
        _with(monkeypatch, ns)
        out.append((calc.evaluate(seq, X, profile=True), calc.evaluate(("T", "C", "B"), X[:, :2],
                                                                        cruise_kmh=cruise)))
    (a, a2), (b, b2) = out
    assert 0 < a.feasible.sum() < len(X)  # the sample mixes verdicts
    for x, y in ((a, b), (a2, b2)):
        np.testing.assert_array_equal(x.reason_code, y.reason_code)
        np.testing.assert_allclose(x.running_time_s, y.running_time_s, rtol=RTOL, equal_nan=True)
        np.testing.assert_allclose(x.traction_energy_kwh, y.traction_energy_kwh, rtol=RTOL)
    for field in ("t_s", "v_kmh", "traction_kn", "brake_kn", "event_m"):
        np.testing.assert_allclose(getattr(a.profile, field), getattr(b.profile, field), rtol=RTOL, atol=1e-12,
                                   equal_nan=True, err_msg=field)


def test_dp_agrees_with_the_jit_kernel(freight, both, monkeypatch):
    route, train = freight
    calc = TractionCalculator(route, train)
    drives, lows = [], []
    for ns in both:
        _with(monkeypatch, ns)
        solver = PricedDriveSolver(calc)
        lows.append(solver._low.copy())
        drives.append([solver.solve(p) for p in (0.02, 0.2, 2.0)])
    np.testing.assert_allclose(lows[0], lows[1], rtol=RTOL)
    for a, b in zip(*drives):
        np.testing.assert_array_equal(a.controls, b.controls)
        np.testing.assert_allclose(a.speed_kmh, b.speed_kmh, rtol=RTOL)
        assert a.time_s == pytest.approx(b.time_s, rel=RTOL) and a.energy_kwh == pytest.approx(b.energy_kwh, rel=RTOL)
    assert drives[0][0].time_s > drives[0][2].time_s  # a higher price of time: a faster drive


def test_the_estar_kernels_divide_as_numpy_does(both):
    """A slack or a distance to a bound at zero gives the interior-point kernels an infinite or NaN
    barrier and multipliers (which the line search rejects), not a ZeroDivisionError, ahead of time as
    with the JIT (``error_model="numpy"``)."""
    from locoplan.sim.records import IPMLayout

    n, N = 3, 1
    lay = IPMLayout(np.array([[0, 1, 2]], dtype=np.int64), np.zeros(n, dtype=bool), np.arange(n, dtype=np.int64),
                    np.arange(0, n, 2, dtype=np.int64), np.zeros(n), np.full(n, 2.0), np.arange(n, dtype=np.int64),
                    np.array([n], dtype=np.int64))
    x, s, sc = np.array([0.0, 0.5, 2.0]), np.array([[0.0, 1.0]]), np.array([1.0])
    e, g, c = np.zeros(N), -s, -sc
    for ns in both:
        logs, theta = getattr(ns.ipm_merit, "fn", ns.ipm_merit)(lay, x, s, sc, e, g, c)
        assert logs == -np.inf and theta == 0.0
        y, z, zc, zl, zu, dl, du = np.zeros(N), np.ones((N, 2)), np.ones(1), np.ones(n), np.ones(n), np.empty(n), np.empty(n)
        getattr(ns.ipm_update, "fn", ns.ipm_update)(lay, x, s, sc, 1.0, np.zeros(N), 1.0, np.zeros((N, 2)), np.zeros(1),
                                                    np.zeros(n), np.zeros(n), 0.1, y, z, zc, zl, zu, dl, du)
        assert z[0, 0] == np.inf and zl[0] == np.inf and dl[0] == 0.0 and du[2] == 0.0


def test_wrong_argument_types_are_refused(both):
    """The ahead-of-time functions read memory as their signature says: every array, inside the records
    too, is checked for dtype, rank and contiguity before the call."""
    nat, _ = both
    h = np.full(4, 100.0)
    cells = DPCells(h, h, np.ones(4), np.full(5, 100.0), np.arange(5.0))
    forces = Forces(5000.0, h, h, h, h, h, h, 1.0, 0.1, 0.01)
    with pytest.raises(TypeError, match=r"argument 0.h must be a C-contiguous float64 array of rank 1, not float32"):
        nat.stall_boundary(cells._replace(h=h.astype(np.float32)), forces, np.zeros(5))
    with pytest.raises(TypeError, match=r"argument 1.tf must be a C-contiguous float64 array"):
        nat.stall_boundary(cells, forces._replace(tf=np.zeros(8)[::2]), np.zeros(5))
    with pytest.raises(TypeError, match="argument 2"):
        nat.stall_boundary(cells, forces, np.zeros(10)[::2])  # not contiguous: an output must not be a copy
    with pytest.raises(TypeError, match="argument 0 must be a DPCells, not tuple"):
        nat.stall_boundary(tuple(cells), forces, np.zeros(5))
    with pytest.raises(TypeError, match="expected 3 arguments"):
        nat.stall_boundary(cells, forces)


def test_a_failed_build_falls_back_to_jit_and_is_not_retried(tmp_path, monkeypatch, freight):
    monkeypatch.setenv("LOCOPLAN_NATIVE_DIR", str(tmp_path))
    monkeypatch.setattr(native, "_kernels", None)
    monkeypatch.setattr(native.sys, "executable", "/bin/false")  # the build's interpreter fails at once
    ns = native.kernels()
    assert ns.source.startswith("numba-jit (the ahead-of-time build failed")
    failed = list(tmp_path.glob("*.failed"))
    assert len(failed) == 1 and "/bin/false" in failed[0].read_text()
    assert not list(tmp_path.glob("locoplan_kernels_*.so")) and not list(tmp_path.glob(".build-*"))
    monkeypatch.setattr(native, "_kernels", None)
    assert "failed before" in native.kernels().source  # not retried
    route, train = freight  # and the calculator runs on the JIT functions
    assert 900 < TractionCalculator(route, train).fastest_time_s < 1500


@pytest.mark.slow
def test_parallel_first_runs_build_the_module_once(tmp_path):
    """Two processes start on an empty folder at once: one builds under the lock, the other waits and loads
    the same module; both then run the calculator on it."""
    code = ("from locoplan.sim import native; from locoplan.io.load import load_route, load_train; "
            "from locoplan.sim.calculator import TractionCalculator; import numpy as np; "
            "r = load_route('routes/freight-20km.yaml'); t = load_train('configs/consists/HXD1-C80x50.yaml'); "
            "x = TractionCalculator(r, t).fastest_time_s; "
            "print(native.kernels().source); print(repr(float(x)))")
    env = {**os.environ, "LOCOPLAN_NATIVE_DIR": str(tmp_path)}
    env.pop("LOCOPLAN_NATIVE", None)
    procs = [subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=900) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-2000:] for o in outs]
    lines = [o[0].split("\n") for o in outs]
    built = [p for p in tmp_path.glob("locoplan_kernels_*") if p.suffix != ".sha256"]
    assert len(built) == 1 and not list(tmp_path.glob("*.failed"))
    assert native._intact(built[0])  # with its record of size and hash beside it
    assert lines[0][0] == lines[1][0] == f"native {built[0]}"
    assert lines[0][1] == lines[1][1]
    assert "numba" not in subprocess.run([sys.executable, "-c", code + "; import sys; print(sorted(sys.modules))"],
                                         cwd=ROOT, env=env, capture_output=True, text=True).stdout.split("\n")[2]


@pytest.mark.parametrize("where", ["not writable", "a file"])
def test_an_unusable_folder_falls_back_to_jit(tmp_path, monkeypatch, where):
    folder = tmp_path / "native"
    if where == "a file":
        folder.write_text("not a folder")
    else:  # as a read-only folder is for a user (root may write anywhere): the lock file cannot be opened
        def refuse(path):
            raise PermissionError(13, "Permission denied", str(path))
        monkeypatch.setattr(native, "_locked", refuse)
    monkeypatch.setenv("LOCOPLAN_NATIVE_DIR", str(folder))
    monkeypatch.setattr(native, "_kernels", None)
    assert native.kernels().source.startswith("numba-jit (cannot ")


def test_a_build_with_no_room_is_not_recorded_as_failed(tmp_path, monkeypatch):
    """A build that failed for want of room (a full disk, a file-size limit) falls back to the JIT functions and
    leaves no ``.failed``: the next command tries again (a failure of the code itself is kept, above)."""
    builder = tmp_path / "no-room-python"
    builder.write_text("#!/bin/sh\necho 'OSError: [Errno 27] File too large' >&2\nexit 1\n")
    builder.chmod(0o755)
    monkeypatch.setenv("LOCOPLAN_NATIVE_DIR", str(tmp_path / "native"))
    monkeypatch.setattr(native, "_kernels", None)
    monkeypatch.setattr(native.sys, "executable", str(builder))
    ns = native.kernels()
    assert ns.source.startswith("numba-jit (the ahead-of-time build in") and "had no room" in ns.source
    assert "File too large" in ns.source and not list((tmp_path / "native").glob("*.failed"))


@pytest.mark.parametrize("tolerant", [True, False])
def test_a_numba_cache_that_cannot_be_saved_is_let_go(tmp_path, tolerant):
    """numba saves what it compiles (cache=True); under a file-size limit the save fails with an OSError that
    names no file, from the call that compiled. The JIT fallback lets it go: the function runs (without, the
    call fails: the test can tell)."""
    (tmp_path / "tiny_kernel.py").write_text("from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n")
    code = (("from locoplan.sim import native; native._tolerant_numba_cache()\n" if tolerant else "")
            + "import tiny_kernel\nprint(tiny_kernel.f(41))\n")

    def limit():
        import resource
        import signal

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (256, 256))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"}
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
                         preexec_fn=limit)
    if tolerant:
        assert res.returncode == 0 and res.stdout.strip() == "42", res.stderr[-2000:]
    else:
        assert res.returncode != 0 and "File too large" in res.stderr


# --- what is read back from the cache folder is checked: the module against its record, a failed build by its cause
def _builder(tmp_path, body: str) -> str:
    """A stand-in for the build's interpreter (``python -m locoplan.sim.native OUT_DIR NAME``: $3 is OUT_DIR)."""
    script = tmp_path / "builder.sh"
    script.write_text("#!/bin/sh\n" + body)
    script.chmod(0o755)
    return str(script)


def _good_module(both) -> Path:
    nat, _ = both
    path = Path(nat.source.split(" ", 1)[1])
    assert native._intact(path) and native.record_path(path).is_file()  # the build recorded its size and hash
    return path


@pytest.mark.parametrize("damage", ["truncated", "bit flipped", "no record", "record of another file"])
def test_a_damaged_module_is_never_loaded_but_built_again(tmp_path, monkeypatch, both, damage):
    """A module whose size or content differs from its build's record (a truncated copy, a flipped bit, another file)
    would crash every process that imports it (SIGBUS, SIGSEGV): it is removed and built again, never loaded."""
    good = _good_module(both)
    folder = tmp_path / "native"
    folder.mkdir()
    copy, record = folder / good.name, native.record_path(folder / good.name)
    data = bytearray(good.read_bytes())
    record.write_text(native.record_path(good).read_text())
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "bit flipped":
        data[len(data) // 3] ^= 0x10
    elif damage == "no record":
        record.unlink()
    else:
        record.write_text('{"bytes": 5, "sha256": "00"}')
    copy.write_bytes(bytes(data))
    monkeypatch.setenv("LOCOPLAN_NATIVE_DIR", str(folder))
    monkeypatch.setattr(native, "_kernels", None)
    monkeypatch.setattr(native.sys, "executable", _builder(tmp_path, f'cp "{good}" "$3/"\n'))
    ns = native.kernels()
    assert ns.source == f"native {copy}", ns.source
    assert copy.read_bytes() == good.read_bytes() and native._intact(copy)
    assert not list(folder.glob("*.failed")) and not list(folder.glob(".build-*"))


@pytest.mark.parametrize("cause", ["killed", "out of memory", "timeout"])
def test_a_build_cut_short_by_a_passing_cause_is_tried_again(tmp_path, monkeypatch, cause):
    """A build killed (the out-of-memory killer), out of memory or past its time falls back to the JIT functions and
    leaves no ``.failed``: the next command builds again (a failure of the code itself is kept, above)."""
    body = {"killed": "kill -9 $$\n", "out of memory": "echo 'MemoryError' >&2\nexit 1\n", "timeout": "exec sleep 30\n"}[cause]
    folder = tmp_path / "native"
    folder.mkdir()
    (folder / ".build-left-by-a-killed-command").mkdir()  # a build folder of a command killed before: removed
    monkeypatch.setenv("LOCOPLAN_NATIVE_DIR", str(folder))
    monkeypatch.setattr(native, "_kernels", None)
    monkeypatch.setattr(native, "BUILD_TIMEOUT_S", 2.0)
    monkeypatch.setattr(native.sys, "executable", _builder(tmp_path, body))
    ns = native.kernels()
    assert ns.source.startswith("numba-jit (the ahead-of-time build in") and "tried again" in ns.source, ns.source
    assert not list(folder.glob("*.failed")) and not list(folder.glob(".build-*"))
    monkeypatch.setattr(native, "_kernels", None)
    monkeypatch.setattr(native.sys, "executable", _builder(tmp_path, "exit 1\n"))  # tried again: now a real failure
    assert "failed, see" in native.kernels().source and list(folder.glob("*.failed"))


def test_the_build_process_ends_with_its_parent(tmp_path):
    """kill -9 of a command while it builds the kernels: the compiler's process ends too (it would run on, reparented,
    and leave its folder)."""
    import signal
    import time

    pid_file = tmp_path / "builder.pid"
    builder = _builder(tmp_path, f'echo $$ > "{pid_file}"\nexec sleep 120\n')
    code = f"import sys; from locoplan.sim import native; sys.executable = {builder!r}; native.kernels()"
    env = {**os.environ, "LOCOPLAN_NATIVE_DIR": str(tmp_path / "native"), "PYTHONPATH": str(ROOT)}
    env.pop("LOCOPLAN_NATIVE", None)
    parent = subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not (pid_file.is_file() and pid_file.read_text().strip()) and time.monotonic() < deadline:
        time.sleep(0.1)
    child = int(pid_file.read_text())
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10
    while _alive(child) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(child), "the build's process outlived its parent"


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False
