"""Basic running resistance (Davis form, TB/T 1407; seed 002 Tables 2-3, seed 000 eq. 2-3)."""

from __future__ import annotations

from ..model.train import G_MS2
from .backend import as_operand


def basic_resistance_n_per_kn(speed_kmh, a: float, b: float, c: float):
    """Unit basic resistance w0 = a + b v + c v^2 [N/kN] at ``speed_kmh`` [km/h]; scalars, arrays or
    CasADi symbols."""
    v = as_operand(speed_kmh)
    return a + v * (b + c * v)


def basic_resistance_kn(speed_kmh, a: float, b: float, c: float, mass_t: float):
    """Basic resistance of one vehicle [kN]: w0 [N/kN] times its weight mass_t * g [kN], divided by 1000."""
    return basic_resistance_n_per_kn(speed_kmh, a, b, c) * mass_t * G_MS2 / 1000.0


def train_resistance_kn(speed_kmh, resistance_kn: tuple[float, float, float]):
    """Whole-train basic resistance A + B v + C v^2 [kN], v in km/h (coefficients from ``Train``);
    scalars, arrays or CasADi symbols."""
    a, b, c = resistance_kn
    v = as_operand(speed_kmh)
    return a + v * (b + c * v)
