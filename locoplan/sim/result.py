"""Typed results of the batch traction calculator."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.conditions import CODE, CONDITIONS  # noqa: F401  (the codes of ``Profile.condition``)

from .constants import AIR_APPLIED, AIR_OFF, AIR_ON, AIR_RELEASED  # noqa: F401  (the codes of ``Profile.air``)

OK, LIMIT_EXCEEDED, STALLED, STOPPED_SHORT, CANNOT_HOLD, IMPOSSIBLE, COUPLER_LIMIT, FORCE_RATE, AIR_RECHARGE, AIR_HELD = range(10)
REASONS = {OK: "ok", LIMIT_EXCEEDED: "limit exceeded", STALLED: "stalled", STOPPED_SHORT: "did not stop at the end",
           CANNOT_HOLD: "full braking cannot hold the limit",
           IMPOSSIBLE: "no entry speed keeps the limit under full braking",
           COUPLER_LIMIT: "coupler force over the consist's limit",
           FORCE_RATE: "force changes faster than the consist's limit",
           AIR_RECHARGE: "air brake applied again before its recharge is over",
           AIR_HELD: "brought to rest by an air brake application it could not release"}
NEVER_ARRIVED = (STALLED, STOPPED_SHORT, CANNOT_HOLD, IMPOSSIBLE, AIR_HELD)
"""Failures after which the train does not reach the stop (no running time); a plan refused for its coupler
forces, its force rate or its air brake's recharge runs to the end and keeps its time and energy."""


@dataclass(frozen=True)
class Profile:
    """Per-plan trajectories on the calculator's distance grid (n_plans rows).

    ``s_m`` (n_nodes,) node positions; ``t_s`` and ``v_kmh`` (n_plans, n_nodes) at the nodes;
    ``condition`` (n_plans, n_cells) the condition actually applied in each cell (codes into
    ``CONDITIONS``; a T held at a limit shows as K, braking forced by a braking curve as B);
    ``traction_kn`` / ``brake_kn`` (n_plans, n_cells) mean forces over each cell.
    """

    s_m: np.ndarray
    t_s: np.ndarray
    v_kmh: np.ndarray
    condition: np.ndarray
    traction_kn: np.ndarray
    brake_kn: np.ndarray
    limit_kmh: np.ndarray
    gradient_permille: np.ndarray
    event_m: np.ndarray | None = None

    """``event_m`` (n_plans, n_cells): where inside a cell the condition changes (a limit or braking
    curve reached, or a plan's switch), NaN where it does not; used to report exact switching points."""
    coupler_tension_kn: np.ndarray | None = None
    coupler_compression_kn: np.ndarray | None = None
    """(n_plans, n_cells): the largest tensile and the largest compressive force [kN] (both >= 0) in any
    coupler of the train in each cell (``physics.couplers``); None for a train of one vehicle."""
    air: np.ndarray | None = None
    """(n_plans, n_cells) int8: the wagons' air brake in each cell (``AIR_OFF``, ``AIR_ON``, ``AIR_APPLIED`` =
    an application begins in the cell, ``AIR_RELEASED`` = released at the cell's start); None without the
    air brake's cycle (the electric brake alone, or the air brake as a continuous force)."""

    def plan(self, i: int) -> "Profile":
        """The profile of plan ``i`` alone (rows kept 2-D)."""
        sl = slice(i, i + 1)

        def rows(a):
            return None if a is None else a[sl]

        return Profile(self.s_m, self.t_s[sl], self.v_kmh[sl], self.condition[sl], self.traction_kn[sl],
                       self.brake_kn[sl], self.limit_kmh, self.gradient_permille, rows(self.event_m),
                       rows(self.coupler_tension_kn), rows(self.coupler_compression_kn), rows(self.air))


@dataclass(frozen=True)
class BatchResult:
    """Per-plan outcome of one batch evaluation (arrays of length n_plans)."""

    running_time_s: np.ndarray
    traction_energy_kwh: np.ndarray
    feasible: np.ndarray
    reason_code: np.ndarray
    failure_m: np.ndarray
    profile: Profile | None = None
    failure_limit_kmh: np.ndarray | None = None
    failure_gradient_permille: np.ndarray | None = None
    failure_brake_kn: np.ndarray | None = None
    impossible: str | None = None
    """Why no plan at all can run the route (the train passes a limit under full braking even from rest
    at the top of a descent); every plan then has the reason code ``IMPOSSIBLE``."""
    recovered_energy_kwh: np.ndarray | None = None
    """Energy the electric brake returned to the line [kWh] per plan (``physics.energy.recovered_energy_kwh``,
    0 for locomotives without ``regen_efficiency``); computed with the profile (or on request), else None."""
    failure_force: np.ndarray | None = None
    """The coupler force [kN] (+ tension, - compression) or the force rate [kN/s] that refused a plan
    (``COUPLER_LIMIT``, ``FORCE_RATE``), NaN for the others."""
    force_limits: tuple[float | None, float | None] = (None, None)
    """The consist's coupler limit [kN] and force-rate limit [kN/s] the plans were checked against."""
    air_applications: np.ndarray | None = None
    """Applications of the air brake per plan (with its cycle; None without)."""
    air_margin_s: np.ndarray | None = None
    """The least recharge margin per plan [s]: the shortest time between a release and the next application
    less the recharge time (< 0: refused, ``AIR_RECHARGE``; inf: no application follows a release)."""
    air_wait_s: np.ndarray | None = None
    """Time from the release to the application that refused a plan [s] (``AIR_RECHARGE``; NaN otherwise)."""
    recharge_s: float | None = None
    """The recharge time the plans were held to [s] (with the air brake's cycle)."""

    @property
    def net_energy_kwh(self) -> np.ndarray | None:
        """Traction energy less the energy the electric brake recovered [kWh] per plan (None without the
        recovered energy)."""
        if self.recovered_energy_kwh is None:
            return None
        return self.traction_energy_kwh - self.recovered_energy_kwh

    def energy_kwh(self, objective: str = "traction") -> np.ndarray:
        """The energy an objective counts [kWh] per plan: ``traction`` (sum F ds) or ``net`` (less the
        recovered energy, which must have been computed)."""
        if objective == "traction":
            return self.traction_energy_kwh
        if self.recovered_energy_kwh is None:
            raise ValueError("the net energy needs the recovered energy: evaluate with recovered=True")
        return self.net_energy_kwh

    def failures(self) -> str:
        """Why the infeasible plans of this batch failed, most common first, each with an example:
        '42 stalled (e.g. stalled at 4,520 m on +12.0 per mille), 8 ...' ('' when all are feasible)."""
        bad = np.flatnonzero(~np.asarray(self.feasible, dtype=bool))
        if not bad.size:
            return ""
        codes, counts = np.unique(self.reason_code[bad], return_counts=True)
        parts = []
        for code, n in sorted(zip(codes.tolist(), counts.tolist()), key=lambda x: -x[1]):
            example = bad[self.reason_code[bad] == code][0]
            parts.append(f"{n} {REASONS[int(code)]} (e.g. {self.reason(int(example))})")
        return f"of {len(self.feasible)} plans, " + ", ".join(parts)

    def reason(self, i: int) -> str:
        """Human-readable feasibility verdict of plan ``i``: what failed, where, and the physics of it."""
        code = int(self.reason_code[i])
        if code == OK:
            return "ok"
        where = float(self.failure_m[i])
        grad = None if self.failure_gradient_permille is None else float(self.failure_gradient_permille[i])
        on = "" if grad is None else f" on {grad:+.1f} per mille"
        if code == IMPOSSIBLE:
            return self.impossible or REASONS[IMPOSSIBLE]
        if code == CANNOT_HOLD:
            brake = float(self.failure_brake_kn[i]) if self.failure_brake_kn is not None else float("nan")
            limit = float(self.failure_limit_kmh[i]) if self.failure_limit_kmh is not None else float("nan")
            return f"full braking ({brake:,.0f} kN) cannot hold {limit:g} km/h{on} at {where:,.0f} m"
        if code == LIMIT_EXCEEDED:
            return f"limit exceeded at {where:,.0f} m"
        if code == COUPLER_LIMIT:
            x = float(self.failure_force[i])
            side = "tension" if x > 0 else "compression"
            return (f"coupler force {abs(x):,.0f} kN in {side} over the consist's limit {self.force_limits[0]:,.0f} kN "
                    f"at {where:,.0f} m{on}")
        if code == FORCE_RATE:
            return (f"traction less braking changes at {float(self.failure_force[i]):,.0f} kN/s, over the consist's "
                    f"limit {self.force_limits[1]:,.0f} kN/s, at {where:,.0f} m")
        if code == AIR_RECHARGE:
            wait = float(self.air_wait_s[i])
            return (f"air brake applied again {wait:.0f} s after its release, before its recharge of {self.recharge_s:.0f} s "
                    f"was over, at {where:,.0f} m{on}: the cycle cannot hold the speed there")
        if code == STALLED:
            return f"stalled at {where:,.0f} m{on}"
        if code == AIR_HELD:
            return (f"brought to rest at {where:,.0f} m{on} by an air brake application it could not release: in its "
                    f"recharge of {self.recharge_s:.0f} s the train would run over the speed at which it must apply "
                    "again (the electric brake cannot hold it there, or is cut in a neutral section)")
        return f"did not stop at the end: came to rest at {where:,.0f} m"
