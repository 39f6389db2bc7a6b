"""E* by a second, independent method: trapezoidal collocation on a fine uniform grid.

The check on the Radau solver (``ocp.bound``): ``locoplan bound --check`` and benchmarks/bench_bound.py
print both. Nothing else of ``locoplan.ocp`` is used: its own grid (every breakpoint of the route plus a uniform step of
at most ``step_m``), the speed ``v`` as state (not ``e``), the trapezoidal rule for the work-energy
balance of each cell, ``dt = 2 ds / (v0 + v1)`` for time (exact for constant acceleration), forces at
the nodes, traction and the electric brake cut at every node inside or on a neutral span (the air brake
works there). Only the physics formulas are
shared (``locoplan.physics``: resistance, force curves, gravity, the train-length-aware gradient and
limits), since the check is of the optimal control, not of the model. CasADi + IPOPT solve it.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

import time as _time
from dataclasses import dataclass

from ..physics.gradient import equivalent_gradient_permille, point_gradient_knots
from ..physics.resistance import train_resistance_kn
from ..physics.traction import gradient_force_kn, max_force_kn
from ..sim.calculator import ModelOptions, limit_kmh_at, neutral_spans_m
from .interrupt import solve_nlp

CHECK_STEPS_M = (10.0, 5.0)
"""The two grid steps of :func:`trapezoid_energy` [m]."""
SHORT_CHECK_STEPS_M = (2.5, 1.25)
"""The steps on a route up to ``SHORT_CHECK_M`` long: a short leg that mostly coasts has an E* of a few
kWh, and at 5 m the scheme's own error there is up to 2 % (CN_Songjiazhuang_Yizhuang leg 3, point mass)."""
SHORT_CHECK_M = 5000.0


@dataclass(frozen=True)
class TrapezoidEstimate:
    """E* on two grids: ``energy_kwh`` on the finer, ``coarse_kwh`` on the coarser, and the relative
    difference of the two as the estimate's accuracy (the scheme converges from above, about at first
    order where a control switches: the finer grid's error is at most about that difference)."""

    energy_kwh: float
    coarse_kwh: float
    accuracy: float
    steps_m: tuple[float, float]
    nodes: int
    solve_time_s: float


def trapezoid_energy(route, train, time_s: float, options: ModelOptions | None = None,
                     steps_m: tuple[float, float] | None = None, ignore_neutral: bool = False) -> TrapezoidEstimate:
    """E* of ``train`` on ``route`` in ``time_s`` by :func:`trapezoid_min_energy` on two grids (``steps_m``,
    default ``CHECK_STEPS_M``, ``SHORT_CHECK_STEPS_M`` on a short route); raises ``InfeasibleError`` when
    IPOPT finds no solution."""
    from ..errors import InfeasibleError

    if steps_m is None:
        steps_m = SHORT_CHECK_STEPS_M if route.length_m <= SHORT_CHECK_M else CHECK_STEPS_M
    t = _time.perf_counter()
    runs = [trapezoid_min_energy(route, train, time_s, options, step, ignore_neutral) for step in steps_m]
    for r in runs:
        if not r["success"]:
            raise InfeasibleError(f"trapezoidal collocation found no run in {time_s:g} s on {route.name} ({r['status']})")
    coarse, fine = runs[0]["energy_kwh"], runs[1]["energy_kwh"]
    return TrapezoidEstimate(fine, coarse, abs(coarse - fine) / max(abs(fine), 1e-9), tuple(steps_m), runs[1]["nodes"],
                             _time.perf_counter() - t)


def trapezoid_min_energy(route, train, time_s: float, options: ModelOptions | None = None, step_m: float = 10.0,
                         ignore_neutral: bool = False) -> dict:
    """Least traction energy [kWh] of ``train`` on ``route`` in ``time_s`` [s] on a ``step_m`` grid.

    Returns ``energy_kwh``, ``time_s`` (of the solution), the grid ``s_m``, speeds ``v_kmh``, forces
    ``F_kn`` / ``B_kn``, IPOPT's ``status`` and the grid size."""
    options = options or ModelOptions()
    L = float(train.length_m)
    strip = options.strip
    length = float(route.length_m)
    knots, _ = point_gradient_knots(route)
    pts = [0.0, length, *knots, *[b for x in route.speed_limits for b in (x.from_m, x.to_m)]]
    if strip:
        pts += [k + L for k in knots] + [x.to_m + L for x in route.speed_limits]
    else:
        pts += [c.from_m + L for c in route.curves]
    spans = [] if ignore_neutral else neutral_spans_m(route, L if strip else 0.0)
    for a, b in spans:
        pts += [a, b]
    n_uni = int(np.ceil(length / step_m))
    s = np.unique(np.concatenate([np.linspace(0.0, length, n_uni + 1), np.clip(pts, 0.0, length)]))
    s = s[np.concatenate([[True], np.diff(s) > 1e-6])]
    n = s.size
    h = np.diff(s)
    mid = 0.5 * (s[1:] + s[:-1])
    grav = gradient_force_kn(equivalent_gradient_permille(route, mid, L, strip), train.mass_t)  # exact cell means
    lim_cell = np.minimum(limit_kmh_at(route, mid, L if strip else None), train.max_speed_kmh) / 3.6
    lim_node = np.minimum(np.concatenate([[lim_cell[0]], lim_cell]), np.concatenate([lim_cell, [lim_cell[-1]]]))
    m_eff = train.inertial_mass_t if options.rotating_mass is None else train.mass_t * (1 + options.rotating_mass)
    b_speed, b_force = train.brake_curve(options.air_brake)
    cut = np.zeros(n, dtype=bool)
    for a, b in spans:
        cut |= (s >= a - 1e-9) & (s <= b + 1e-9)

    v = ca.MX.sym("v", n)
    t = ca.MX.sym("t", n)
    F = ca.MX.sym("F", n)
    B = ca.MX.sym("B", n)
    vk = ca.SX.sym("vk")
    fb = ca.Function("fb", [vk], [ca.vertcat(max_force_kn(3.6 * vk, train.traction_speed_kmh, train.traction_kn),
                                              max_force_kn(3.6 * vk, b_speed, b_force),
                                              train_resistance_kn(3.6 * vk, train.resistance_kn))])
    caps = fb.map(n)(v.T)
    fmax, bmax, res = caps[0, :].T, caps[1, :].T, caps[2, :].T
    # in a neutral span the main breaker is open: traction and the electric brake are cut, the wagons'
    # air brake works (the same rule as the calculator's and the LGR model's)
    air_kn = np.asarray(train.air_brake_kn, float)
    has_air = bool(options.air_brake and np.any(air_kn > 0))
    if cut.any():
        air_cap = (ca.Function("air", [vk], [max_force_kn(3.6 * vk, train.air_brake_speed_kmh, air_kn)]).map(n)(v.T).T
                   if has_air else ca.DM.zeros(n, 1))
        c = ca.DM(cut.astype(float))
        bmax = (1 - c) * bmax + c * air_cap
    net = F - B - res  # at the nodes, without gravity
    work = 0.5 * (net[:-1] + net[1:]) * ca.DM(h) - ca.DM(grav * h)
    g_energy = 0.5 * (v[1:] ** 2 - v[:-1] ** 2) * m_eff - work
    g_time = (t[1:] - t[:-1]) * (v[1:] + v[:-1]) - 2 * ca.DM(h)
    g_path = ca.vertcat(F - fmax, B - bmax)
    obj = ca.sum1(0.5 * (F[:-1] + F[1:]) * ca.DM(h)) / 3600.0
    w = ca.vertcat(v, t, F, B)
    nlp = {"x": w, "f": obj / 100.0, "g": ca.vertcat(g_energy / 100.0, g_time / 10.0, g_path)}
    solver = ca.nlpsol("trap", "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                                               "ipopt.tol": 1e-9, "ipopt.max_iter": 3000})
    f_top, b_top = float(np.max(train.traction_kn)), float(np.max(b_force))
    lbv, ubv = np.zeros(n), lim_node.copy()
    ubv[0] = ubv[-1] = 0.0
    lbt, ubt = np.zeros(n), np.full(n, time_s)
    ubt[0] = 0.0
    ubF = np.where(cut, 0.0, f_top)
    ubB = np.where(cut & (not has_air), 0.0, b_top)
    lbx = np.concatenate([lbv, lbt, np.zeros(n), np.zeros(n)])
    ubx = np.concatenate([ubv, ubt, ubF, ubB])
    # start from a trapezoidal speed profile at a uniform fraction of the limit that takes time_s
    v0 = np.minimum(lim_node, 0.9 * length / time_s * 1.3)
    ramp = np.minimum(np.sqrt(2 * 0.1 * s), np.sqrt(2 * 0.2 * (length - s)))
    v0 = np.minimum(v0, ramp)
    t0 = np.concatenate([[0.0], np.cumsum(2 * h / np.maximum(v0[1:] + v0[:-1], 0.5))])
    t0 = t0 * min(1.0, time_s / t0[-1])
    x0 = np.concatenate([v0, t0, np.where(cut, 0.0, 0.3 * f_top), np.zeros(n)])
    n_g = 2 * (n - 1) + 2 * n
    lbg = np.concatenate([np.zeros(2 * (n - 1)), np.full(2 * n, -np.inf)])
    ubg = np.zeros(n_g)
    sol = solve_nlp(solver, x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    x = np.asarray(sol["x"]).ravel()
    st = solver.stats()
    return {"energy_kwh": float(sol["f"]) * 100.0, "time_s": float(x[2 * n - 1]), "s_m": s, "v_kmh": x[:n] * 3.6,
            "F_kn": x[2 * n:3 * n], "B_kn": x[3 * n:], "status": st.get("return_status"),
            "success": bool(st.get("success")), "nodes": n}
