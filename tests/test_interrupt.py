"""Ctrl-C stops an optimal-control solve: CasADi catches the KeyboardInterrupt inside IPOPT and returns as
from a failed solve, so without ``ocp.interrupt.solve_nlp`` the refinement went on and wrote its outputs."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import casadi as ca
import pytest

from locoplan.ocp.interrupt import solve_nlp


def _slow_solver(tol: float = 1e-30):
    """An NLP whose every objective evaluation takes 20 ms (a Python callback), so that IPOPT needs
    seconds for the iterations it is allowed (``tol`` unreachable: minutes)."""

    class Slow(ca.Callback):
        def __init__(self):
            ca.Callback.__init__(self)
            self.construct("slow", {"enable_fd": True})

        def get_n_in(self):
            return 1

        def get_n_out(self):
            return 1

        def get_sparsity_in(self, i):
            return ca.Sparsity.dense(2, 1)

        def eval(self, arg):
            time.sleep(0.02)
            x = arg[0]
            return [(1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2]

    f = Slow()
    x = ca.MX.sym("x", 2)
    solver = ca.nlpsol("s", "ipopt", {"x": x, "f": f(x)},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": 3000,
                        "ipopt.tol": tol, "ipopt.hessian_approximation": "limited-memory"})
    return f, solver


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(), reason="signals need the main thread")
def test_ctrl_c_stops_an_ipopt_solve_at_once():
    # Python's own Ctrl-C handler, as in a terminal: pytest started in the background by a shell without
    # job control inherits SIGINT ignored, and then neither Python nor solve_nlp sees a Ctrl-C
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _ctrl_c_stops_an_ipopt_solve_at_once()
    finally:
        signal.signal(signal.SIGINT, previous)


def _ctrl_c_stops_an_ipopt_solve_at_once():
    f, solver = _slow_solver()
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    t0 = time.perf_counter()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        solve_nlp(solver, x0=[-1.2, 1.0])
    took = time.perf_counter() - t0
    timer.join()
    # the interrupt came at 0.5 s; IPOPT stopped at its next iteration, not after its 3000 (minutes)
    assert took < 5.0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the handler is given back
    # without an interrupt the same call returns IPOPT's result (from the optimum, to a tolerance IPOPT
    # reaches there: with 1e-30 it is "acceptable" only after minutes of line searches in the noise)
    _, quick = _slow_solver(tol=1e-8)
    assert solve_nlp(quick, x0=[1.0, 1.0])["f"] < 1e-12


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="watches the command's loaded libraries in /proc")
@pytest.mark.slow
def test_an_interrupted_ocp_command_writes_nothing_and_exits_130(root, tmp_path):
    """The command line: Ctrl-C during the heavy-haul line's minimum-energy solve (about 20 s of solving)
    ends it with exit 130, no --out file and no --json object; stderr says so."""
    out = tmp_path / "run.json"
    env = {**os.environ, "LOCOPLAN_CACHE_DIR": os.environ.get("LOCOPLAN_CACHE_DIR", str(tmp_path / "cache"))}
    proc = subprocess.Popen([sys.executable, "-m", "locoplan", "ocp", str(root / "routes/heavy-haul-60km.yaml"),
                             "--consist", "HXD1x2-C80x100", "--objective", "energy", "--out", str(out), "--json"],
                            cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    maps = f"/proc/{proc.pid}/maps"
    deadline = time.perf_counter() + 300
    while time.perf_counter() < deadline and proc.poll() is None:  # until IPOPT is loaded: the solve under way
        try:
            with open(maps) as fh:
                if "nlpsol_ipopt" in fh.read():  # CasADi's IPOPT plugin: loaded for the first solve
                    break
        except OSError:
            pass
        time.sleep(0.1)
    time.sleep(1.0)
    assert proc.poll() is None, "the command ended before it could be interrupted"
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=600)
    took = time.perf_counter() - t0
    assert proc.returncode == 130, stderr.decode()
    assert stdout == b"" and not out.exists() and not list(tmp_path.glob("*.tmp*"))
    assert b"interrupted: nothing written" in stderr
    assert took < 10.0  # not the rest of the solve (a hang guard; the interrupt ends it within an iteration)
