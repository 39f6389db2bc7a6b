"""The compiled loops' inputs and outputs, each one record (a ``NamedTuple`` of arrays and numbers).

The calculator's distance loop (``kernel.run_plans``), its braking envelope and the DP drive's passes
(``optimize/dp_kernel.py``) take these instead of dozens of positional arrays. ``FIELD_TYPES`` gives
every field's type once: ``locoplan.sim.native`` builds the ahead-of-time signatures from it and checks each
call's arrays against it. A plain module (no numba), so building a record costs nothing.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Forces(NamedTuple):
    """The train's force model for the kernels: inertial mass [t], traction (tv, tf), electric brake
    (ev, ef) and air brake (av, af) curves [km/h, kN], and the Davis coefficients (ra, rb, rc) [kN]."""

    m: float
    tv: np.ndarray
    tf: np.ndarray
    ev: np.ndarray
    ef: np.ndarray
    av: np.ndarray
    af: np.ndarray
    ra: float
    rb: float
    rc: float


class Cells(NamedTuple):
    """The calculator's grid: node positions ``s`` [m], cell lengths ``h``, the braking envelope ``e_env``
    and the limits (``e_limit_node``, ``e_limit_cell``) as e = v^2/2 [m^2/s^2], ``allowed`` (1 where the
    catenary feeds traction and the electric brake), ``grav`` the cell's gravity force [kN],
    ``holds_limit`` (the cell's cap is its limit, to be held), ``brake_holds`` (full braking holds the
    limit there), ``t_build`` the air brake's build-up time [s] of an application made in the cell and
    ``next_short`` the first cell from this one on whose grade the electric brake alone cannot hold the limit
    (-1: none); ``e_env_el`` the electric brake's own envelope (the braking curves it alone follows, inf on
    and just before those grades: there the air brake cycles), which caps a train whose air brake recharges,
    and ``next_air`` the first cell from this one on where a braking curve of ``e_env`` needs the air brake
    (-1: none)."""

    s: np.ndarray
    h: np.ndarray
    e_env: np.ndarray
    e_limit_node: np.ndarray
    e_limit_cell: np.ndarray
    allowed: np.ndarray
    grav: np.ndarray
    holds_limit: np.ndarray
    brake_holds: np.ndarray
    t_build: np.ndarray
    next_short: np.ndarray
    e_env_el: np.ndarray
    next_air: np.ndarray


class Plans(NamedTuple):
    """A batch of plans sharing one condition sequence: ``codes`` (n_runs,), where each run starts and
    ends (n, n_runs) [m, inf = never], the cruise speed's e per plan (with ``has_cruise``), whether a plan
    coasting up to a limit is infeasible (``strict``), and whether to write the profile. ``cycle``: the wagons'
    air brake is direct-release (applied, held, released in full, recharged: ``recharge_s`` after a release
    before the next application, held at least ``min_hold_s``, < 0 = its build-up time); per plan and cycle
    region the release margin (n, n_regions + 1; ``kernel.cycle_speeds``; <= 0: the rule's; column 0 is the
    rule's, for cells outside every region), and each cell's region (``margin_region``, (n_cells,), 0 = none)."""

    codes: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    cruise_e: np.ndarray
    has_cruise: bool
    strict: bool
    want_profile: bool
    cycle: bool
    recharge_s: float
    min_hold_s: float
    release_margin: np.ndarray
    margin_region: np.ndarray


class Outputs(NamedTuple):
    """What ``run_plans`` writes per plan: time [s], traction work [kJ], the first cell of each failure
    (-1 = never) and whether it was braking where it came to rest; per plan and node / cell (written only
    with ``want_profile``, else (1, 1) placeholders) the time, speed, condition, forces and events. The air
    brake's cycle per plan: the first cell where it is applied before its recharge is over (-1 = never) and
    the time since its release there [s], its applications and the least recharge margin [s] (time between a
    release and the next application less the recharge time; inf without a re-application); per cell
    (profile) its state (``AIR_*`` codes of ``sim.result``)."""

    t: np.ndarray
    work: np.ndarray
    over_at: np.ndarray
    stop_at: np.ndarray
    hold_at: np.ndarray
    fb_at: np.ndarray
    t_nodes: np.ndarray
    v_nodes: np.ndarray
    cond: np.ndarray
    trac: np.ndarray
    brk: np.ndarray
    event: np.ndarray
    air_at: np.ndarray
    air_wait: np.ndarray
    air_apps: np.ndarray
    air_margin: np.ndarray
    air: np.ndarray


class DPCells(NamedTuple):
    """The DP drive's coarser grid: cell lengths [m], mean gravity force [kN], traction allowed (0/1),
    the cap at each node (e = v^2/2) and the shared speed grid [m/s]."""

    h: np.ndarray
    grav: np.ndarray
    allowed: np.ndarray
    e_cap: np.ndarray
    v_grid: np.ndarray


class CycleCells(NamedTuple):
    """The cycle DP's grid (``optimize/cycle_dp.py``, ``optimize/cycle_kernel.py``): the priced DP's cells
    (lengths ``h`` [m], mean gravity ``grav`` [kN], ``allowed`` catenary 1/0, the cap at each node ``e_cap`` as
    e = v^2/2, the shared speed grid ``v_grid`` [m/s]) and the air brake's: per node whether its state is tracked
    there (``zone`` 1/0; 0 = no air brake), per cell the build-up time of an application made in it (``t_build``
    [s]), the speed at which the calculator applies it on a grade the electric brake cannot hold (``e_app``, e; inf
    elsewhere) and the speed at or below which an application may be kept on with the electric brake eased, or
    released (``e_keep``, e: the calculator's release speed at the least release margin there; inf elsewhere), the
    speed a recharging train stays below (``e_rec``, e: the apply speed less the look-ahead's margin, as the
    calculator releases only where the train stays that far below it through the recharge; inf elsewhere);
    each node's lowest feasible e under full traction (``e_low``, the priced DP's stall boundary); the recharge
    ``t_rec`` and least hold ``t_hold`` [s] (< 0: the build-up time), ``n_rec`` the recharge's states (one every
    ``t_rec / n_rec`` seconds since a release), and ``relaxed``: the air brake as a continuous force everywhere
    (no state: the relaxation's DP)."""

    h: np.ndarray
    grav: np.ndarray
    allowed: np.ndarray
    e_cap: np.ndarray
    v_grid: np.ndarray
    zone: np.ndarray
    t_build: np.ndarray
    e_app: np.ndarray
    e_keep: np.ndarray
    e_rec: np.ndarray
    e_low: np.ndarray
    t_rec: float
    t_hold: float
    n_rec: int
    relaxed: bool


class CycleTables(NamedTuple):
    """What the cycle DP computes once per grid (``optimize/cycle_kernel.py``, ``cycle_prepare``): per node k, grid
    speed j and single-cell control u (``se`` .. [k, j, u]) the step's e at the cell's end, traction work [kJ],
    time [s], verdict (``sok``) and where e lands on the next node's grid (``si`` its lower grid index, -1: above the
    cap; ``sx`` the weight of the upper one, negative where the state lies above that node's stall boundary); per
    zone node (``zmap[k]``: its row, -1 outside the zones) and path m the same for the path's end (``pj`` its node,
    -1: none; ``pq`` the time since its release there [s], for a path that ends recharging); ``top[k]`` the last
    grid index below node k's cap; ``dl[k, j]`` the recharge's deadline at node k and grid speed j: the least time
    since a release [s] from which a recharging train there can go on (0: any; the recharge time: only charged; inf:
    not even charged), written by each backward pass (it does not depend on the price of time); ``ethr[k]`` the
    highest e at node k from which an applied train may be released there and recharge under the electric brake
    (-1: none, or outside the zones)."""

    se: np.ndarray
    sw: np.ndarray
    st: np.ndarray
    sok: np.ndarray
    si: np.ndarray
    sx: np.ndarray
    pj: np.ndarray
    pe: np.ndarray
    pt: np.ndarray
    pw: np.ndarray
    pq: np.ndarray
    pi: np.ndarray
    px: np.ndarray
    top: np.ndarray
    zmap: np.ndarray
    dl: np.ndarray
    ethr: np.ndarray


class CellModel(NamedTuple):
    """E*'s cell problem (``ocp/cells.py``) for its compiled evaluation (``ocp/cell_kernel.py``): ``nf``
    forces per cell (variables ``[v_0, f_0.., v_1, ...]`` scaled by ``v_ref`` and ``f_ref``), the cells'
    lengths ``h`` [m], gravity ``grav`` [kN] and ``allowed`` (catenary 1/0), which caps are real
    (``active`` (N, nf), 1/0), the inertial mass ``m`` [t], the scales (forces, speeds, objective, time), the
    Davis coefficients, the objective's weight on each force (``cost``), each force's cap as a curve fed by
    the catenary (``cap_cat``) plus one that works everywhere (``cap_free``) (indices of the curves, -1 for
    none), the rounded curves end to end (points ``cx``, ``cy``, segment slopes ``cs`` (one more per curve),
    changes of slope ``cd``; curve i's points from ``coff[i]``, its slopes from ``coff[i] + i``; ``cw`` its
    width), and the global inequalities ``(cmask @ tau + cconst) / t_ref <= 0``."""

    nf: int
    h: np.ndarray
    grav: np.ndarray
    allowed: np.ndarray
    active: np.ndarray
    m: float
    f_ref: float
    v_ref: float
    e_ref: float
    t_ref: float
    ra: float
    rb: float
    rc: float
    cost: np.ndarray
    cap_cat: np.ndarray
    cap_free: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    cs: np.ndarray
    cd: np.ndarray
    coff: np.ndarray
    cw: np.ndarray
    cmask: np.ndarray
    cconst: np.ndarray


class IPMLayout(NamedTuple):
    """A cell-structured NLP's layout for the interior-point method's compiled vector work
    (``ocp/ipm_kernel.py``): each cell's variables ``loc`` (N, p), which variables are ``fixed``, the indices
    of those with a lower (``il``) and an upper (``iu``) bound and the bounds ``lb``, ``ub`` (0 where none),
    and the KKT ordering's places of the variables (``pos_x``) and of the cells' equality multipliers
    (``pos_y``)."""

    loc: np.ndarray
    fixed: np.ndarray
    il: np.ndarray
    iu: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    pos_x: np.ndarray
    pos_y: np.ndarray


_F, _B, _A1, _A2 = "f8", "b1", "f8[:]", "f8[:, :]"
FIELD_TYPES: dict[type, tuple[str, ...]] = {
    Forces: ("f8", _A1, _A1, _A1, _A1, _A1, _A1, _F, _F, _F),
    Cells: (_A1, _A1, _A1, _A1, _A1, _A1, _A1, "b1[:]", "b1[:]", _A1, "i8[:]", _A1, "i8[:]"),
    Plans: ("i8[:]", _A2, _A2, _A1, _B, _B, _B, _B, _F, _F, _A2, "i8[:]"),
    Outputs: (_A1, _A1, "i8[:]", "i8[:]", "i8[:]", "i8[:]", _A2, _A2, "i1[:, :]", _A2, _A2, _A2, "i8[:]", _A1,
              "i8[:]", _A1, "i1[:, :]"),
    DPCells: (_A1, _A1, _A1, _A1, _A1),
    CycleCells: (_A1, _A1, _A1, _A1, _A1, "i8[:]", _A1, _A1, _A1, _A1, _A1, _F, _F, "i8", _B),
    CycleTables: ("f8[:, :, :]", "f8[:, :, :]", "f8[:, :, :]", "i1[:, :, :]", "i4[:, :, :]", "f8[:, :, :]",
                  "i4[:, :, :]", "f8[:, :, :]", "f8[:, :, :]", "f8[:, :, :]", "f8[:, :, :]", "i4[:, :, :]", "f8[:, :, :]",
                  "i8[:]", "i8[:]", _A2, _A1),
    CellModel: ("i8", _A1, _A1, _A1, _A2, _F, _F, _F, _F, _F, _F, _F, _F, _A1, "i8[:]", "i8[:]", _A1, _A1, _A1, _A1,
                "i8[:]", _A1, _A2, _A1),
    IPMLayout: ("i8[:, :]", "b1[:]", "i8[:]", "i8[:]", _A1, _A1, "i8[:]", "i8[:]"),
}
"""Each record's field types, in field order ("f8[:]" = a C-contiguous float64 vector)."""
assert all(len(t) == len(r._fields) for r, t in FIELD_TYPES.items())


def contiguous(record):
    """The record with every array C-contiguous and scalars as Python numbers (what the compiled
    functions read)."""
    out = []
    for value, kind in zip(record, FIELD_TYPES[type(record)]):
        if "[" in kind:
            out.append(np.ascontiguousarray(value))
        else:
            out.append({"f8": float, "b1": bool, "i8": int}[kind](value))
    return type(record)(*out)
