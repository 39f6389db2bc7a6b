"""Quasi-static coupler forces along the train, and the rate at which its applied force changes.

The train is rigid: every vehicle has the train's common acceleration ``a``. Vehicle i (head first)
carries its own applied force P_i (a locomotive's share of the traction, less its share of the
electric brake; a wagon's share of the air brake), its own basic resistance R_i(v), the gravity force
G_i of the gradient under it (the mean equivalent gradient over its own length at its own position)
and its inertia m_i a (m_i with its rotating-mass allowance). The force in coupler j, behind vehicle j,
is what the vehicles ahead of it need from the rest of the train:

    C_j = sum over i <= j of (P_i - R_i - G_i - m_i a),    a = sum over all i of (P_i - R_i - G_i) / sum m_i

so that the last vehicle's balance closes (C behind the tail is 0). C_j > 0 is tension (the front
pulls the rear), C_j < 0 compression (the rear pushes the front).

How the train's forces are shared: each locomotive gives the same share of its own curve (its traction,
or its electric brake) as the whole train gives of the sum of the curves; the electric brake takes its
part of the braking first, B_e = min(B, B_e,max(v)) (0 where the catenary is off), the air brake the
rest, shared among the vehicles in proportion to their own air-brake force at v (by mass where the
consist gives a constant deceleration instead of air brakes). This is the calculator's own split
(``physics.braking``, ``physics.energy``); the model is quasi-static: no slack, no draft-gear springs, no
brake-pipe propagation (the longitudinal dynamics of a real train give larger peaks).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .braking import electric_share_kn
from .gradient import Track, mean_gradient_permille
from .traction import gradient_force_kn, max_force_kn


@dataclass(frozen=True)
class VehicleLine:
    """The train vehicle by vehicle, head first (n vehicles): ``mass_t``, ``inertial_t`` (mass x
    rotating-mass factor), ``length_m``, ``front_m`` (distance from the head of the train to the vehicle's
    front), ``resistance_kn`` (n, 3) each vehicle's Davis (A, B, C) [kN], ``group`` (n,) the index of its
    consist entry, and per entry its force curves ((speeds [km/h], forces [kN]) or None): ``traction``,
    ``electric`` (brake), ``air`` (brake)."""

    mass_t: np.ndarray
    inertial_t: np.ndarray
    length_m: np.ndarray
    front_m: np.ndarray
    resistance_kn: np.ndarray
    group: np.ndarray
    traction: tuple
    electric: tuple
    air: tuple

    @property
    def n(self) -> int:
        return len(self.mass_t)

    @classmethod
    def from_layout(cls, layout, rotating_mass: float | None = None) -> "VehicleLine":
        """From ``Train.layout`` (its ``VehicleGroup`` entries); ``rotating_mass``: a uniform allowance gamma
        (inertial mass m (1 + gamma)) instead of each vehicle's own factor, as the calculator's option."""
        counts = np.array([g.count for g in layout], dtype=np.int64)
        group = np.repeat(np.arange(len(layout)), counts)
        mass = np.array([g.mass_t for g in layout])[group]
        factor = (np.array([g.inertial_factor for g in layout])[group] if rotating_mass is None
                  else np.full(len(group), 1.0 + rotating_mass))
        length = np.array([g.length_m for g in layout])[group]
        front = np.concatenate([[0.0], np.cumsum(length)[:-1]])
        res = np.array([g.resistance_kn for g in layout], dtype=float)[group]

        def curves(attr):
            return tuple(None if not getattr(g, attr) else tuple(np.asarray(getattr(g, attr), float).T)
                         for g in layout)

        return cls(mass, mass * factor, length, front, res, group, curves("traction_kn"),
                   curves("electric_brake_kn"), curves("air_brake_kn"))


def vehicle_gravity_kn(track: Track, line: VehicleLine, head_m) -> np.ndarray:
    """Gravity force along the track on every vehicle [kN], (positions, n): each vehicle's mass on the mean
    equivalent gradient under its own length, with the train's head at ``head_m`` [m]."""
    head = np.asarray(head_m, dtype=float)[:, None]
    front = head - line.front_m[None, :]
    grad = mean_gradient_permille(track, front - line.length_m[None, :], front)
    return gradient_force_kn(grad, 1.0) * line.mass_t[None, :]


def _shares(curves: tuple, group: np.ndarray, speed_kmh: np.ndarray, allowed=None) -> np.ndarray | None:
    """Each vehicle's force curve at ``speed_kmh`` (cells,) as (cells, n), or None when no vehicle has one;
    times ``allowed`` (cells,) where given (the electric brake needs the catenary)."""
    if all(c is None for c in curves):
        return None
    per_group = np.stack([np.zeros_like(speed_kmh) if c is None else max_force_kn(speed_kmh, c[0], c[1])
                          for c in curves], axis=1)
    out = per_group[:, group]
    return out if allowed is None else out * np.asarray(allowed, dtype=float)[:, None]


def _spread(total_kn: np.ndarray, weights: np.ndarray | None, fallback: np.ndarray) -> np.ndarray:
    """``total_kn`` (cells,) shared among the vehicles in proportion to ``weights`` (cells, n), or to
    ``fallback`` (n,) where the weights sum to zero (or there are none)."""
    if weights is None:
        weights = np.broadcast_to(fallback, (len(total_kn), len(fallback)))
    s = weights.sum(axis=1, keepdims=True)
    flat = fallback / fallback.sum() if fallback.sum() > 0 else np.full(len(fallback), 1.0 / len(fallback))
    share = np.where(s > 0, weights / np.where(s > 0, s, 1.0), flat[None, :])
    return total_kn[:, None] * share


def coupler_forces_kn(line: VehicleLine, traction_kn, brake_kn, speed_kmh, gravity_kn, electric_allowed=None):
    """Force in every coupler [kN] (cells, n - 1), + = tension, for the train's cell-mean traction
    ``traction_kn`` and braking ``brake_kn`` (cells,) at ``speed_kmh`` (cells,), with ``gravity_kn`` (cells, n)
    from :func:`vehicle_gravity_kn` and ``electric_allowed`` (cells,) 1 where the catenary feeds the
    electric brake (None: everywhere). See the module docstring for the model."""
    f = np.asarray(traction_kn, dtype=float)
    b = np.asarray(brake_kn, dtype=float)
    v = np.asarray(speed_kmh, dtype=float)
    allowed = np.ones_like(v) if electric_allowed is None else np.asarray(electric_allowed, dtype=float)
    locos = np.array([c is not None for c in line.traction])[line.group].astype(float)
    trac = _spread(f, _shares(line.traction, line.group, v), locos)
    e_max = _shares(line.electric, line.group, v, allowed)
    e_total = np.zeros_like(v) if e_max is None else e_max.sum(axis=1)
    b_e = electric_share_kn(b, e_total)
    elec = _spread(b_e, e_max, locos)
    air = _spread(b - b_e, _shares(line.air, line.group, v), line.mass_t)
    r = line.resistance_kn
    resist = r[None, :, 0] + v[:, None] * (r[None, :, 1] + r[None, :, 2] * v[:, None])
    net = trac - elec - air - resist - gravity_kn
    a = net.sum(axis=1) / line.inertial_t.sum()
    return np.cumsum(net - a[:, None] * line.inertial_t[None, :], axis=1)[:, :-1]


@dataclass(frozen=True)
class CouplerBound:
    """A bound on the largest coupler force that costs a few operations per cell instead of one per vehicle.

    C_j is linear in the vehicles' forces: with S_j(x) = sum over i <= j of x_i - (M_j / M) sum of x_i (M_j
    the inertial mass ahead of coupler j), C_j = F S_j(f) - B_e S_j(e) - B_a S_j(b) - S_j(r(v)) - S_j(g),
    f, e, b each vehicle's share of the traction, the electric and the air brake, r its resistance and g its
    gravity force. So |C_j| <= F s_f + B_e s_e + B_a s_b + s_r + s_g(cell), each s the largest |S_j| over the
    couplers (and over the speeds, for the shares and the resistance). Where the bound is under a limit, no
    coupler can be over it."""

    traction: float
    electric: float
    air: float
    resistance: float
    gravity_kn: np.ndarray
    """(cells,) the largest gravity imbalance in each cell [kN]."""

    def kn(self, traction_kn, electric_kn, air_kn):
        """The bound [kN] for cell-mean forces (any shape ending in cells)."""
        return (np.asarray(traction_kn) * self.traction + np.asarray(electric_kn) * self.electric
                + np.asarray(air_kn) * self.air + (self.resistance + self.gravity_kn))


def coupler_bound(line: VehicleLine, gravity_kn: np.ndarray, top_kmh: float, step_kmh: float = 0.5) -> CouplerBound:
    """The :class:`CouplerBound` of a train whose vehicles feel ``gravity_kn`` (cells, n) in each cell, over the
    speeds 0 .. ``top_kmh`` (the shares and the resistance taken at every ``step_kmh`` and at each curve's
    points, where a piecewise-linear share has its extremes)."""
    m = line.inertial_t
    ahead = np.cumsum(m)[:-1] / m.sum()

    def imbalance(x: np.ndarray) -> np.ndarray:  # (..., n) -> (...) the largest |S_j| over the couplers
        return np.max(np.abs(np.cumsum(x, axis=-1)[..., :-1] - ahead * x.sum(axis=-1, keepdims=True)), axis=-1)

    knots = [np.arange(0.0, top_kmh + step_kmh, step_kmh)]
    for curves in (line.traction, line.electric, line.air):
        knots += [c[0] for c in curves if c is not None]
    v = np.unique(np.clip(np.concatenate(knots), 0.0, top_kmh))
    locos = np.array([c is not None for c in line.traction])[line.group].astype(float)

    def worst(curves, fallback):
        w = _shares(curves, line.group, v)
        if w is None:
            w = np.broadcast_to(fallback, (len(v), len(fallback)))
        s = w.sum(axis=1, keepdims=True)
        w = np.where(s > 0, w / np.where(s > 0, s, 1.0), fallback / fallback.sum())
        return float(imbalance(w).max())

    r = line.resistance_kn
    resist = r[None, :, 0] + v[:, None] * (r[None, :, 1] + r[None, :, 2] * v[:, None])
    return CouplerBound(worst(line.traction, locos), worst(line.electric, locos), worst(line.air, line.mass_t),
                        float(imbalance(resist).max()), imbalance(np.asarray(gravity_kn, dtype=float)))


def force_rate_kn_per_s(t_nodes_s, applied_kn) -> np.ndarray:
    """How fast the applied force changes between neighbouring cells [kN/s] (cells - 1,): the change of the
    cell-mean force ``applied_kn`` (cells,) over the time between the two cells' middles (``t_nodes_s``
    (cells + 1,) the times at the nodes). A switch between conditions counts as its jump over the time
    of about one cell, so the number depends on the grid: it is a check on jumps at the calculator's
    resolution, not a model of how a driver ramps the force."""
    t = np.asarray(t_nodes_s, dtype=float)
    mid = 0.5 * (t[1:] + t[:-1])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.abs(np.diff(np.asarray(applied_kn, dtype=float))) / np.diff(mid)
