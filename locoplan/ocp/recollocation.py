"""The two-stage adaptive Gauss re-collocation of the control (the two-stage Gauss paper's section 3, eq. 26-31, Fig. 3-4).

Stage 1 solves the Gauss transcription with the control paired on the LG points
(:func:`~locoplan.ocp.gauss.paired_control_map`); :func:`recollocate` reads its slope changes and
returns the stage-2 :class:`~locoplan.ocp.mesh.Mesh` (the paper's single-interval re-grouping, or our
hp extension with moving break points on the detected switches).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from .gauss import GaussSolution, gauss_interval, gauss_mesh, grouped_control_map, lagrange_control_map, single_mesh
from .mesh import Mesh

__all__ = ["recollocate", "recollocated_groups", "slope_changes"]


def slope_changes(params: np.ndarray, tau: np.ndarray, u_range: float) -> np.ndarray:
    """The paper's eq. 28 for one control after the paired stage 1:
    ``S_{l+1} = (U_{l+1} - U_l) / (tau_{2l+1} - tau_{2l-1})``, ``l = 1 .. L-1``.

    ``params`` are the ``L`` paired values, ``tau`` the ``2 L`` LG points. The paper's thresholds
    (``eps = 0.04``) only make sense for a dimensionless control, so the values are divided by
    ``u_range`` (the width of the control bounds) and the magnitude ``|S|`` is returned (a drop is as
    much a jump as a rise).
    """
    u = np.asarray(params, dtype=float).reshape(-1) / float(u_range)
    tau = np.asarray(tau, dtype=float).reshape(-1)
    if tau.size != 2 * u.size:
        raise InputError(f"slope change: {u.size} paired values need {2 * u.size} LG points, got {tau.size}")
    first = tau[0::2]  # tau_{2l-1}, l = 1..L
    return np.abs(np.diff(u)) / np.diff(first)


def _groups_from_ties(tied: np.ndarray) -> list[int]:
    """Group sizes from ``tied[i]`` = "LG point i shares the value of point i-1" (tied[0] ignored)."""
    sizes = [1]
    for t in tied[1:]:
        if t:
            sizes[-1] += 1
        else:
            sizes.append(1)
    return sizes


def recollocated_groups(s: np.ndarray, eps_upper: float, eps_lower: float) -> list[int]:
    """Stage-2 control groups on the *same* LG points (the paper's single-interval stage 2).

    Start from the pairs ``U_{2l-1} = U_{2l}``. Where ``S_{l+1} <= eps_L`` (eq. 30) the next pair is
    merged into the current group (``U_{l+1} = U_l``, eq. 31). Where ``S_{l+1} >= eps_U`` (eq. 29) the
    interval ``[tau_{2l-1}, tau_{2l+1}]`` is subdivided: the points of pair ``l`` and of pair ``l + 1``
    get a value each. Subdivision wins over merging. Returns group sizes (they sum to ``2 L``).
    """
    s = np.asarray(s, dtype=float)
    n = 2 * (s.size + 1)
    tied = np.zeros(n, dtype=bool)
    tied[1::2] = True  # pairs (0-based: point 2l+1 tied to 2l)
    for l, sl in enumerate(s):  # boundary between pair l and pair l+1 (0-based)
        if sl <= eps_lower and sl < eps_upper:
            tied[2 * l + 2] = True  # merge pair l+1 into the group of pair l
    for l, sl in enumerate(s):
        if sl >= eps_upper:
            tied[2 * l + 1] = False  # split pair l
            tied[2 * l + 2] = False  # new value at tau_{2l+1}
            tied[2 * l + 3] = False  # split pair l+1
    return _groups_from_ties(tied)


def recollocate(
    stage1: GaussSolution,
    u_range: float,
    *,
    eps_upper: float = 0.04,
    eps_lower: float | None = None,
    mode: str = "hp",
    max_jump_boundaries: int = 3,
    widen: float = 1.0,
) -> Mesh:
    """Stage-2 mesh from a paired stage-1 solution (single segment, paired control map).

    ``mode="global"`` is the paper's stage 2: same LG points, control groups from
    :func:`recollocated_groups`. ``mode="hp"`` (our extension, needed for a bang-bang optimum to be
    resolved to ~0.01 s) uses the same eq. 28-31 classification to cut the *state* mesh as well:

    * every short run (``<= max_jump_boundaries``) of consecutive jump boundaries ``S >= eps_U`` is a
      control switch; it gets a break point, first guessed at the largest jump of the run;
    * a longer run is a steep stretch (or stage-1 noise) and becomes a segment of its own with a
      linear control between its two ends (a break point at each end; two control parameters whose
      bounds keep the whole ramp inside the control bounds);
    * the break points are decision variables ("moving mesh"): each may move half-way towards the
      neighbouring guesses (``widen = 1``) or anywhere in (0, 1) (``widen = inf``), segments being
      kept at least ``1e-4 t_f`` long;
    * between them the control is smooth (``S <= eps_L``): by eq. 31 it is merged to one value;
    * the ``2 L`` state nodes of stage 1 are shared out evenly among the segments (if that leaves
      fewer than 3 per segment, the global mode is used instead).

    Multiple controls: a boundary counts as a jump if any control jumps there.
    """
    if mode not in ("hp", "global"):
        raise InputError(f"two-stage: stage-2 mode must be 'hp' or 'global', got {mode!r}")
    eps_lower = eps_upper if eps_lower is None else float(eps_lower)
    if not (eps_upper > 0 and eps_lower > 0 and eps_lower <= eps_upper):
        raise InputError(f"two-stage: need 0 < eps_L <= eps_U, got eps_U = {eps_upper}, eps_L = {eps_lower}")
    if len(stage1.segments) != 1:
        raise InputError("two-stage: stage 1 must be a single-segment (global) solution")
    seg = stage1.segments[0]
    n = len(seg.tau)
    s = np.max(np.atleast_2d([slope_changes(p, seg.tau, u_range) for p in seg.params]), axis=0)
    if mode == "global":
        return single_mesh(n, grouped_control_map(recollocated_groups(s, eps_upper, eps_lower)))

    tf = stage1.final_time
    sig_lg = seg.lg_times / tf
    jump = s >= eps_upper
    # runs of consecutive jump boundaries (0-based boundary l sits between pair l and pair l+1)
    runs, l = [], 0
    while l < jump.size:
        if jump[l]:
            start = l
            while l + 1 < jump.size and jump[l + 1]:
                l += 1
            runs.append((start, l))
        l += 1
    # break point guesses: the largest jump of a short run (a control switch); both ends of a long
    # run (a steep stretch, which becomes a segment with a linear control)
    bps, kinds = [], ["flat"]
    for a, b in runs:
        lo_idx, hi_idx = 2 * a, min(2 * b + 2, n - 1)  # tau_{2a-1} .. tau_{2b+1} (0-based)
        if b - a + 1 <= max_jump_boundaries:
            big = a + int(np.argmax(s[a : b + 1]))
            bps.append(0.5 * (sig_lg[2 * big + 1] + sig_lg[min(2 * big + 2, n - 1)]))
            kinds.append("flat")
        else:
            bps.extend([sig_lg[lo_idx], sig_lg[hi_idx]])
            kinds.extend(["ramp", "flat"])
    k = len(kinds)
    sizes = [n // k + (1 if i < n % k else 0) for i in range(k)]
    if min(sizes) < 3:  # too many jumps for the nodes: keep the paper's single interval
        return single_mesh(n, grouped_control_map(recollocated_groups(s, eps_upper, eps_lower)))
    segments = tuple(
        gauss_interval(m, np.ones((m, 1)) if kind == "flat" else lagrange_control_map(m, (-1.0, 1.0)))
        for m, kind in zip(sizes, kinds)
    )
    if not bps:
        return gauss_mesh(segments)
    # every break point is free: it may move half-way towards its neighbours' guesses (``widen`` =
    # 1), or anywhere between the ends (``widen = inf``; the ordering constraint keeps segments apart)
    margin = 0.5 * min(sig_lg[0], 1.0 - sig_lg[-1])
    ext = [0.0] + bps + [1.0]
    bounds = []
    for i in range(1, len(ext) - 1):
        if math.isinf(widen):
            lo, hi = margin, 1.0 - margin
        else:
            lo = max(margin, ext[i] - 0.5 * widen * (ext[i] - ext[i - 1]))
            hi = min(1.0 - margin, ext[i] + 0.5 * widen * (ext[i + 1] - ext[i]))
        bounds.append((lo, hi))
    bps = [float(np.clip(v, lo, hi)) for v, (lo, hi) in zip(bps, bounds)]
    return gauss_mesh(segments, tuple(bps), tuple(bounds), min_fraction=1e-4)
