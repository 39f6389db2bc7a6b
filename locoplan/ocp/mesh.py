"""Meshes of a multi-phase problem and their hp refinement (GPOPS-II's ph idea, the MPOC paper's Fig. 4).

A :class:`Mesh` is a flat, ordered list of :class:`Interval` s covering the problem; every interval
lies in one phase and carries its number of Legendre-Gauss-Radau (LGR) collocation points ``n``
(the state is a degree-``n`` polynomial on it). :class:`Grid` lays a mesh out as arrays: the
``N + 1`` state points (each interval's ``n`` LGR points, the last interval's end), the mapping
``s(tau)`` of every interval and its derivative, the block Radau differentiation matrix and the
quadrature weights. Consecutive intervals share their boundary point, so states are continuous
inside a phase and across phases (the linkage) without extra constraints.

Interval mappings: ``linear``; ``start`` = ``s = s_a + (s_b - s_a) ((1 + tau) / 2)^2`` and ``end`` =
``s = s_b - (s_b - s_a) ((1 - tau) / 2)^2``, used on the first / last interval of a rest-to-rest
problem: a train leaving rest has ``v ~ sqrt(s)``, which no polynomial in ``s`` follows well, but it
is linear in ``sqrt(s)``, so in ``tau`` the states are smooth again.

Refinement (:func:`refine`): where an interval above the tolerance (see ``radau.interval_errors``)
holds a control switch, a moving mesh point goes onto it, with the arcs either side held (our
extension, as the two-stage Gauss paper's two-stage hp stage); elsewhere the degree is raised by
``P = ceil(log(e / tol) / log(n))`` (GPOPS-II eq. 29) up to ``max_degree``, beyond which the interval is
cut into pieces of ``min_degree``, or cut at a kink where raising did not help.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from . import nodes as _nodes

MAPPINGS = ("linear", "start", "end")


@dataclass(frozen=True)
class Interval:
    """``[s_a, s_b]`` in phase ``phase`` with ``n`` LGR points and a mapping from ``MAPPINGS``."""

    phase: int
    s_a: float
    s_b: float
    n: int
    mapping: str = "linear"
    free_start: tuple[float, float] | None = None
    """Bounds within which ``s_a`` (shared with the previous interval's end) is an NLP variable: a
    moving mesh point placed on a detected switch (None: fixed)."""
    last_error: float | None = None
    """The interval's error on the previous mesh when its degree was raised at the last refinement
    (if raising did not halve it, the solution is not smooth here and the interval is split); None
    once a refinement leaves it as it is."""
    regime: tuple[str | None, ...] | None = None
    """Per control: ``"lower"`` (held at its lower bound), ``"upper"`` (at its upper or speed-dependent
    bound) or ``None`` (free) on the whole interval: the arc the solution showed next to a switch,
    so that the switch has to sit on the moving point between the arcs (the two-stage Gauss paper's merging, eq. 31)."""
    control_map: np.ndarray | None = field(default=None, compare=False, repr=False)
    """Gauss transcription only: the ``n x m`` matrix ``C`` giving the control at the ``n`` collocation
    points from the interval's ``m`` control parameters, ``U = C P`` (``None``: one value per point; see
    :mod:`~locoplan.ocp.gauss`)."""

    @property
    def length(self) -> float:
        return self.s_b - self.s_a

    def s_of(self, tau) -> np.ndarray:
        """Position [m] of ``tau`` in [-1, 1]."""
        tau = np.asarray(tau, dtype=float)
        d = self.length
        if self.mapping == "start":
            return self.s_a + d * ((1.0 + tau) / 2.0) ** 2
        if self.mapping == "end":
            return self.s_b - d * ((1.0 - tau) / 2.0) ** 2
        return self.s_a + d * (1.0 + tau) / 2.0

    def ds_dtau(self, tau) -> np.ndarray:
        tau = np.asarray(tau, dtype=float)
        d = self.length
        if self.mapping == "start":
            return d * (1.0 + tau) / 2.0
        if self.mapping == "end":
            return d * (1.0 - tau) / 2.0
        return np.full_like(tau, d / 2.0)

    def tau_of(self, s) -> np.ndarray:
        """Inverse of :meth:`s_of` (clipped to [-1, 1])."""
        s = np.asarray(s, dtype=float)
        d = self.length
        if self.mapping == "start":
            tau = 2.0 * np.sqrt(np.clip((s - self.s_a) / d, 0.0, 1.0)) - 1.0
        elif self.mapping == "end":
            tau = 1.0 - 2.0 * np.sqrt(np.clip((self.s_b - s) / d, 0.0, 1.0))
        else:
            tau = 2.0 * (s - self.s_a) / d - 1.0
        return np.clip(tau, -1.0, 1.0)

    def shape(self, tau) -> tuple[np.ndarray, np.ndarray]:
        """``(g, g')`` with ``s = s_a + (s_b - s_a) g(tau)``: the mapping without its end points."""
        tau = np.asarray(tau, dtype=float)
        if self.mapping == "start":
            return ((1.0 + tau) / 2.0) ** 2, (1.0 + tau) / 2.0
        if self.mapping == "end":
            return 1.0 - ((1.0 - tau) / 2.0) ** 2, (1.0 - tau) / 2.0
        return (1.0 + tau) / 2.0, np.full_like(tau, 0.5)

    @property
    def sqrt_factor(self) -> float:
        """``d sqrt(s - s_a) / d tau`` of a ``start`` interval (constant: ``sqrt(length) / 2``)."""
        return math.sqrt(self.length) / 2.0


@dataclass(frozen=True)
class Mesh:
    """Intervals in order, each with its collocation points; shared by both transcriptions.

    The Radau transcription lays a mesh over the phases' independent variable (positions [m]); the
    Gauss transcription of a free-end problem over the fraction ``sigma = s / s_end`` in [0, 1] (its
    interior interval starts are the break points, moving ones where ``free_start`` is set).
    ``min_fraction`` is the smallest share of ``[0, 1]`` a Gauss interval may shrink to."""

    intervals: tuple[Interval, ...]
    min_fraction: float = 1e-4

    @property
    def n_state_nodes(self) -> int:
        """Collocation points of all intervals (the Gauss transcription's state LG points)."""
        return self.n_points

    @property
    def n_control_params(self) -> int:
        """Control parameters per control: an interval's map columns, else its collocation points."""
        return sum(iv.n if iv.control_map is None else iv.control_map.shape[1] for iv in self.intervals)

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """The interior interval boundaries."""
        return tuple(iv.s_a for iv in self.intervals[1:])

    @property
    def breakpoint_bounds(self) -> tuple[tuple[float, float], ...] | None:
        """The moving range of every interior boundary when all of them move, else ``None``."""
        free = [iv.free_start for iv in self.intervals[1:]]
        return tuple(free) if free and all(f is not None for f in free) else None

    @property
    def free_breakpoints(self) -> bool:
        return self.breakpoint_bounds is not None

    def with_breakpoints(self, breakpoints) -> "Mesh":
        """The same intervals with the interior boundaries moved to ``breakpoints`` (bounds kept)."""
        edges = [self.intervals[0].s_a, *(float(b) for b in breakpoints), self.intervals[-1].s_b]
        if len(edges) != len(self.intervals) + 1:
            raise ValueError(f"mesh: {len(self.intervals) - 1} break points needed, got {len(edges) - 2}")
        return replace(self, intervals=tuple(replace(iv, s_a=a, s_b=b)
                                             for iv, a, b in zip(self.intervals, edges[:-1], edges[1:])))

    @property
    def n_points(self) -> int:
        """Collocation points (the state has one more point: the end)."""
        return sum(iv.n for iv in self.intervals)

    def plain(self) -> "Mesh":
        """The same intervals with no moving points, fixed arcs or error history: a start for a
        neighbouring problem (another running time), whose switches lie elsewhere."""
        return replace(self, intervals=tuple(replace(iv, free_start=None, last_error=None, regime=None)
                                             for iv in self.intervals))

    def describe(self) -> str:
        degs = [iv.n for iv in self.intervals]
        return f"{len(degs)} intervals, {sum(degs)} LGR points (degree {min(degs)}..{max(degs)})"


def initial_mesh(phases, degree: int = 4, max_length: float | None = None, rest_start: bool = False,
                 rest_end: bool = False, end_length: float | None = None) -> Mesh:
    """One interval per phase (cut into pieces no longer than ``max_length``), ``degree`` LGR points
    each; with ``rest_start`` / ``rest_end`` the first / last interval is mapped quadratically and,
    if ``end_length`` is given, kept no longer than it (the start and the stop are where the
    solution changes fastest)."""
    out: list[Interval] = []
    for k, ph in enumerate(phases):
        edges = [ph.s0, ph.s1]
        if max_length and ph.length > max_length:
            edges = list(np.linspace(ph.s0, ph.s1, int(math.ceil(ph.length / max_length)) + 1))
        if end_length and k == 0 and rest_start and edges[1] - edges[0] > end_length:
            edges.insert(1, edges[0] + end_length)
        if end_length and k == len(phases) - 1 and rest_end and edges[-1] - edges[-2] > end_length:
            edges.insert(-1, edges[-1] - end_length)
        for a, b in zip(edges[:-1], edges[1:]):
            out.append(Interval(k, float(a), float(b), degree))
    if rest_start:
        out[0] = replace(out[0], mapping="start")
    if rest_end:
        out[-1] = replace(out[-1], mapping="end" if out[-1].mapping == "linear" else out[-1].mapping)
    if len(out) == 1 and rest_start and rest_end:  # one interval cannot be both: cut it
        iv = out[0]
        mid = 0.5 * (iv.s_a + iv.s_b)
        out = [Interval(iv.phase, iv.s_a, mid, degree, "start"), Interval(iv.phase, mid, iv.s_b, degree, "end")]
    return Mesh(tuple(out))


class Grid:
    """A mesh laid out as arrays for the transcription (see the module text)."""

    def __init__(self, mesh: Mesh):
        self.mesh = mesh
        ivs = mesh.intervals
        self.n_col = mesh.n_points
        self.offsets = np.concatenate([[0], np.cumsum([iv.n for iv in ivs])]).astype(int)
        tau, s, jac, w, phase, interval = [], [], [], [], [], []
        rows, cols, vals = [], [], []
        for i, iv in enumerate(ivs):
            x, wq = _nodes.legendre_gauss_radau(iv.n)
            d = _nodes.radau_differentiation_matrix(iv.n)
            off = self.offsets[i]
            r, c = np.nonzero(d)
            rows.append(r + off)
            cols.append(c + off)
            vals.append(d[r, c])
            tau.append(x)
            s.append(iv.s_of(x))
            j = iv.ds_dtau(x)
            jac.append(j)
            w.append(wq * j)
            phase.append(np.full(iv.n, iv.phase))
            interval.append(np.full(iv.n, i))
        self.tau = np.concatenate(tau)
        self.s_col = np.concatenate(s)
        self.jacobian = np.concatenate(jac)
        self.weights = np.concatenate(w)  # quadrature weights in s: sum w f = integral of f ds
        self.phase_col = np.concatenate(phase).astype(int)
        self.interval_col = np.concatenate(interval).astype(int)
        self.s_points = np.concatenate([self.s_col, [ivs[-1].s_b]])
        # moving mesh points: s_a of the intervals with ``free_start``. Node positions and ds/dtau are
        # affine in them: s = s_a + (s_b - s_a) g(tau), ds/dtau = (s_b - s_a) g'(tau) (times 2 for
        # the quadratic maps' own factor, already in g').
        self.free = [i for i, iv in enumerate(ivs) if iv.free_start is not None]
        self.free_bounds = np.array([ivs[i].free_start for i in self.free], dtype=float).reshape(-1, 2)
        nf = len(self.free)
        g_all, dg_all = [], []
        for iv in ivs:
            x, _ = _nodes.legendre_gauss_radau(iv.n)
            g, dg = iv.shape(x)
            g_all.append(g)
            dg_all.append(dg)
        self.g = np.concatenate(g_all)
        self.dg = np.concatenate(dg_all)
        # per node: s_a = a0 + Aa z, s_b = b0 + Ab z (z = the free points' positions)
        a0 = np.repeat([iv.s_a for iv in ivs], [iv.n for iv in ivs]).astype(float)
        b0 = np.repeat([iv.s_b for iv in ivs], [iv.n for iv in ivs]).astype(float)
        Aa = np.zeros((self.n_col, nf))
        Ab = np.zeros((self.n_col, nf))
        for j, i in enumerate(self.free):
            Aa[self.cols_of(i), j] = 1.0
            Ab[self.cols_of(i - 1), j] = 1.0
            a0[self.cols_of(i)] = 0.0
            b0[self.cols_of(i - 1)] = 0.0
        self.a0, self.b0, self.Aa, self.Ab = a0, b0, Aa, Ab
        self.D = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                               shape=(self.n_col, self.n_col + 1))
        # the rest start: the first point of a 'start' interval, where ds/dtau = 0
        self.singular = np.zeros(self.n_col, dtype=bool)
        self.sqrt_factor = np.zeros(self.n_col)
        if ivs[0].mapping == "start":
            self.singular[0] = True
            self.sqrt_factor[0] = ivs[0].sqrt_factor

    def points_of(self, i: int) -> slice:
        """State points of interval ``i`` (its ``n`` LGR points and its end)."""
        return slice(self.offsets[i], self.offsets[i + 1] + 1)

    def cols_of(self, i: int) -> slice:
        """Collocation points of interval ``i``."""
        return slice(self.offsets[i], self.offsets[i + 1])

    @cached_property
    def phase_points(self) -> list[np.ndarray]:
        """Indices of the state points of each phase (boundary points belong to both phases)."""
        n_phase = max(iv.phase for iv in self.mesh.intervals) + 1
        out: list[list[int]] = [[] for _ in range(n_phase)]
        for i, iv in enumerate(self.mesh.intervals):
            out[iv.phase].extend(range(self.offsets[i], self.offsets[i + 1] + 1))
        return [np.unique(np.array(x, dtype=int)) for x in out]


# --------------------------------------------------------------------------------------------------
# refinement
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RefineSettings:
    """``tol``: relative error to reach; ``min_degree`` / ``max_degree``: LGR points per interval;
    ``jump``: a control change between neighbouring points above this share of its scale marks a
    switch; ``min_length``: intervals are not cut below this length [units of s]; ``kink``: a corner
    of the controls is cut at only where a point lies this share of its scale off the chord of its
    neighbours (a smaller bend is no corner: the interval is cut into pieces instead)."""

    tol: float = 1e-5
    min_degree: int = 3
    max_degree: int = 10
    jump: float = 0.05
    margin: float = 0.3
    min_length: float = 1e-3
    kink: float = 1e-3


def _switch_gaps(u: np.ndarray, lower: np.ndarray | None, upper: np.ndarray | None, jump: float) -> np.ndarray:
    """Gaps between neighbouring collocation points (gap k lies between points k and k + 1) where a
    control switches: it changes by more than ``jump`` of its scale (``u`` is scaled), or by more
    than a tenth of that while it leaves or reaches a bound."""
    du = np.max(np.abs(np.diff(u, axis=1)), axis=0)
    hit = du > jump
    if lower is not None:
        pat = np.vstack([lower, upper])
        hit |= np.any(pat[:, 1:] != pat[:, :-1], axis=0) & (du > 0.1 * jump)
    return hit


def _kink(s: np.ndarray, u: np.ndarray, visible: float) -> float | None:
    """Where the controls' slope changes most between neighbouring collocation points (a kink, such
    as a force curve's corner crossed at full traction): the point between the two gaps; None when no
    point leaves the line through its two neighbours by more than ``visible`` (a share of the control's
    scale, ``u`` is scaled): a straight or merely curved control has no corner to cut at."""
    if s.size < 3:
        return None
    slope = np.diff(u, axis=1) / np.diff(s)[None, :]
    change = np.max(np.abs(np.diff(slope, axis=1)), axis=0)
    k = int(np.argmax(change))
    # how far the middle point lies off the chord of its neighbours
    w = (s[k + 1] - s[k]) / (s[k + 2] - s[k])
    off = np.max(np.abs(u[:, k + 1] - ((1 - w) * u[:, k] + w * u[:, k + 2])))
    return float(s[k + 1]) if off > visible else None


def _node(iv: Interval, k: int) -> float:
    """Position of the ``k``-th LGR point of ``iv`` (negative ``k`` counts from its last)."""
    tau, _ = _nodes.legendre_gauss_radau(iv.n)
    return float(iv.s_of(tau[k]))


def _arc(lower: np.ndarray, upper: np.ndarray) -> tuple[str | None, ...] | None:
    """Each control's arc from the points given: ``"lower"`` / ``"upper"`` if every one is there."""
    if lower.shape[1] == 0:
        return None
    reg = tuple("lower" if lo.all() else "upper" if hi.all() else None for lo, hi in zip(lower, upper))
    return reg if any(r is not None for r in reg) else None


def refine(mesh: Mesh, errors: np.ndarray, s_col: np.ndarray, u_scaled: np.ndarray, offsets: np.ndarray,
           settings: RefineSettings, at_lower: np.ndarray | None = None,
           at_upper: np.ndarray | None = None, on_state_bound: np.ndarray | None = None) -> tuple[Mesh, dict]:
    """The next mesh (see the module text). ``errors`` per interval; ``s_col`` the collocation points,
    ``u_scaled`` the controls there divided by their scales, ``at_lower`` / ``at_upper`` whether each
    control sits on its lower / upper bound there, ``on_state_bound`` whether a state sits on its upper
    bound there (the train on its limit).

    1. A switch between two neighbouring points, next to an interval above the tolerance, gets a
       moving mesh point: an existing boundary between them is freed, else the interval is cut
       half-way; the point may move between the two points that bracket the switch.
    2. The intervals either side of a moving point keep the arc their other points show (a control
       on its lower or upper bound throughout), so the switch cannot hide inside them. The point next
       to a moving end is no evidence (it may be a compromise between the arcs), nor is a point where a
       state is on its bound (the train on its limit: the controls hold it there and lie on no arc of
       their own; a point reached on the limit with no force, as a coarse mesh gives where the train
       reaches it, would put a coasting arc into the cruise).
    3. Other intervals above the tolerance, next to moving points or not, get a higher degree
       (GPOPS-II eq. 29), or, where that did not halve their error at the last refinement (a kink),
       are cut at the kink, each piece keeping the interval's density of points; beyond
       ``max_degree`` they are cut into pieces of ``min_degree``.
    """
    ivs = list(mesh.intervals)
    done = {"split": 0, "raised": 0, "moving": 0}
    target = settings.margin * settings.tol  # aim below the tolerance: the next solve moves the optimum a little
    bad = errors > target
    cuts, freed = _switch_points(ivs, bad, s_col, u_scaled, offsets, settings, at_lower, at_upper)
    out: list[Interval] = []
    origin: list[int] = []  # the old interval each new one comes from
    for i, iv in enumerate(ivs):
        if i in freed:
            iv = replace(iv, free_start=freed[i])
            done["moving"] += 1
        if i in cuts:
            pieces = _cut_at_switches(iv, sorted(cuts[i])[:3], settings)
            done["split"] += 1
            done["moving"] += len(pieces) - 1
        elif not bad[i]:
            pieces = [replace(iv, last_error=None) if iv.last_error is not None else iv]
        else:
            pieces = _raised_or_cut(iv, errors[i], target, s_col[offsets[i]:offsets[i + 1]],
                                    u_scaled[:, offsets[i]:offsets[i + 1]], settings)
            done["raised" if len(pieces) == 1 else "split"] += 1
        out += pieces
        origin += [i] * len(pieces)
    if at_lower is not None:
        _arcs_beside_moving_points(out, origin, ivs, s_col, offsets, at_lower, at_upper, on_state_bound)
    _bound_moving_points(out, settings)
    return Mesh(tuple(out)), done


def _switch_points(ivs: list, bad: np.ndarray, s_col, u_scaled, offsets, settings: RefineSettings, at_lower, at_upper):
    """Step 1 of ``refine``: each switch between two neighbouring points next to an interval above the tolerance,
    as a cut inside its interval ({interval: [(cut, lo, hi, gap)]}) or, at an existing boundary, that boundary freed
    ({interval whose start becomes free: (lo, hi)})."""
    interval_of = np.repeat(np.arange(len(ivs)), np.diff(offsets))
    gaps = _switch_gaps(u_scaled, at_lower, at_upper, settings.jump)
    cuts: dict[int, list[tuple[float, float, float, int]]] = {}
    freed: dict[int, tuple[float, float]] = {}
    for k in np.nonzero(gaps)[0]:
        a, b = interval_of[k], interval_of[k + 1]
        if ivs[a].phase != ivs[b].phase or not (bad[a] or bad[b]):
            continue
        if a == b:
            iv = ivs[a]
            c = 0.5 * (s_col[k] + s_col[k + 1])
            if c - iv.s_a > settings.min_length and iv.s_b - c > settings.min_length:
                cuts.setdefault(a, []).append((c, float(s_col[k]), float(s_col[k + 1]), int(k)))
        elif b > 0 and ivs[b].free_start is None:  # the switch is at an existing boundary
            freed[b] = (float(s_col[k]), _node(ivs[b], 1))
    return cuts, freed


def _piece_mapping(iv: Interval, k: int, n_pieces: int) -> str:
    """The mapping of piece ``k`` of ``n_pieces`` cut from ``iv``: its own at a mapped end, else linear."""
    if (k == 0 and iv.mapping == "start") or (k == n_pieces - 1 and iv.mapping == "end"):
        return iv.mapping
    return "linear"


def _cut_at_switches(iv: Interval, cs: list, settings: RefineSettings) -> list[Interval]:
    """``iv`` cut at each switch of ``cs`` ((cut, lo, hi, gap), at most three), each cut a moving point free between
    the two collocation points that bracket its switch."""
    edges = [iv.s_a, *[c[0] for c in cs], iv.s_b]
    out = []
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        mapping = _piece_mapping(iv, k, len(edges) - 1)
        free = iv.free_start if k == 0 else (cs[k - 1][1] + settings.min_length, cs[k - 1][2] - settings.min_length)
        degree = settings.min_degree + (1 if mapping != "linear" else 0)
        out.append(Interval(iv.phase, float(a), float(b), degree, mapping, free, regime=iv.regime))
    return out


def _raised_or_cut(iv: Interval, e: float, target: float, s_cols, u_cols, settings: RefineSettings) -> list[Interval]:
    """Step 3 of ``refine`` for an interval above the tolerance: a higher degree (GPOPS-II eq. 29), or where that
    did not halve its error at the last refinement, cut at its kink (each piece keeping its density of points), or
    beyond ``max_degree`` cut into pieces of ``min_degree``: one interval (raised) or the pieces."""
    p = max(1, math.ceil(math.log(e / target) / math.log(max(iv.n, 2))))
    stalled = iv.last_error is not None and e > 0.5 * iv.last_error
    kink = _kink(s_cols, u_cols, settings.kink) if stalled else None
    if kink is not None and (kink - iv.s_a <= settings.min_length or iv.s_b - kink <= settings.min_length):
        kink = None
    if kink is None and (iv.n + p <= settings.max_degree or iv.length <= 2 * settings.min_length):
        return [replace(iv, n=min(iv.n + p, settings.max_degree), last_error=e)]
    if kink is not None:  # either side of a corner the control is smooth: each piece keeps the density
        edges = [iv.s_a, kink, iv.s_b]
    else:
        pieces = max(2, math.ceil((iv.n + p) / settings.min_degree))
        edges = list(np.linspace(iv.s_a, iv.s_b, pieces + 1))
    out = []
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        mapping = _piece_mapping(iv, k, len(edges) - 1)
        degree = settings.min_degree + (1 if mapping != "linear" else 0)
        if kink is not None:
            degree = max(degree, min(settings.max_degree, math.ceil(iv.n * (b - a) / iv.length)))
        out.append(Interval(iv.phase, float(a), float(b), degree, mapping, iv.free_start if k == 0 else None,
                            regime=iv.regime))
    return out


def _arcs_beside_moving_points(out: list, origin: list, ivs: list, s_col, offsets, at_lower, at_upper,
                               on_state_bound) -> None:
    """Step 2 of ``refine``, in place: the arc either side of every moving point, from the old points inside each
    side's interval, leaving out the one next to each of its moving ends (its value may be a compromise between two
    arcs) and those where a state is on its bound; a side with no other point keeps the arc it had, or, having
    none, takes the arc of the points it has."""
    for j, iv in enumerate(out):
        moving_start = j > 0 and iv.free_start is not None
        moving_end = j + 1 < len(out) and out[j + 1].free_start is not None
        if not (moving_start or moving_end):
            continue
        o = origin[j]
        cols = np.arange(offsets[o], offsets[o + 1])
        cols = cols[(s_col[cols] >= iv.s_a - 1e-9) & (s_col[cols] <= iv.s_b + 1e-9)]
        if on_state_bound is not None:
            cols = cols[~on_state_bound[cols]]
        keep = np.ones(cols.size, dtype=bool)
        if cols.size:
            keep[0] &= not moving_start
            keep[-1] &= not moving_end
        if keep.any():
            reg = _arc(at_lower[:, cols[keep]], at_upper[:, cols[keep]])
        elif ivs[o].regime is not None:
            reg = ivs[o].regime
        else:
            reg = _arc(at_lower[:, cols], at_upper[:, cols]) if cols.size else None
        if reg is not None:
            out[j] = replace(iv, regime=reg)


def _bound_moving_points(out: list, settings: RefineSettings) -> None:
    """In place: a moving point between alike arcs tracks nothing and is fixed; the others get bounds from the
    collocation points around them."""
    for j, iv in enumerate(out):
        if iv.free_start is None:
            continue
        left = out[j - 1] if j > 0 else None
        if left is None or left.phase != iv.phase or (left.regime == iv.regime and iv.regime is not None):
            out[j] = replace(iv, free_start=None)
            continue
        lo, hi = _node(left, -1), _node(iv, 1)
        lo = max(lo, min(iv.free_start[0], left.s_b), left.s_a + 0.1 * left.length)
        hi = min(max(hi, iv.free_start[1]), iv.s_b - 0.1 * iv.length)
        if not lo < iv.s_a < hi:
            lo, hi = min(lo, iv.s_a - settings.min_length), max(hi, iv.s_a + settings.min_length)
        out[j] = replace(iv, free_start=(lo, hi))
