"""Transcription / problem / solve layers on the seed-000 minimum-time cases (Tables 2-3).

The reference is the exact minimum running time of the bang-cruise-bang optimum (full traction to
the 11.1 m/s limit, cruise, full brake), integrated here with ``scipy.integrate.quad`` from the
seed's own formulas (eq. 1-3, Table 1), independently of ``locoplan``.
"""

from __future__ import annotations

import dataclasses
import math
import time

import casadi as ca
import numpy as np
import pytest

from locoplan.errors import InfeasibleError, InputError, LocoplanError
from locoplan.ocp import MinTimeTrainProblem, resimulate, gauss_paper_problem, solve_min_time
from locoplan.ocp.cvp import solve_cvp
from locoplan.ocp.gauss import (
    gauss_interval,
    gauss_mesh,
    lagrange_control_map,
    paired_control_map,
    single_mesh,
    solve_gauss,
)
from locoplan.ocp.nlp import Guess
from locoplan.ocp.phase import MultiPhaseProblem, Phase, PhaseModel
from locoplan.ocp.recollocation import recollocated_groups, slope_changes
from oracles import G, LIMIT, seed000_exact, seed000_resistance_kn

GRADES = (0.0, 30.0)
RUNS = [("cvp", 20), ("cvp", 40), ("gpm", 34), ("gpm", 48), ("two-stage", 17), ("two-stage", 24)]


EXACT = {g: seed000_exact(g)[4] for g in GRADES}


def test_reference_minimum_times():
    ta, sa, tb, sb, t, _ = seed000_exact(0.0)
    assert ta == pytest.approx(5.995, abs=1e-3) and sa == pytest.approx(33.30, abs=1e-2)
    assert tb == pytest.approx(6.748, abs=1e-3) and sb == pytest.approx(37.41, abs=1e-2)
    assert t == pytest.approx(141.507, abs=1e-3)
    assert EXACT[30.0] == pytest.approx(141.56, abs=5e-3)


@pytest.fixture(scope="module")
def runs():
    out = {}
    for grade in GRADES:
        problem = gauss_paper_problem(grade)
        for method, nodes in RUNS:
            t0 = time.perf_counter()
            sol = solve_min_time(problem, method, nodes)
            wall = time.perf_counter() - t0
            out[grade, method, nodes] = (problem, sol, resimulate(problem, sol), wall)
    return out


def test_seed_problem_matches_table1():
    p = gauss_paper_problem(30.0)
    assert p.mass_t == 284.0 and p.f_max_kn == 532.0 and p.b_max_kn == 461.0 and p.length_m == 1500.0
    assert p.speed_limit_ms == pytest.approx(LIMIT)
    for v in (0.0, 5.0, 11.1):
        assert p.resistance(v) == pytest.approx(seed000_resistance_kn(v), rel=1e-12)
    assert p.grade_force_kn == pytest.approx(284 * G * 0.03)


# ---- the best method: two-stage with the hp stage 2 -----------------------------------------------


@pytest.mark.parametrize("grade", GRADES)
@pytest.mark.parametrize("nodes", [17, 24])
@pytest.mark.slow
def test_two_stage_reaches_exact_minimum(runs, grade, nodes):
    problem, sol, rs, wall = runs[grade, "two-stage", nodes]
    assert sol.success, sol.status
    assert abs(sol.objective_s - EXACT[grade]) < 0.02
    # re-simulation of the solved control agrees with the NLP and respects the limits
    assert abs(rs.time_to_length_s - sol.objective_s) < 0.05
    assert abs(rs.distance_at_tf_m - 1500.0) < 0.05 and abs(rs.final_speed_ms) < 0.01
    assert rs.max_overspeed_kmh < 0.01 and rs.max_control_excess_kn < 0.01
    # stage 1 is the seed's paired stage (Tables 2-3: 17 / 34 and 24 / 48), stage 2 merges
    s1 = sol.stages[0]
    assert (s1.control_nodes, s1.state_nodes, s1.segments) == (nodes, 2 * nodes, 1)
    assert sol.state_nodes == 2 * nodes and sol.control_nodes < nodes
    # breakpoints sit on the switches of the exact solution
    ta, _, tb, _, t, _ = seed000_exact(grade)
    assert sol.breakpoints_s[0] == pytest.approx(ta, abs=0.05)
    assert sol.breakpoints_s[-1] == pytest.approx(t - tb, abs=0.05)
    # (solve times are measured by benchmarks/ocp_study.py, not asserted here)


def test_two_stage_on_a_route_too_short_for_the_limit():
    """60 m, level (the limit needs ~71 m): full traction, then full brake from the peak speed."""
    exact = seed000_exact(0.0, 60.0)[4]
    problem = dataclasses.replace(gauss_paper_problem(0.0), length_m=60.0)
    sol = solve_min_time(problem, "two-stage", 17)
    assert sol.success and abs(sol.objective_s - exact) < 0.02
    rs = resimulate(problem, sol)
    assert abs(rs.time_to_length_s - sol.objective_s) < 0.05 and rs.max_overspeed_kmh < 0.01


@pytest.mark.slow
def test_best_method_is_the_best(runs):
    for grade in GRADES:
        best = min(runs[grade, m, n][1].objective_s for m, n in RUNS)
        assert runs[grade, "two-stage", 17][1].objective_s <= best + 1e-6
        assert best >= EXACT[grade] - 0.02


# ---- the baselines, reported honestly ---------------------------------------------------------------


@pytest.mark.parametrize("grade", GRADES)
@pytest.mark.parametrize("nodes", [34, 48])
def test_classical_gpm(runs, grade, nodes):
    problem, sol, rs, wall = runs[grade, "gpm", nodes]
    assert sol.success and sol.control_nodes == sol.state_nodes == nodes
    # one global polynomial cannot resolve the corners: within 0.2 s, not 0.02 s
    assert abs(sol.objective_s - EXACT[grade]) < 0.2
    # the NLP is consistent with its own polynomial control ...
    raw = resimulate(problem, sol, clip=False)
    assert abs(raw.time_to_length_s - sol.objective_s) < 0.05
    # ... but that polynomial leaves the traction / brake bounds between the LG points
    assert rs.max_control_excess_kn > 50.0
    # (solve times are measured by benchmarks/ocp_study.py, not asserted here)


@pytest.mark.parametrize("grade", GRADES)
@pytest.mark.parametrize("nodes", [20, 40])
def test_cvp(runs, grade, nodes):
    problem, sol, rs, wall = runs[grade, "cvp", nodes]
    assert sol.success and sol.control_nodes == nodes and sol.time_s.size == nodes
    # a piecewise-linear control on a uniform grid is a restriction: never below the optimum
    assert EXACT[grade] - 1e-3 < sol.objective_s < EXACT[grade] + 3.0
    assert abs(rs.time_to_length_s - sol.objective_s) < 0.05
    assert abs(rs.distance_at_tf_m - 1500.0) < 0.05
    assert rs.max_overspeed_kmh < 0.25  # the limit is imposed at the RK4 points only
    # (solve times are measured by benchmarks/ocp_study.py, not asserted here)


def test_cvp_improves_with_nodes(runs):
    for grade in GRADES:
        assert runs[grade, "cvp", 40][1].objective_s < runs[grade, "cvp", 20][1].objective_s


@pytest.mark.slow
def test_seed_global_stage2():
    """``stage2="global"`` is the seed's stage 2 on the same global LG mesh: better than stage 1,
    close to the seed's own 141.59-141.75 s, but not within 0.02 s."""
    for grade in GRADES:
        sol = solve_min_time(gauss_paper_problem(grade), "two-stage", 24, stage2="global")
        assert sol.success
        assert len(sol.stages) == 2 and sol.stages[1].segments == 1
        assert sol.objective_s < sol.stages[0].objective_s
        assert EXACT[grade] < sol.objective_s < EXACT[grade] + 0.35
        assert sol.control_nodes < 24


def test_solution_is_frozen_and_read_only(runs):
    _, sol, _, _ = runs[0.0, "two-stage", 17]
    with pytest.raises(dataclasses.FrozenInstanceError):
        sol.objective_s = 0.0
    for arr in (sol.time_s, sol.position_m, sol.speed_ms, sol.control_kn):
        assert not arr.flags.writeable
    assert sol.time_s.size == sol.position_m.size == sol.speed_ms.size == sol.control_kn.size
    assert sol.time_s[0] == 0.0 and sol.time_s[-1] == pytest.approx(sol.objective_s)
    assert sol.position_m[-1] == pytest.approx(1500.0, abs=1e-6) and sol.speed_ms[-1] == pytest.approx(0.0, abs=1e-6)
    assert np.all(np.diff(sol.time_s) > 0)


# ---- the transcription layer on a smooth problem with a known answer --------------------------------


def _lq(tf=1.0, dynamics=lambda x, u, t, p: [u[0]]):
    """min int_0^1 (x^2 + u^2) dt, x' = u, x(0) = 1, x(1) free: J = tanh(1), x = cosh(1-t)/cosh(1).
    One phase with a free end held at ``tf`` by its bounds (the problem notion of every transcription)."""
    model = PhaseModel(states=("x",), controls=("u",), dynamics=dynamics,
                       integrand=lambda x, u, t, p: x[0] ** 2 + u[0] ** 2, state_scale=(1.0,), control_scale=(1.0,))
    phase = Phase("lq", 0.0, tf, model, lambda t: {}, state_lower=(-10.0,), state_upper=(10.0,),
                  control_lower=(-10.0,), control_upper=(10.0,))
    return MultiPhaseProblem((phase,), initial_state=(1.0,), final_lower=(-math.inf,), final_upper=(math.inf,),
                             free_end=(tf, tf))


def _flat_guess():
    return Guess(np.array([0.0, 1.0]), np.array([[1.0, 0.5]]), np.array([[-1.0, -0.5]]), 1.0)


def test_gpm_transcription_is_spectrally_accurate():
    exact = math.tanh(1.0)
    errors = []
    for n in (3, 5, 8):
        r = solve_gauss(_lq(), single_mesh(n), _flat_guess())
        assert r.success
        errors.append(abs(r.objective - exact))
    assert errors[-1] < 1e-10 and errors[0] > errors[1] > errors[2]
    r = solve_gauss(_lq(), single_mesh(10), _flat_guess())
    seg = r.segments[0]
    t = seg.lg_times
    np.testing.assert_allclose(seg.support_states[0, 1:], np.cosh(1 - t) / np.cosh(1.0), atol=1e-9)
    assert seg.end_state[0] == pytest.approx(1.0 / np.cosh(1.0), abs=1e-9)  # eq. 24 quadrature


def test_separate_control_nodes_and_hp_mesh():
    exact = math.tanh(1.0)
    # the control on its own 6-node set, the state on 12 LG points
    c_map = lagrange_control_map(12, np.cos(np.linspace(np.pi, 0, 6)))
    r = solve_gauss(_lq(), single_mesh(12, c_map), _flat_guess())
    assert r.success and r.mesh.n_control_params == 6 and r.objective == pytest.approx(exact, abs=1e-6)
    # three fixed segments; and the same with free break points
    mesh = gauss_mesh((gauss_interval(5), 5, 5), (0.3, 0.6))
    r = solve_gauss(_lq(), mesh, _flat_guess())
    assert r.success and r.objective == pytest.approx(exact, abs=1e-10)
    mesh = gauss_mesh((5, 5), (0.5,), ((0.2, 0.8),))
    r = solve_gauss(_lq(), mesh, _flat_guess())
    assert r.success and r.objective == pytest.approx(exact, abs=1e-9)


def test_cvp_transcription():
    r = solve_cvp(_lq(), 21, _flat_guess(), substeps=4)
    assert r.success and r.objective == pytest.approx(math.tanh(1.0), abs=1e-3)


def test_description_takes_casadi_dynamics():
    ocp = _lq(dynamics=lambda x, u, t, p: ca.vertcat(ca.sin(0.0 * x[0]) + u[0]))
    assert solve_gauss(ocp, single_mesh(6), _flat_guess()).success


def test_pairing_and_slope_change():
    c = paired_control_map(6)
    np.testing.assert_array_equal(c, np.kron(np.eye(3), np.ones((2, 1))))
    tau = np.array([-0.9, -0.8, -0.5, -0.4, 0.5, 0.6])
    s = slope_changes(np.array([1.0, 1.0, 0.0]), tau, u_range=1.0)
    np.testing.assert_allclose(s, [0.0, 1.0 / 1.0])  # (U_{l+1} - U_l) / (tau_{2l+1} - tau_{2l-1})
    groups = recollocated_groups(np.array([0.0, 0.01, 1.0, 0.0]), 0.04, 0.04)
    # points (0-based) 0-4: pairs 1-2 and the first point of pair 3 merged (eq. 31); 5, 6: the jump
    # interval [tau_5, tau_7] subdivided (eq. 29); 7-9: pair 4's second point merged with pair 5
    assert groups == [5, 1, 1, 3]


# ---- bad inputs ----------------------------------------------------------------------------------------


def test_bad_node_counts():
    p = gauss_paper_problem(0.0)
    for method, nodes in [("gpm", 1), ("cvp", 0), ("two-stage", 1), ("gpm", 2.5)]:
        with pytest.raises(InputError, match="nodes"):
            solve_min_time(p, method, nodes)
    with pytest.raises(InputError, match="even number of LG points"):
        solve_min_time(p, "two-stage", state_nodes=33)  # N = 32 even in the seed's eq. 26
    with pytest.raises(InputError, match="even number of LG points"):
        paired_control_map(33)
    with pytest.raises(InputError, match="method"):
        solve_min_time(p, "shooting", 20)
    with pytest.raises(InputError, match="stage-2 mode"):
        solve_min_time(p, "two-stage", 5, stage2="bogus")


def test_infeasible_and_invalid_problems():
    base = gauss_paper_problem(30.0)
    with pytest.raises(InfeasibleError, match="cannot start") as err:
        dataclasses.replace(base, f_max_kn=80.0)  # below resistance + 30 per mille grade (~89 kN)
    assert err.value.exit_code == 1
    with pytest.raises(InfeasibleError, match="cannot stop"):
        dataclasses.replace(base, gradient_permille=-200.0, b_max_kn=100.0)
    with pytest.raises(InputError) as err:
        MinTimeTrainProblem(mass_t=-1, resistance_kn=(1, 0, 0), f_max_kn=0, b_max_kn=100,
                            gradient_permille=0, speed_limit_kmh=40, length_m=float("nan"))
    msg = str(err.value)
    assert "mass_t" in msg and "f_max_kn" in msg and "length_m" in msg  # every problem reported
    assert isinstance(err.value, LocoplanError) and err.value.exit_code == 2
    with pytest.raises(InputError, match="resistance_kn"):
        MinTimeTrainProblem(284, (1, 2), 532, 461, 0, 40, 1500)
    # a valid problem, but 2 paired control values cannot go rest-to-rest: too coarse a transcription
    with pytest.raises(InfeasibleError, match="try more nodes"):
        solve_min_time(dataclasses.replace(base, f_max_kn=100.0), "two-stage", 2)


# ---- one framework: the shared problem, mesh and equation of motion -------------------------------------


def test_gauss_mesh_is_the_shared_mesh():
    from locoplan.ocp.mesh import Mesh

    mesh = gauss_mesh((5, 6), (0.5,), ((0.2, 0.8),))
    assert isinstance(mesh, Mesh) and mesh.n_state_nodes == 11 and mesh.n_control_params == 11
    assert mesh.free_breakpoints and mesh.breakpoints == (0.5,) and mesh.breakpoint_bounds == ((0.2, 0.8),)
    moved = mesh.with_breakpoints((0.4,))
    assert moved.breakpoints == (0.4,) and moved.breakpoint_bounds == ((0.2, 0.8),)
    assert moved.intervals[0].s_b == moved.intervals[1].s_a == 0.4
    with pytest.raises(InputError, match="increase strictly"):
        gauss_mesh((5, 5), (1.2,))
    with pytest.raises(InputError, match="its bounds"):
        gauss_mesh((5, 5), (0.5,), ((0.6, 0.8),))
    with pytest.raises(InputError, match="control map"):
        gauss_interval(4, np.ones((3, 1)))


def test_radau_takes_fixed_end_problems_only():
    from locoplan.ocp.mesh import Interval, Mesh
    from locoplan.ocp.radau import RadauTranscription

    with pytest.raises(InputError, match="Gauss transcription"):
        RadauTranscription(gauss_paper_problem(0.0).to_ocp(), Mesh((Interval(0, 0.0, 1.0, 4),)))


def test_min_time_problem_is_one_free_end_phase():
    ocp = gauss_paper_problem(30.0).to_ocp()
    assert len(ocp.phases) == 1 and ocp.free_end[0] == pytest.approx(1500.0 / (39.96 / 3.6))
    assert ocp.phase.model.states == ("s", "v") and ocp.phase.model.integrand is None and ocp.mayer is not None
    with pytest.raises(InputError, match="free end"):
        dataclasses.replace(ocp, phases=ocp.phases * 2)


def test_equation_of_motion_keeps_the_order_of_its_forces():
    from locoplan.physics.motion import acceleration_ms2

    assert acceleration_ms2(100.0, 50.0, 20.0, 30.0) == pytest.approx(1.0)
    f, r, g = 0.1, 0.2, 0.3  # (f - r) - g and f - (r + g) differ in the last bit: the callers' NLPs depend on it
    assert acceleration_ms2(f, 1.0, r, g) == (f - r) - g and acceleration_ms2(f, 1.0, r + g) == f - (r + g)
    x = ca.SX.sym("x")
    assert float(ca.Function("a", [x], [acceleration_ms2(x, 2.0, 1.0)])(3.0)) == 1.0
