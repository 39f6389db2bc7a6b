"""A consist resolved against its vehicles: the numbers the physics needs (no physics here)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from ..errors import InputError, Problem
from ..physics.adhesion import adhesion_limited
from ..physics.braking import air_brake_curve_kn
from ..physics.resistance import unit_to_train_coefficients_kn
from .consist import PLAUSIBLE, Consist, Vehicle


@dataclass(frozen=True)
class AirCycle:
    """The wagons' direct-release air brake as a cycle (``Consist.air_brake_cycle``, resolved for the train):
    ``recharge_s`` after a full release before the next application, an application held at least
    ``min_hold_s`` (None: its build-up time) and reaching full force ``build_up_s(gradient)`` after it is made."""

    recharge_s: float
    min_hold_s: float | None
    reduction_kpa: float
    n_vehicles: int
    fixed_build_up_s: float | None = None

    def build_up_s(self, gradient_permille):
        """Build-up time [s] of an application on ``gradient_permille``: the given ``build_up_s``, else TB/T 1407's
        brake idle time t_k = (3.6 + 0.00176 r n)(1 - 0.032 i_j), the gradient held to [-30, +15] per mille
        (longer on a descent; the up-grade's shortening kept to half)."""
        i = np.clip(np.asarray(gradient_permille, dtype=float), -30.0, 15.0)
        if self.fixed_build_up_s is not None:
            return np.full_like(i, self.fixed_build_up_s)
        return (3.6 + 0.00176 * self.reduction_kpa * self.n_vehicles) * (1.0 - 0.032 * i)


class VehicleGroup(NamedTuple):
    """One consist entry as the coupler forces need it (``physics.couplers``): ``count`` vehicles of one
    ``kind`` standing one behind the other, each of ``mass_t`` (with its load), ``inertial_factor``,
    ``length_m``, its own basic resistance (A, B, C) [kN] and its own force curves ((speed_kmh, kN), ...):
    traction and electric brake (locomotives), air brake at the consist's service coefficient (() where
    it has none). Plain numbers and tuples, so that a train's content hash covers them."""

    kind: str
    count: int
    mass_t: float
    inertial_factor: float
    length_m: float
    resistance_kn: tuple[float, float, float]
    traction_kn: tuple = ()
    electric_brake_kn: tuple = ()
    air_brake_kn: tuple = ()


@dataclass(frozen=True)
class Train:
    """Whole-train quantities. Force curves are summed over vehicles on the union of their speed points.

    ``resistance_kn`` holds (A, B, C) such that the train's basic resistance is A + B v + C v^2 [kN],
    v in km/h: the mass-weighted sum of each vehicle's w0 [N/kN] times its weight [kN] / 1000.

    Braking: ``electric_brake_*`` is the locomotives' electric brake (the part that can return energy);
    ``air_brake_*`` the wagons' air brakes at the consist's service coefficient beta_c (or, with a
    constant ``brake_deceleration_ms2``, what it takes on top of the electric brake to reach it).
    ``brake_curve(air=True)`` is what the planner brakes with.
    ``inertial_mass_t`` is the sum of mass x rotating-mass factor (= ``mass_t`` when no vehicle gives one).
    ``layout``: the consist's entries head first (:class:`VehicleGroup`), for the coupler forces;
    ``coupler_limit_kn`` and ``force_rate_limit_kn_per_s`` the consist's limits (None: not checked).
    """

    name: str
    mass_t: float
    length_m: float
    max_speed_kmh: float
    resistance_kn: tuple[float, float, float]
    traction_speed_kmh: np.ndarray
    traction_kn: np.ndarray
    electric_brake_speed_kmh: np.ndarray
    electric_brake_kn: np.ndarray
    air_brake_speed_kmh: np.ndarray
    air_brake_kn: np.ndarray
    n_vehicles: int
    inertial_mass_t: float = 0.0
    regen_efficiency: float = 0.0
    """Share of the electric brake's work returned to the line (0: none; the locomotives' own
    ``regen_efficiency``, weighted by their electric brake force when they differ)."""
    layout: tuple = ()
    coupler_limit_kn: float | None = None
    force_rate_limit_kn_per_s: float | None = None
    air_cycle: AirCycle | None = None
    """The air brake's cycle (None: no wagon air brake, or a constant ``brake_deceleration_ms2``)."""

    def __post_init__(self):
        if not self.inertial_mass_t:
            object.__setattr__(self, "inertial_mass_t", self.mass_t)

    def brake_curve(self, air: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(speeds [km/h], max braking force [kN]): electric + air brake, or the electric brake alone."""
        if not air:
            return self.electric_brake_speed_kmh, self.electric_brake_kn
        return self._total_brake

    @property
    def brake_speed_kmh(self) -> np.ndarray:
        """Speeds [km/h] of the planner's braking curve (electric + air)."""
        return self._total_brake[0]

    @property
    def brake_kn(self) -> np.ndarray:
        """The planner's max braking force [kN] (electric + air) at ``brake_speed_kmh``."""
        return self._total_brake[1]

    @cached_property
    def _total_brake(self) -> tuple[np.ndarray, np.ndarray]:
        return _sum_curves([(np.column_stack([self.electric_brake_speed_kmh, self.electric_brake_kn]), 1),
                            (np.column_stack([self.air_brake_speed_kmh, self.air_brake_kn]), 1)])

    @classmethod
    def from_consist(cls, consist: Consist, vehicles: dict[str, Vehicle]) -> "Train":
        mass = inertial = length = 0.0
        coeffs = np.zeros(3)
        n = 0
        n_braked_wagons = 0
        vmax = np.inf
        locos: list[tuple] = []  # (traction, electric brake, regen_efficiency, count)
        air: list[tuple[np.ndarray, int]] = []
        layout = []
        for entry in consist.vehicles:
            veh = vehicles[entry.type]
            m = veh.mass_t + entry.load_t
            mass += entry.count * m
            inertial += entry.count * m * veh.rotating_mass_factor
            length += entry.count * veh.length_m
            r = veh.resistance_n_per_kn
            coeffs += np.array(unit_to_train_coefficients_kn(r.a, r.b, r.c, entry.count * m))
            vmax = min(vmax, veh.max_speed_kmh)
            n += entry.count
            traction, electric = _driven_curves(veh)
            if veh.kind == "locomotive":
                locos.append((traction, electric, veh.regen_efficiency, entry.count))
            curve = None
            if veh.air_brake is not None:
                ab = veh.air_brake
                curve = (np.asarray(ab.force_kn, float) if ab.force_kn is not None
                         else air_brake_curve_kn(ab.braking_ratio, ab.shoe, m, veh.max_speed_kmh))
                air.append((curve, entry.count))
                if veh.kind == "wagon":
                    n_braked_wagons += entry.count
            layout.append(VehicleGroup(
                veh.kind, entry.count, float(m), float(veh.rotating_mass_factor), float(veh.length_m),
                tuple(float(x) for x in unit_to_train_coefficients_kn(r.a, r.b, r.c, m)),
                _pairs(traction), _pairs(electric),
                () if curve is None or consist.brake_deceleration_ms2 is not None
                else _pairs(np.column_stack([curve[:, 0], curve[:, 1] * consist.service_brake_coefficient]))))
        # regeneration weighted by each locomotive group's peak electric brake force
        weights = np.array([c * max(e[:, 1]) for _, e, _, c in locos], dtype=float)
        shares = np.array([eta or 0.0 for _, _, eta, _ in locos], dtype=float)
        regen = float(weights @ shares / weights.sum()) if weights.sum() > 0 else 0.0
        tv, tf = _sum_curves([(t, c) for t, _, _, c in locos])
        ev, ef = _sum_curves([(e, c) for _, e, _, c in locos])
        av, af = _sum_curves(air)
        af = af * consist.service_brake_coefficient
        if consist.brake_deceleration_ms2 is not None:
            # a constant deceleration (railtoolkit's a_braking): the air brake makes up what the
            # electric brake does not give towards inertial mass x deceleration
            total = inertial * consist.brake_deceleration_ms2
            av = np.unique(np.concatenate([ev, [0.0, float(vmax)]]))
            af = np.maximum(total - np.interp(av, ev, ef), 0.0)
        for a in (av, af):
            a.setflags(write=False)
        cyc = consist.air_brake_cycle
        cycle = None
        if n_braked_wagons and consist.brake_deceleration_ms2 is None:
            cycle = AirCycle(float(cyc.recharge_s + cyc.recharge_s_per_wagon * n_braked_wagons), cyc.min_hold_s,
                             float(cyc.reduction_kpa), n, cyc.build_up_s)
        return cls(consist.name, mass, length, float(vmax), tuple(float(x) for x in coeffs),
                   tv, tf, ev, ef, av, af, n, inertial, float(regen), tuple(layout), consist.coupler_limit_kn,
                   consist.force_rate_limit_kn_per_s, cycle)


def _driven_curves(veh: Vehicle) -> tuple[np.ndarray | None, np.ndarray | None]:
    """A vehicle's traction and electric-brake curves as the train has them: each capped by the adhesion of its
    driven wheels where the vehicle gives ``adhesion_mu`` (``physics.adhesion``); None where it has none."""
    curves = []
    for curve in (veh.traction_kn, veh.brake_kn):
        if curve is not None:
            curve = np.asarray(curve, dtype=float)
            if veh.adhesion_mu is not None:
                curve = adhesion_limited(curve, np.asarray(veh.adhesion_mu, dtype=float), veh.mass_t)
        curves.append(curve)
    return curves[0], curves[1]


def _pairs(curve) -> tuple:
    """A force curve as a tuple of (speed_kmh, force_kn) pairs (() for none)."""
    return () if curve is None else tuple((float(v), float(f)) for v, f in np.asarray(curve, float))


def _sum_curves(curves: list[tuple[list | np.ndarray, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Sum piecewise-linear force curves [[speed_kmh, force_kn], ...] on the union of their speed points
    (each held flat beyond its last point)."""
    if not curves:
        return np.array([0.0, 1.0]), np.zeros(2)
    speeds = np.unique(np.concatenate([np.asarray(c, float)[:, 0] for c, _ in curves]))
    total = np.zeros_like(speeds)
    for c, count in curves:
        arr = np.asarray(c, float)
        total += count * np.interp(speeds, arr[:, 0], arr[:, 1])
    for a in (speeds, total):
        a.setflags(write=False)
    return speeds, total


def build_train(consist: Consist, vehicles: dict[str, Vehicle], name: str = "", lines: dict | None = None) -> Train:
    """``Train.from_consist`` with the plausibility bounds on the whole train (mass, length)."""
    problems: list[Problem] = []
    train = Train.from_consist(consist, vehicles)
    lines = lines or {}
    where = lines[("vehicles",)] if ("vehicles",) in lines else lines.get(())  # the field's line, else the file's
    if train.mass_t > PLAUSIBLE["train_mass_t"]:
        problems.append(Problem(name, "vehicles", f"total mass {train.mass_t:,.0f} t is implausible: the heaviest train "
                                f"ever run weighed 99,734 t (limit {PLAUSIBLE['train_mass_t']:,.0f} t)", where))
    if train.length_m > PLAUSIBLE["train_length_m"]:
        problems.append(Problem(name, "vehicles", f"train length {train.length_m:,.0f} m is implausible: the longest "
                                f"train ever run was 7.35 km (limit {PLAUSIBLE['train_length_m']:,.0f} m)", where))
    if not max(train.traction_kn, default=0.0) > 0:
        problems.append(Problem(name, "vehicles", "the train has no traction: no vehicle of kind 'locomotive' gives a "
                                "traction_kn above 0 kN, so it could never start", where))
    if not max(train.brake_kn, default=0.0) > 0:
        problems.append(Problem(name, "vehicles", "the train has no brake: no locomotive gives a brake_kn above 0 kN, "
                                "no wagon an air_brake, and the consist no brake_deceleration_ms2, so it could never "
                                "stop", where))
    if problems:
        raise InputError(problems)
    return train


def shorter_than_train(route, train: "Train", route_file: str, consist_file: str = "") -> Problem:
    """The problem of a route no longer than its train (it cannot run from stop to stop)."""
    of = f" ({consist_file})" if consist_file else ""
    return Problem(route_file, "length_m", f"{route.length_m:,.0f} m: the route is not longer than the train '{train.name}'"
                   f"{of}, {train.length_m:,.0f} m long; it cannot run from stop to stop")
