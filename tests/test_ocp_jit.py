"""The compiled point functions of the LGR transcription (locoplan/ocp/jit.py): they compute what the
SX functions compute, and without a working compiler everything falls back to the SX functions."""

import numpy as np
import pytest

from locoplan.io.load import load_route, load_train
from locoplan.ocp import jit
from locoplan.ocp import radau
from locoplan.ocp.train_energy import build_problem
from locoplan.sim.calculator import ModelOptions


@pytest.fixture(scope="module")
def sx_functions(root):
    route = load_route(root / "routes/freight-20km.yaml")
    train = load_train(root / "configs/consists/HXD1-C80x50.yaml")
    model = build_problem(route, train, ModelOptions(), 1500.0).problem.model
    radau._point_functions(model, ("gravity_kn", "powered"))
    return radau._POINTS[id(model)][2]  # the SX functions (the compiled ones may be ready already)


def _random_inputs(f, rng):
    """Inputs in the range the NLP sees: e = v^2/2 up to (80 km/h)^2/2, forces up to 2000 kN."""
    args = []
    for i in range(f.n_in()):
        a = rng.uniform(0.5, 2.0, f.size_in(i))
        if i == 0:  # w = (e, t, F, B, s, ds/dtau)
            a = np.array([[rng.uniform(1, 250)], [rng.uniform(0, 1500)], [rng.uniform(0, 800)],
                          [rng.uniform(0, 2000)], [rng.uniform(0, 2e4)], [rng.uniform(1, 300)]])
        args.append(a)
    return args


def test_compiled_functions_equal_the_sx_ones(sx_functions, tmp_path, monkeypatch):
    if not jit.enabled():
        pytest.skip("no C compiler: the SX functions are used (the fallback is tested below)")
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path))
    jit.forget()
    con, jac, _, hess = sx_functions
    job = jit.start((con, jac, hess), helpers=(con.jacobian(),))
    job.wait()
    fast = job.ready()
    assert fast is not None and [f.name() for f in fast] == [con.name(), jac.name(), hess.name()]
    assert len(list((tmp_path / "jit").glob("points_*.so"))) == 1  # kept for the next process
    rng = np.random.default_rng(7)
    for sx, compiled in zip((con, jac, hess), fast):
        for _ in range(20):
            args = _random_inputs(sx, rng)
            a, b = np.asarray(sx(*args)), np.asarray(compiled(*args))
            assert a.shape == b.shape
            np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * max(1.0, float(np.max(np.abs(a)))))
    # the same code again (another process, another solve): found on disk, nothing compiled
    jit.forget()
    again = jit.start((con, jac, hess), helpers=(con.jacobian(),))
    assert again.thread is None and again.ready() is not None


@pytest.mark.parametrize("env", [{"LOCOPLAN_JIT": "0"}, {"CC": "no-such-compiler-here"}])
def test_no_compiler_means_the_sx_functions(sx_functions, tmp_path, monkeypatch, env):
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path))
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    jit.forget()
    assert jit.start(sx_functions[:2]) is None


def test_a_failing_compile_falls_back(sx_functions, tmp_path, monkeypatch):
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # a "compiler" that always fails
    jit.forget()
    job = jit.start(sx_functions[:2])
    job.wait()
    assert job.ready() is None and job.failed
    assert not list((tmp_path / "jit").glob("points_*.so"))
