"""The train's equation of motion along the track, once for every optimal-control problem.

M a = F - W: ``F`` the driving force [kN] (traction; in the minimum-time problem the signed net
control force), ``W`` the forces against it (braking, basic running resistance, gravity on the
equivalent gradient) [kN], ``M`` the (inertial) mass [t]; kN / t = m/s^2. Numbers, numpy arrays and
CasADi symbols alike (arithmetic only), as :mod:`locoplan.physics.backend` asks of every formula.
"""

from __future__ import annotations


def acceleration_ms2(force_kn, mass_t, *resisting_kn):
    """``(F - W_1 - W_2 - ...) / M`` [m/s^2]: ``force_kn`` the driving force [kN], ``mass_t`` [t], then
    the resisting forces [kN] (e.g. ``brake_kn, resistance_kn + gravity_kn``).

    They are subtracted one after the other in the order given: the callers' NLPs depend on that
    order at the last bit (the energy problem's hp refinement turns a rounding difference into a
    different mesh), so each caller keeps the grouping it was validated with."""
    net = force_kn
    for w in resisting_kn:
        net = net - w
    return net / mass_t
