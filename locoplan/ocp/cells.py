"""E* on the traction calculator's own cells: the minimum-energy problem on a fine grid, solved by a
structured interior-point method, with its accuracy from nested grids.

The discretisation is the calculator's (``sim/calculator.py``): a grid with every breakpoint of the
route (gradient, limit, curve, tunnel, neutral span, and in the strip model the same + the train's
length), each cell with one gravity force (its exact mean), one speed limit and one traction
permission; in each cell constant forces, traction F and braking B, taken at the cell's mean kinetic
energy ``vm = sqrt((v0^2 + v1^2) / 2)``, so that

    M (v1^2 - v0^2) / 2 = h (F - B - R(vm) - G),     dt = 2 h / (v0 + v1),

the work-energy balance of the cell and its time (exact for a constant acceleration). The speeds at the
nodes are bounded by the braking envelope (the highest speed from which full braking keeps every limit
ahead), F by the traction curve at vm (0 in a neutral span), B by full braking at vm (electric where
the catenary feeds it, plus the air brake). The objective is the traction work sum h F [kWh], the running
time at most T, the train at rest at both ends.

Why this scheme: it is second order in the cell length once the two rest points are resolved. At a
rest point the speed goes as sqrt(distance), which a uniform grid resolves only to first order (the
time of the last cell was the largest error on every line tried), so the cells shrink quadratically
towards both ends (``END_GRADING_M``). A switch between conditions inside a cell is a partial force
over the whole cell, which moves the energy by second order only. Nested grids, h and every cell halved,
then give the accuracy: where the optima converge at second order, the difference of two bounds the finer
grid's error (about three times over); where three grids show slower convergence, ``grid_accuracy`` says
more.

The solver (``ocp/ipm.py``) uses the structure: every function reads one cell's variables, so the KKT
matrix is banded and a Newton step costs time linear in the number of cells.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InfeasibleError
from ..physics.braking import full_brake_kn
from ..physics.energy import recovered_energy_kwh
from ..physics.resistance import davis_slope_kn_per_kmh, train_resistance_kn
from ..physics.traction import max_force_kn, rounded_force_curve
from ..physics.units import KJ_PER_KWH, KMH_PER_MS, kmh, ms
from ..sim.calculator import ModelOptions, TractionCalculator
from ..sim.native import kernels
from ..sim.records import CellModel, contiguous
from .ipm import CellDerivatives, CellIPM, CellValues, IPMResult, IPMSettings, _raw

END_GRADING_M = 300.0
"""Length [m] at each end of the route over which the cells shrink quadratically towards the rest point."""
END_GRADING_NODES = 24
"""Nodes in each graded end (the smallest cell is END_GRADING_M / END_GRADING_NODES^2, about 0.5 m)."""
V_FLOOR_MS = 1e-6
ROUNDING_KMH = 0.2
"""The optimiser sees the force curves with their corners rounded over this speed range [km/h] (less where
the curve's points are closer): Newton's method needs a continuous slope, and at a corner (the traction
curve's change from constant force to constant power, say) it otherwise cycles, or stalls, when the
optimum runs at that speed. The rounded curve is nowhere further from the curve than |change of slope| x
width / 8 (0.5 kN at the HXD1's corner) and differs from it only within 0.1 km/h of each point."""


def graded_end_nodes(length_m: float, end_m: float = END_GRADING_M, n: int = END_GRADING_NODES) -> np.ndarray:
    """Extra nodes [m] that make the cells shrink quadratically towards both rest points."""
    end = min(end_m, 0.25 * length_m)
    j = (np.arange(n + 1) / n) ** 2 * end
    return np.concatenate([j, length_m - j])


class CellEnergyProblem:
    """The minimum-energy problem on ``calc``'s cells in ``time_s`` (see the module docstring), in the form
    ``ocp.ipm.CellIPM`` solves: variables ``[v_0, F_0, B_0, v_1, F_1, B_1, ..., v_N]`` scaled to order one,
    one equality (the cell's work-energy balance) and two inequalities (F and B under their curves) per
    cell, and the running time as the one global inequality."""

    FORCES = ("F", "B")
    """A cell's forces, in the order of its variables: traction, then braking (keys of the point's physics)."""
    CAPS = ("Fm", "Bm")
    """Each force's cap, its inequality (keys of the point's physics)."""

    def __init__(self, calc: TractionCalculator, time_s: float, stops_m=(), windows=()):
        """``stops_m``: positions [m] (grid nodes) where the train also stands (a journey's stops);
        ``windows``: ``(position_m, earliest_s, latest_s)`` on the running time at a grid node (either end may
        be None or infinite), besides the total running time ``time_s``."""
        self.calc = calc
        self.time_s = float(time_s)
        tr = calc.train
        h = calc.h_m
        self.N = N = len(h)
        self.h = h
        self.M = calc.m_eff_t
        self.G = calc.gravity_kn
        self.allowed = calc.traction_allowed
        self.v_cap = ms(np.sqrt(np.maximum(calc.e_envelope, 0.0) * 2.0) * KMH_PER_MS)
        # the scales: forces by the largest traction, speeds by the top speed, the objective and the
        # time so that a cell's share of each is of order one
        self.f_ref = float(np.max(tr.traction_kn))
        self.v_ref = max(float(np.max(self.v_cap)), 1.0)
        h_mean = float(np.mean(h))
        self.e_ref = h_mean * self.f_ref / KJ_PER_KWH
        self.t_ref = h_mean / self.v_ref
        powered = self.allowed > 0
        air = np.asarray(calc.air_brake_kn, float)
        has_electric = bool(np.any(np.asarray(calc.electric_brake_kn, float) > 0))
        self.can_brake = (powered & has_electric) | bool(np.any(air > 0))  # the air brake works in a neutral span
        n = 3 * N + 1
        ref = np.empty(n)
        ref[0::3] = self.v_ref
        ref[1::3] = self.f_ref
        ref[2::3] = self.f_ref
        self.ref = ref
        lb = np.zeros(n)
        ub = np.full(n, np.inf)
        ub[0::3] = self.v_cap / self.v_ref
        ub[0] = ub[-1] = 0.0  # at rest at both ends
        for s_stop in stops_m:  # and at every stop
            ub[3 * self._node(s_stop)] = 0.0
        ub[1::3] = np.where(powered, np.inf, 0.0)
        ub[2::3] = np.where(self.can_brake, np.inf, 0.0)
        self.lb, self.ub = lb, ub
        k = np.arange(N)
        self.local = np.column_stack([3 * k, 3 * k + 1, 3 * k + 2, 3 * k + 3])
        pos_x = np.empty(n, dtype=np.int64)
        pos_x[0::3] = 4 * np.arange(N + 1)
        pos_x[1::3] = 4 * k + 1
        pos_x[2::3] = 4 * k + 2
        self.pos_x = pos_x
        self.pos_y = 4 * k + 3
        self._rl = ref[self.local]  # each cell's variables' scales
        # which inequalities are real: F <= Fmax where traction is allowed, B <= Bmax where there is a brake
        self.active = np.column_stack([powered, self.can_brake])
        self._last = None
        self._curves = None
        self._model = None
        self._caps_last = None
        # the global inequalities: (sum over cells of cmask * tau + const) / t_ref <= 0
        rows, const = [np.ones(N)], [-self.time_s]
        for s_w, lo, hi in windows:
            before = (np.arange(N) < self._node(s_w)).astype(float)
            if hi is not None and np.isfinite(hi):
                rows.append(before)
                const.append(-float(hi))
            if lo is not None and np.isfinite(lo) and lo > 0:
                rows.append(-before)
                const.append(float(lo))
        self.cmask, self.cconst = np.array(rows), np.array(const)

    def _node(self, s_m: float) -> int:
        """The grid node at ``s_m`` (it must be one: the grid is built with it)."""
        k = int(np.argmin(np.abs(self.calc.s_m - s_m)))
        if abs(self.calc.s_m[k] - s_m) > 1e-6:
            raise ValueError(f"{s_m} m is not a node of the grid")
        return k

    # ------------------------------------------------------------------ physics at the cells
    def _physics(self, x: np.ndarray):
        """Speeds and forces of every cell at the scaled point ``x``, with the mean speed's and the force
        curves' derivatives (kept for the last point: values, derivatives and Hessian read it in turn)."""
        if self._last is not None and self._last[0] is x:
            return self._last[1]
        xp = x * self.ref
        phys, V = self._speed_terms(xp[0::3])
        ftr, fel, fair = (curve(V) for curve in self._force_curves())
        phys.update({
            "F": xp[1::3], "B": xp[2::3],
            # the caps, d/dvm and d2/dvm2 (the curves are in km/h)
            "Fm": tuple(f * self.allowed * KMH_PER_MS ** i for i, f in enumerate(ftr)),
            "Bm": tuple(full_brake_kn(e, a_, self.allowed) * KMH_PER_MS ** i for i, (e, a_) in enumerate(zip(fel, fair))),
        })
        self._last = (x, phys)
        return phys

    def _speed_terms(self, v: np.ndarray):
        """The cells' speeds from the node speeds ``v`` [m/s]: (``p``, ``q`` at the two nodes, the mean ``vm``,
        the resistance ``R`` there with dR/dvm ``R_v`` [kN s/m] and ``R_vv``), and vm in km/h."""
        p, q = v[:-1], v[1:]
        vm = np.sqrt(np.maximum(0.5 * (p * p + q * q), V_FLOOR_MS ** 2))
        V = kmh(vm)
        tr = self.calc.train
        _, b, c = tr.resistance_kn
        return {"p": p, "q": q, "vm": vm, "R": train_resistance_kn(V, tr.resistance_kn),
                "R_v": KMH_PER_MS * davis_slope_kn_per_kmh(V, b, c), "R_vv": KMH_PER_MS ** 2 * 2.0 * c}, V

    def _force_curves(self):
        """The traction, electric-brake and air-brake curves, rounded (``_rounded``), made once."""
        if self._curves is None:
            calc, tr = self.calc, self.calc.train
            self._curves = tuple(self._rounded(xs, ys) for xs, ys in (
                (tr.traction_speed_kmh, tr.traction_kn), (calc.electric_brake_speed_kmh, calc.electric_brake_kn),
                (calc.air_brake_speed_kmh, calc.air_brake_kn)))
        return self._curves

    @staticmethod
    def _rounded(xs, ys):
        xs = np.asarray(xs, dtype=float)
        width = min(ROUNDING_KMH, 0.5 * float(np.min(np.diff(xs)))) if xs.size > 1 else ROUNDING_KMH
        return rounded_force_curve(xs, ys, width)

    @staticmethod
    def _vm_derivatives(P):
        """d vm / d(v_k, v_k+1) and the second derivatives (pp, pq, qq), kept with the point's physics."""
        if "vm_d" not in P:
            p, q, vm = P["p"], P["q"], P["vm"]
            i2, i4 = 1 / (2 * vm), 1 / (4 * vm ** 3)
            P["vm_d"] = (p * i2, q * i2, i2 - p * p * i4, -p * q * i4, i2 - q * q * i4)
        return P["vm_d"]

    def cost(self) -> tuple[float, ...]:
        """The objective's weight on each force of :data:`FORCES` (the traction work: 1 on F)."""
        return (1.0, 0.0)

    # ------------------------------------------------------------------ the compiled evaluation
    CAP_CURVES = ((0, -1), (1, 2))
    """Each cap of :data:`CAPS` as (the curve fed by the catenary, the curve that works everywhere), indices
    of ``_force_curves`` (traction, electric brake, air brake), -1 for none: ``full_brake_kn`` of the two."""

    def model(self) -> CellModel:
        """The problem as the compiled evaluation reads it (``ocp/cell_kernel.py``), made once."""
        if self._model is None:
            curves = self._force_curves()
            coff = np.cumsum([0] + [c.xs.size for c in curves])
            self._model = contiguous(CellModel(
                len(self.FORCES), self.h, self.G, np.asarray(self.allowed, float), self.active.astype(float),
                self.M, self.f_ref, self.v_ref, self.e_ref, self.t_ref, *self.calc.train.resistance_kn,
                np.array(self.cost(), float), np.array([c[0] for c in self.CAP_CURVES], np.int64),
                np.array([c[1] for c in self.CAP_CURVES], np.int64), np.concatenate([c.xs for c in curves]),
                np.concatenate([c.ys for c in curves]), np.concatenate([c.slopes for c in curves]),
                np.concatenate([c.dslope for c in curves]), coff.astype(np.int64),
                np.array([c.width for c in curves]), np.asarray(self.cmask, float), np.asarray(self.cconst, float)))
        return self._model

    def values(self, x: np.ndarray) -> CellValues:
        """The objective, each cell's equality and inequalities and the global inequalities (compiled:
        :meth:`values_numpy`'s arithmetic cell by cell)."""
        x = np.ascontiguousarray(x, dtype=float)
        e, g, c = np.empty(self.N), np.empty((self.N, len(self.CAPS))), np.empty(len(self.cmask))
        caps = np.empty((self.N, len(self.CAPS), 3))
        f = _raw(kernels().cell_values)(self.model(), x, e, g, c, caps)
        self._caps_last = (x, caps)
        return CellValues(f, e, g, c)

    def _caps(self, x: np.ndarray) -> np.ndarray:
        """The caps at ``x`` (N, q, 3) as :meth:`values` left them there (the solver asks for the values at
        a point before its derivatives), else worked out now."""
        last = self._caps_last
        if last is None or last[0] is not x:
            self.values(x)
        return self._caps_last[1]

    def derivatives(self, x: np.ndarray) -> CellDerivatives:
        """Gradients on each cell's variables (v_k, its forces, v_k+1), in the scaled variables (compiled:
        :meth:`derivatives_numpy`)."""
        x = np.ascontiguousarray(x, dtype=float)
        n, q = self.local.shape[1], len(self.CAPS)
        gf, ge, gg, gc = np.empty((self.N, n)), np.empty((self.N, n)), np.empty((self.N, q, n)), \
            np.empty((len(self.cmask), self.N, n))
        _raw(kernels().cell_derivatives)(self.model(), x, self._caps(x), gf, ge, gg, gc)
        return CellDerivatives(gf, ge, gg, gc)

    def hessian(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, zc: np.ndarray) -> np.ndarray:
        """The Lagrangian's Hessian on each cell's variables (compiled: :meth:`hessian_numpy`)."""
        x = np.ascontiguousarray(x, dtype=float)
        n = self.local.shape[1]
        out = np.empty((self.N, n, n))
        f8 = np.float64
        _raw(kernels().cell_hessian)(self.model(), x, self._caps(x), np.ascontiguousarray(y, f8),
                                     np.ascontiguousarray(z, f8), np.ascontiguousarray(zc, f8), out)
        return out

    # ------------------------------------------------------------------ the same in numpy (the reference)
    def values_numpy(self, x: np.ndarray) -> CellValues:
        P = self._physics(x)
        p, q, h, fr = P["p"], P["q"], self.h, self.f_ref
        net = P[self.FORCES[0]]
        for f in self.FORCES[1:]:  # traction less every brake
            net = net - P[f]
        e = (0.5 * self.M * (q * q - p * p) - h * (net - P["R"] - self.G)) / (h * fr)
        g = np.where(self.active, np.stack([(P[f] - P[cap][0]) / fr for f, cap in zip(self.FORCES, self.CAPS)], axis=1),
                     -1.0)
        c = (np.einsum("jk,k->j", self.cmask, 2 * h / np.maximum(p + q, V_FLOOR_MS)) + self.cconst) / self.t_ref
        work = sum(w * P[f] for f, w in zip(self.FORCES, self.cost()) if w)
        return CellValues(float(np.sum(h * work)) / KJ_PER_KWH / self.e_ref, e, g, c)

    def derivatives_numpy(self, x: np.ndarray) -> CellDerivatives:
        """Gradients on each cell's variables (v_k, its forces, v_k+1), in the scaled variables."""
        P = self._physics(x)
        vm_p, vm_q, *_ = self._vm_derivatives(P)
        N, h, M, fr = self.N, self.h, self.M, self.f_ref
        n = self.local.shape[1]
        rl = self._rl
        ge = np.empty((N, n))
        ge[:, 0] = (-M * P["p"] + h * P["R_v"] * vm_p) / (h * fr)
        ge[:, 1] = -1.0 / fr  # traction
        ge[:, 2:n - 1] = 1.0 / fr  # the brakes
        ge[:, n - 1] = (M * P["q"] + h * P["R_v"] * vm_q) / (h * fr)
        gg = np.zeros((N, len(self.CAPS), n))
        for j, key in enumerate(self.CAPS):  # force j under its cap
            cap = P[key]
            gg[:, j, 0] = -cap[1] * vm_p / fr
            gg[:, j, n - 1] = -cap[1] * vm_q / fr
            gg[:, j, j + 1] = 1.0 / fr
        gg[~self.active] = 0.0
        dtau = -2 * h / np.maximum(P["p"] + P["q"], V_FLOOR_MS) ** 2 / self.t_ref
        gc = np.zeros((len(self.cmask), N, n))
        gc[:, :, 0] = gc[:, :, n - 1] = self.cmask * dtau
        gf = np.zeros((N, n))
        for j, w in enumerate(self.cost()):
            if w:
                gf[:, j + 1] = w * h / KJ_PER_KWH / self.e_ref
        return CellDerivatives(gf * rl, ge * rl, gg * rl[:, None, :], gc * rl[None])

    def hessian_numpy(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, zc: np.ndarray) -> np.ndarray:
        """The Lagrangian's Hessian on each cell's variables: only the two speeds enter nonlinearly."""
        P = self._physics(x)
        vm_p, vm_q, vm_pp, vm_pq, vm_qq = self._vm_derivatives(P)
        h, M, fr = self.h, self.M, self.f_ref
        R_v, R_vv = P["R_v"], P["R_vv"]
        # the equality (work-energy balance): its second derivatives
        e_pp = (-M + h * (R_vv * vm_p ** 2 + R_v * vm_pp)) / (h * fr)
        e_qq = (M + h * (R_vv * vm_q ** 2 + R_v * vm_qq)) / (h * fr)
        e_pq = (R_vv * vm_p * vm_q + R_v * vm_pq) / fr
        pp, pq_, qq = y * e_pp, y * e_pq, y * e_qq
        for j, key in enumerate(self.CAPS):  # - cap(vm) in each inequality
            cap = P[key]
            w = np.where(self.active[:, j], z[:, j], 0.0) / fr
            pp = pp - w * (cap[2] * vm_p ** 2 + cap[1] * vm_pp)
            qq = qq - w * (cap[2] * vm_q ** 2 + cap[1] * vm_qq)
            pq_ = pq_ - w * (cap[2] * vm_p * vm_q + cap[1] * vm_pq)
        d2 = np.einsum("j,jk->k", zc, self.cmask) * 4 * h / np.maximum(P["p"] + P["q"], V_FLOOR_MS) ** 3 / self.t_ref  # the times
        n = self.local.shape[1]  # the cell's variables: its two speeds first and last
        out = np.zeros((self.N, n, n))
        vr2 = self.v_ref ** 2
        out[:, 0, 0] = (pp + d2) * vr2
        out[:, n - 1, n - 1] = (qq + d2) * vr2
        out[:, 0, n - 1] = out[:, n - 1, 0] = (pq_ + d2) * vr2
        return out

    # ------------------------------------------------------------------ start and results
    def _needed_kn(self, v_nodes_ms: np.ndarray):
        """(node speeds [m/s] under the envelope and at rest at both ends, the cells' mean speeds [m/s], the net
        force each cell needs for them [kN])."""
        v = np.clip(v_nodes_ms, 0.0, self.v_cap)
        v[0] = v[-1] = 0.0
        p, q = v[:-1], v[1:]
        vm = np.sqrt(0.5 * (p * p + q * q))
        u = 0.5 * self.M * (q * q - p * p) / self.h + train_resistance_kn(kmh(vm), self.calc.train.resistance_kn) + self.G
        return v, vm, u

    def start_from_profile(self, v_nodes_ms: np.ndarray) -> np.ndarray:
        """A scaled start vector from node speeds [m/s] (the forces each cell needs for them)."""
        v, _, u = self._needed_kn(v_nodes_ms)
        F = np.clip(u, 0.0, None) * (self.allowed > 0)
        B = np.clip(-u, 0.0, None) * self.can_brake
        x = np.empty(3 * self.N + 1)
        x[0::3], x[1::3], x[2::3] = v, F, B
        return x / self.ref

    def energy_kwh(self, xs: np.ndarray) -> float:
        return float(np.sum(self.h * xs[1::3] * self.f_ref)) / KJ_PER_KWH

    def speeds_ms(self, xs: np.ndarray) -> np.ndarray:
        return xs[0::3] * self.v_ref


class NetCellEnergyProblem(CellEnergyProblem):
    """The minimum-*net*-energy problem on ``calc``'s cells: the traction work less what the electric brake
    returns to the line, sum h (F - eta B_e), with eta the train's ``regen_efficiency``.

    The electric and the air brake are two controls here, B_e <= B_e,max(vm) (0 where the catenary is off)
    and B_a <= B_a,max(vm), where the traction problem has one, B <= B_e,max + B_a,max: the objective credits
    only the electric part, and with two controls it stays smooth (min(B, B_e,max) would not be). Variables
    ``[v_0, F_0, E_0, A_0, v_1, ...]``, three inequalities per cell. The optimum never brakes with air while
    electric braking is left (that would give up a credit), so it brakes as the calculator does: the
    electric brake first. E* of this problem is the least net energy of any run in the time, a true
    optimum of the train model with the credit; for a train that regenerates nothing it is the traction E*.
    """

    FORCES = ("F", "E", "A")
    CAPS = ("Fm", "Em", "Am")
    CAP_CURVES = ((0, -1), (1, -1), (-1, 2))

    def __init__(self, calc: TractionCalculator, time_s: float, regen: float):
        super().__init__(calc, time_s)
        self.regen = float(regen)
        N = self.N
        powered = self.allowed > 0
        has_electric = bool(np.any(np.asarray(calc.electric_brake_kn, float) > 0))
        has_air = bool(np.any(np.asarray(calc.air_brake_kn, float) > 0))
        self.electric_ok = powered & has_electric
        self.air_ok = np.full(N, has_air)
        n = 4 * N + 1
        ref = np.empty(n)
        ref[0::4] = self.v_ref
        ref[1::4] = ref[2::4] = ref[3::4] = self.f_ref
        self.ref = ref
        lb, ub = np.zeros(n), np.full(n, np.inf)
        ub[0::4] = self.ub[0::3]  # the speeds' bounds (the envelope, rest at both ends) as the traction problem's
        ub[1::4] = np.where(powered, np.inf, 0.0)
        ub[2::4] = np.where(self.electric_ok, np.inf, 0.0)
        ub[3::4] = np.where(self.air_ok, np.inf, 0.0)
        self.lb, self.ub = lb, ub
        k = np.arange(N)
        self.local = np.column_stack([4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3, 4 * k + 4])
        pos_x = np.empty(n, dtype=np.int64)
        pos_x[0::4] = 5 * np.arange(N + 1)
        pos_x[1::4] = 5 * k + 1
        pos_x[2::4] = 5 * k + 2
        pos_x[3::4] = 5 * k + 3
        self.pos_x = pos_x
        self.pos_y = 5 * k + 4
        self._rl = ref[self.local]
        self.active = np.column_stack([powered, self.electric_ok, self.air_ok])
        self._last = None

    def _physics(self, x: np.ndarray):
        if self._last is not None and self._last[0] is x:
            return self._last[1]
        xp = x * self.ref
        phys, V = self._speed_terms(xp[0::4])
        phys.update({"F": xp[1::4], "E": xp[2::4], "A": xp[3::4]})
        # the caps, d/dvm and d2/dvm2 (the curves are in km/h); traction and the electric brake need the catenary
        for key, curve, on in zip(self.CAPS, self._force_curves(), (self.allowed, self.allowed, 1.0)):
            phys[key] = tuple(f * on * KMH_PER_MS ** i for i, f in enumerate(curve(V)))
        self._last = (x, phys)
        return phys

    def cost(self) -> tuple[float, ...]:
        return (1.0, -self.regen, 0.0)

    def start_from_profile(self, v_nodes_ms: np.ndarray) -> np.ndarray:
        """A scaled start from node speeds [m/s]: each cell's force, braking electric first."""
        v, vm, u = self._needed_kn(v_nodes_ms)
        brake = np.clip(-u, 0.0, None)
        e_max = max_force_kn(kmh(vm), self.calc.electric_brake_speed_kmh, self.calc.electric_brake_kn) * self.electric_ok
        x = np.empty(4 * self.N + 1)
        x[0::4] = v
        x[1::4] = np.clip(u, 0.0, None) * (self.allowed > 0)
        x[2::4] = np.minimum(brake, e_max)
        x[3::4] = (brake - x[2::4]) * self.air_ok
        return x / self.ref

    def energy_kwh(self, xs: np.ndarray) -> float:
        return float(np.sum(self.h * (xs[1::4] - self.regen * xs[2::4]) * self.f_ref)) / KJ_PER_KWH

    def speeds_ms(self, xs: np.ndarray) -> np.ndarray:
        return xs[0::4] * self.v_ref

    def forces_kn(self, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(traction, electric brake, air brake) [kN] per cell at the scaled point ``xs``."""
        x = xs * self.ref
        return x[1::4], x[2::4], x[3::4]


@dataclass(frozen=True)
class CellSolution:
    """E* on one grid: the objective [kWh], the node positions [m] and speeds [m/s], the cells' forces
    [kN], dE*/dT [kWh/s] from the running time's multiplier, the solver's result."""

    energy_kwh: float
    s_m: np.ndarray
    v_ms: np.ndarray
    traction_kn: np.ndarray
    brake_kn: np.ndarray
    slope_kwh_per_s: float
    result: IPMResult
    solve_time_s: float
    traction_kwh: float = math.nan
    recovered_kwh: float = math.nan
    electric_kn: np.ndarray | None = None
    """The net problem's electric part of ``brake_kn`` (None for the traction problem's solution)."""
    """The optimum's traction work and the energy its electric brake returns [kWh] (the train's
    ``regen_efficiency`` x its electric braking work, the electric brake taking its share first): the
    objective is the first (traction E*) or their difference (net E*)."""


def cell_calculator(route, train, options: ModelOptions, step_m: float, coarser: TractionCalculator | None = None,
                    extra_m=()) -> TractionCalculator:
    """The calculator on the E* grid: ``step_m`` cells, graded towards both rest points, with nodes at
    ``extra_m`` [m] (a journey's timing points); with ``coarser``, every cell of that grid halved (nested
    grids: their optima differ by the discretisation alone, not by where the route's breakpoints happen to
    fall between uniform nodes)."""
    opts = ModelOptions(step_m=step_m, point_mass=options.point_mass, air_brake=options.air_brake,
                        rotating_mass=options.rotating_mass, strict_limits=options.strict_limits,
                        air_cycle=False)  # E*'s relaxation: the air brake a continuous force (ocp.bound.relaxed)
    nodes = np.concatenate([graded_end_nodes(route.length_m), np.asarray(extra_m, dtype=float)])
    if coarser is not None:
        s = coarser.s_m
        nodes = np.concatenate([s, 0.5 * (s[1:] + s[:-1])])
        opts = replace(opts, step_m=2 * step_m)  # its uniform nodes are among the coarser grid's
    # (E*'s own grading towards both rest points, END_GRADING_M, instead of the plans' departure grading)
    return TractionCalculator(route, train, opts, extra_nodes_m=nodes, graded_departure=False)


def initial_speeds(calc: TractionCalculator, time_s: float) -> np.ndarray:
    """A run slightly faster than ``time_s`` from the calculator: full traction up to a cruise speed, held
    there (braking where it must), and the braking curves (the ISSA paper's four-stage drive), the cruise speed
    the highest of a batch that still takes more than ``time_s`` less 1 %: node speeds [m/s]."""
    top = float(np.max(calc.limit_kmh))
    cruise = np.linspace(5.0, top, 60)
    res = calc.evaluate(("T",), np.zeros((cruise.size, 0)), cruise_kmh=cruise)
    ok = res.feasible & (res.running_time_s <= 0.99 * time_s)
    i = int(np.argmax(ok)) if ok.any() else cruise.size - 1
    prof = calc.evaluate(("T",), np.zeros((1, 0)), profile=True, cruise_kmh=cruise[i:i + 1]).profile
    return ms(prof.v_kmh[0])


def solve_cells(calc: TractionCalculator, time_s: float, start: np.ndarray | None = None,
                settings: IPMSettings | None = None, mu_init: float | None = None,
                point: np.ndarray | None = None, regen: float = 0.0) -> CellSolution:
    """E* on ``calc``'s cells in ``time_s`` [s]; ``start``: node speeds [m/s] to start from (default
    :func:`initial_speeds`), or ``point`` a whole scaled start (speeds and forces, :func:`warm_point`);
    ``mu_init`` the barrier parameter to start with; ``regen`` > 0: the least net energy with that share of
    the electric brake's work credited (:class:`NetCellEnergyProblem`), else the least traction work. Raises
    ``InfeasibleError`` when the solver does not converge."""
    t0 = _time.perf_counter()
    prob = cell_problem(calc, time_s, regen)
    if point is not None:
        x0 = point
    else:
        x0 = prob.start_from_profile(initial_speeds(calc, time_s) if start is None else start)
    if settings is None:  # near an optimum (a start from a solution): the adaptive barrier rule
        near = start is not None or point is not None
        settings = IPMSettings(mu_strategy="adaptive" if near else "monotone", max_iter=WARM_MAX_ITER if near else MAX_ITER)
    res = CellIPM(prob, settings).solve(x0, mu_init=mu_init)
    if not res.converged:
        raise InfeasibleError(f"the minimum-energy problem on {len(prob.h)} cells did not converge "
                              f"({res.status} after {res.iterations} iterations, error {res.error:.1e})")
    slope = -float(res.zc[0]) * prob.e_ref / prob.t_ref
    v = prob.speeds_ms(res.x)
    vm_kmh = kmh(np.sqrt(0.5 * (v[:-1] ** 2 + v[1:] ** 2)))
    if isinstance(prob, NetCellEnergyProblem):
        f, electric, air = prob.forces_kn(res.x)
        brake, recovered = electric + air, prob.regen * float(np.sum(calc.h_m * electric)) / KJ_PER_KWH
    else:
        x = res.x * prob.ref
        f, brake, electric = x[1::3], x[2::3], None
        e_max = max_force_kn(vm_kmh, calc.electric_brake_speed_kmh, calc.electric_brake_kn) * calc.traction_allowed
        recovered = float(recovered_energy_kwh(calc.s_m, brake, e_max, calc.train.regen_efficiency))
    return CellSolution(prob.energy_kwh(res.x), calc.s_m, v, f, brake, slope, res, _time.perf_counter() - t0,
                        float(np.sum(calc.h_m * f)) / KJ_PER_KWH, recovered, electric)


def cell_problem(calc: TractionCalculator, time_s: float, regen: float = 0.0) -> CellEnergyProblem:
    """The minimum-energy problem on ``calc``'s cells: of the net energy with ``regen`` > 0
    (:class:`NetCellEnergyProblem`), else of the traction work."""
    return NetCellEnergyProblem(calc, time_s, regen) if regen > 0 else CellEnergyProblem(calc, time_s)


def warm_point(prob: CellEnergyProblem, sol: CellSolution) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A start for ``prob`` from a solution on another grid or at another time: node speeds interpolated,
    each new cell's forces and multipliers those of the old cell around its middle (the multipliers as
    densities per metre, so that they carry over between cell lengths)."""
    s_new = prob.calc.s_m
    mid = 0.5 * (s_new[1:] + s_new[:-1])
    old = sol.s_m
    k = np.clip(np.searchsorted(old, mid) - 1, 0, len(old) - 2)
    v = np.interp(s_new, old, sol.v_ms)
    if isinstance(prob, NetCellEnergyProblem):  # the braking split: the old one's, or electric first
        x = np.empty(4 * prob.N + 1)
        x[0::4] = v
        x[1::4] = np.where(prob.allowed > 0, sol.traction_kn[k], 0.0)
        brake = sol.brake_kn[k]
        if sol.electric_kn is not None:
            electric = sol.electric_kn[k]
        else:
            v_mid = kmh(np.sqrt(0.5 * (v[1:] ** 2 + v[:-1] ** 2)))
            electric = np.minimum(brake, max_force_kn(v_mid, prob.calc.electric_brake_speed_kmh,
                                                      prob.calc.electric_brake_kn))
        x[2::4] = np.where(prob.electric_ok, electric, 0.0)
        x[3::4] = np.where(prob.air_ok, brake - electric, 0.0)
    else:
        x = np.empty(3 * prob.N + 1)
        x[0::3] = v
        x[1::3] = np.where(prob.allowed > 0, sol.traction_kn[k], 0.0)
        x[2::3] = np.where(prob.can_brake, sol.brake_kn[k], 0.0)
    h_old = np.diff(old)
    r = sol.result
    hm_old = float(np.mean(h_old))
    per_m_y = r.y * hm_old / h_old
    per_m_z = r.z * (hm_old / h_old)[:, None]
    hm_new = float(np.mean(prob.h))
    y = per_m_y[k] * prob.h / hm_new
    z = per_m_z[k] * (prob.h / hm_new)[:, None]
    return x / prob.ref, y, z, r.zc


MAX_ITER = 150
"""A solve that has not converged in this many iterations is given up (they converge in 25-80; one that
ran on to 300 was a warm start that had lost its way, and a cold start then took 40)."""
WARM_MAX_ITER = 90
"""A solve started from a neighbouring solution (a coarser grid, another time) that has not converged in
this many iterations has lost its way: the caller starts it cold (on the 300 km line at 16,252 s the start
from the 30 m grid reached 150 iterations at an error of 4e-2, 5 s, and the cold start took 71 iterations,
1.3 s; warm starts that converge take 20-70, one of the journeys' legs 133)."""
COARSE_STEP_M = 40.0
"""The first grid's longest cell length [m]; the second has half of it."""
COARSE_MIN_CELLS = 400
"""The first grid solved has at least this many cells (or is the last but one before ``FINEST_STEP_M``): on
a short route the coarser grids of the nest are built but not solved. Every grid costs the solver about
the same number of iterations, and on grids of a few dozen cells those were spent on grids far too
coarse for the tolerance (a 2 km leg needed 40, 20, 10 and 5 m)."""
FINEST_STEP_M = 5.0
"""Grids are halved until two agree to the tolerance or the cells reach this length."""
WARM_MU = 1e-3
"""Barrier parameter a solve from a neighbouring solution starts at (its primal values; its multipliers
are not carried over: from them and a small barrier parameter the method lost its way on long lines)."""


def grid_accuracy(energies_kwh: list[float], floor_kwh: float = 0.0) -> float:
    """The finest grid's relative error, estimated from the optima on successively halved grids: the last
    change ``d``, or where three grids show the changes shrinking by only ``r < 2`` per halving (slower than
    first order), ``d / (r - 1)``, the rest of a geometric series of such changes. The estimate never
    assumes a faster convergence than the grids showed; relative to ``max(E*, floor_kwh)``."""
    e = energies_kwh
    d = abs(e[-1] - e[-2])
    if len(e) >= 3 and abs(e[-2] - e[-3]) > 0:
        r = abs(e[-2] - e[-3]) / max(d, 1e-300)
        d = d * max(1.0, 1.0 / (r - 1.0)) if r > 1.0 else math.inf
    return d / max(abs(e[-1]), floor_kwh, 1e-9)


@dataclass(frozen=True)
class EStar:
    """E* from the cell scheme on successively halved grids: the finest grid's optimum [kWh], its relative
    accuracy (the last two grids' difference relative to ``max(E*, floor_kwh)``), whether that met the
    tolerance, dE*/dT [kWh/s], each grid's step [m], cell count, optimum [kWh] and iterations, the wall
    time [s], and the finest solution (a warm start for a neighbouring time)."""

    energy_kwh: float
    accuracy: float
    converged: bool
    slope_kwh_per_s: float
    steps_m: tuple
    cells: tuple
    energies_kwh: tuple
    iterations: tuple
    solve_time_s: float
    solution: CellSolution
    calc: TractionCalculator | None = None
    """The finest grid's calculator (the mesh a curve of running times is solved on)."""


def solve_estar(route, train, options: ModelOptions, time_s: float, *, tol: float, floor_kwh: float = 0.0,
                warm: CellSolution | None = None, first_step_m: float | None = None,
                finest_step_m: float = FINEST_STEP_M, scale_kwh: float | None = None, regen: float = 0.0) -> EStar:
    """E* of ``train`` on ``route`` in ``time_s`` [s]: the cell scheme on a ``first_step_m`` grid (default
    ``COARSE_STEP_M``, halved while it has fewer than ``COARSE_MIN_CELLS`` cells), then on
    grids of half the step, each started from the one before, until two agree to ``tol`` (relative to
    ``max(E*, floor_kwh)``, or to ``scale_kwh`` where given: an error in kWh that must be small against
    another E*) or the cells reach ``finest_step_m``. ``warm``: a solution at a neighbouring time to start
    the first grid from. The accuracy returned is relative to ``max(E*, floor_kwh)`` in either case.
    ``regen`` > 0: the least net energy (:func:`solve_cells`)."""
    t0 = _time.perf_counter()
    step = float(COARSE_STEP_M if first_step_m is None else first_step_m)
    sols, steps, cells, calcs = [], [], [], []
    prev = warm
    calc = cell_calculator(route, train, options, step)
    while first_step_m is None and len(calc.h_m) < COARSE_MIN_CELLS and step / 4 >= finest_step_m - 1e-9:
        step /= 2  # a grid too coarse to be worth a solve: the next of the nest
        calc = cell_calculator(route, train, options, step, coarser=calc)
    while True:
        if sols:
            calc = cell_calculator(route, train, options, step, coarser=calc)
        calcs.append(calc)
        point = None
        if prev is not None and prev.result.error <= 1e-6:  # the coarser grid's (or the neighbouring time's) speeds and forces
            point = warm_point(cell_problem(calc, time_s, regen), prev)[0]
        try:
            try:
                sol = solve_cells(calc, time_s, mu_init=None if point is None else WARM_MU, point=point, regen=regen)
            except InfeasibleError:
                if point is None:
                    raise
                sol = solve_cells(calc, time_s, regen=regen)  # the start from the coarser grid led astray: a cold start
        except InfeasibleError:
            if len(sols) < 2:
                raise
            break  # a finer grid the solver cannot finish: the last two grids' answer, not converged
        sols.append(sol)
        steps.append(step)
        cells.append(len(calc.h_m))
        prev = sol
        if len(sols) >= 2:
            acc = grid_accuracy([s.energy_kwh for s in sols], floor_kwh)
            ref = max(abs(sols[-1].energy_kwh), floor_kwh, 1e-9)
            met = (acc if scale_kwh is None else acc * ref / scale_kwh) <= tol
            if met or step / 2 < finest_step_m - 1e-9:
                break
        step /= 2
    fine = sols[-1]
    steps, cells = steps[:len(sols)], cells[:len(sols)]
    return EStar(fine.energy_kwh, acc, met, fine.slope_kwh_per_s, tuple(steps), tuple(cells),
                 tuple(s.energy_kwh for s in sols), tuple(s.result.iterations for s in sols),
                 _time.perf_counter() - t0, fine, calcs[len(sols) - 1])
