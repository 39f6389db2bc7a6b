"""Traction energy: work at the wheel, or energy drawn with an efficiency and a regenerative credit.

The default objective of every planner here is the traction work at the wheel, sum F ds [kWh] (the ISSA
paper's eq. 1, SPEC). :class:`EnergyModel` adds two options of the MPOC paper's objective:

* ``efficiency``: wheel power / drawn power of the traction chain, a constant or a curve over speed
  (``[[speed_kmh, eta], ...]``, linear between points); drawn energy = sum F / eta(v) ds;
* ``regen_credit``: the share of the *electric* brake's work returned to the line and credited,
  sum r B_e ds. The wagons' air brake returns nothing, so only the electric part counts.

:func:`energy_rate_kn` is the integrand [kN = kJ/m] that the optimal control minimises and that the
check of a plan sums over the calculator's profile: one formula for both (numpy or CasADi symbols).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .backend import as_operand, piecewise_linear
from .braking import electric_share_kn
from .units import KJ_PER_KWH


@dataclass(frozen=True)
class EnergyModel:
    """What the energy of a run counts. ``efficiency``: a number in (0, 1], or ``((speed_kmh, eta),
    ...)`` rising in speed; ``regen_credit``: share in [0, 1] of the electric brake's work credited.
    The default (1, 0) is the traction work at the wheel."""

    efficiency: float | tuple[tuple[float, float], ...] = 1.0
    regen_credit: float = 0.0

    @property
    def is_wheel_work(self) -> bool:
        """True when the energy is the plain traction work at the wheel (the calculator's number)."""
        return self.efficiency == 1.0 and self.regen_credit == 0.0

    def efficiency_at(self, speed_kmh):
        """Traction efficiency at ``speed_kmh`` (numbers, arrays or CasADi symbols)."""
        if isinstance(self.efficiency, (int, float)):
            return float(self.efficiency) + 0 * as_operand(speed_kmh)
        pts = np.asarray(self.efficiency, dtype=float)
        return piecewise_linear(speed_kmh, pts[:, 0], pts[:, 1])

    def label(self) -> str:
        if self.is_wheel_work:
            return "traction work at the wheel"
        eff = (f"{self.efficiency:g}" if isinstance(self.efficiency, (int, float))
               else ",".join(f"{v:g}:{e:g}" for v, e in self.efficiency))
        return f"traction energy drawn (efficiency {eff}, regenerative credit {self.regen_credit:g})"


WHEEL_WORK = EnergyModel()

OBJECTIVES = ("traction", "net")
"""What a planner's energy term counts (``--objective``): ``traction``, the traction work at the wheel
sum F ds (the ISSA paper's eq. 1, the default); ``net``, that work less the energy the electric brake returns
to the line, eta x sum B_e ds (:func:`recovered_energy_kwh`)."""


def energy_rate_kn(traction_kn, electric_brake_kn, speed_kmh, model: EnergyModel = WHEEL_WORK):
    """Energy per metre [kN = kJ/m]: F / eta(v) - r B_e (numbers, arrays or CasADi symbols)."""
    f = as_operand(traction_kn)
    if model.is_wheel_work:
        return f
    out = f / model.efficiency_at(speed_kmh)
    if model.regen_credit:
        out = out - model.regen_credit * as_operand(electric_brake_kn)
    return out


def profile_energy_kwh(s_m, v_kmh, traction_kn, brake_kn, electric_brake_curve, model: EnergyModel = WHEEL_WORK) -> float:
    """Energy [kWh] of one calculator profile (cell-mean forces on the cells of ``s_m``, node speeds
    ``v_kmh``): the sum of :func:`energy_rate_kn` over the cells at their mean speed. The electric
    brake takes its share first (blended braking): B_e = min(B, B_e,max(v)). With the default model
    this is exactly the calculator's traction work."""
    s = np.asarray(s_m, dtype=float)
    v = np.asarray(v_kmh, dtype=float)
    v_mid = 0.5 * (v[1:] + v[:-1])
    brake = np.asarray(brake_kn, dtype=float)
    b_e = electric_share_kn(brake, piecewise_linear(v_mid, *electric_brake_curve))
    rate = energy_rate_kn(np.asarray(traction_kn, dtype=float), b_e, v_mid, model)
    return float(np.sum(rate * np.diff(s)) / KJ_PER_KWH)


def recovered_energy_kwh(s_m, brake_kn, electric_max_kn, efficiency: float):
    """Energy the electric brake returns to the line [kWh]: ``efficiency`` x sum B_e ds over the cells of
    ``s_m``, with B_e = min(B, B_e,max) the electric part of each cell's mean braking force ``brake_kn``
    (blended braking: the electric brake takes its share first) and ``electric_max_kn`` what it has there
    at the cell's speed (0 where the catenary is off, in a neutral section's span). Arrays of cells, or of
    (plans, cells) rows."""
    b_e = electric_share_kn(np.asarray(brake_kn, dtype=float), np.asarray(electric_max_kn, dtype=float))
    return efficiency * np.sum(b_e * np.diff(np.asarray(s_m, dtype=float)), axis=-1) / KJ_PER_KWH
