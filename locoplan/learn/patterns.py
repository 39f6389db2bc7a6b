"""The pattern-curve patent's double-layer pattern curves, learned from good drivers' logs (claims 1-3, eq. I-II).

**Good drivers** (claim 3): the runs are grouped by route, load class (mass rounded to
``load_class_t``) and planned running time — the same job; in each group a driver whose mean traction
energy is below the group's mean over all drivers is a good driver there, and their punctual runs
(within the route's tolerance, else 1 % of the time) are the learning data.

**Upper layer** (eq. I): the share alpha of the running time spent in each section, as a polynomial
of odd powers ``sum_i (b_i0 + b_i1 M^(2i-1) + b_i2 T^(2i-1) + b_i3 L^(2i-1) + b_i4 G^(2i-1))`` — the
patent writes the powers as 2i+1 in a garbled line; 2i-1 gives the linear term for i = 1 — with an
offset per section type S. Inputs are standardised (z-scores) before the powers. Two departures,
both needed to carry a pattern to a line it was not learned on, and both reported:

- T enters as ``T / T_min`` (the time reserve over the fastest run of that train on that line), and
  the section's mean speed limit V is an input too: the patent learns one line, where both are fixed;
- the response is either alpha itself (the patent's form, ``share``) or the section's pace
  alpha / (L / L_line) (``pace``: 1 = the line's mean speed), because alpha grows with L in
  proportion, which a sum of powers of L cannot express; cross-validation picks the form. Predicted
  shares are normalised to sum to 1 over the line.

**Lower layer** (eq. II): the speed at the p equal division points of a section, one division at
a time: v_k from the division's entry speed v_(k-1), k / p, alpha, L, G, M and T (as above), plus the
section's mean speed L / (alpha T), the limits there (the lowest limit over the division and the
braking-envelope speed at its end, which carries every lower limit ahead and the stop) and the next
section's gradient (drivers speed up before a climb and ease off before a descent). Chained,
each division's exit speed is the next one's entry (claim 1 step 5.3).

**Order** i (or j) of each layer is chosen by K-fold cross-validation grouped by run (no run is in
both a fit and its test fold): the smallest order whose CV error is within 1 % of the best; the
in-sample R^2 of every order is reported beside it. The fit report gives R^2 and errors on runs held
out of the fit altogether (``holdout_share`` of the good runs); the saved pattern is then refitted on
all good runs with the chosen orders.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from .. import __version__
from ..errors import InputError, Problem
from ..model.logs import LoggedRun
from ..model.route import Route
from ..model.train import Train
from ..physics.units import KMH_PER_MS, kmh_from_e
from ..sim.calculator import ModelOptions, TractionCalculator
from .segments import LEVEL_PERMILLE, SECTION_TYPES, Section, segment_route

PATTERN_SCHEMA = "locoplan/patterns@1"
UPPER_FEATURES = ("mass_t", "time_ratio", "length_m", "gradient_permille", "limit_kmh")
LOWER_FEATURES = ("entry_kmh", "position", "share", "length_m", "gradient_permille", "mass_t", "time_ratio",
                  "mean_speed_kmh", "limit_kmh", "envelope_kmh", "next_gradient_permille")
UPPER_FORMS = ("pace", "share")
RIDGE = 1e-8
"""Ridge weight (relative to the number of rows) on every coefficient but the intercept: keeps the
normal equations solvable when a section type is missing, and leaves well-posed fits unchanged."""
PATTERN_FLOOR = 0.5
"""A chained pattern speed is kept at or above this share of the speed cap at its point: a pattern
never asks the train to crawl mid-route (a lower-layer prediction far outside what it learned can)."""
TYPE_SHRINK = 1.0
"""Pull of a per-type fit towards the pooled fit (ridge weight on the coefficient differences; the
design's columns are z-scores, so 1 weighs like one row of data)."""
ORDER_TOLERANCE = 0.01
"""An order is chosen when its CV error is within this share of the best order's (prefer the simpler)."""
BLOCK_BYTES = 32 * 2**20
"""Most memory for a block of a layer's design matrix [bytes]. A larger matrix (the lower layer's from 20,000
logs: 800,000 rows, 380 MB) is made, summed into the normal equations and predicted from a block of rows at a
time; one that fits in a block is one matrix, and its numbers are those of the plain computation, bit for bit."""


@dataclass(frozen=True)
class LearnSettings:
    divisions: int = 8
    level_permille: float = LEVEL_PERMILLE
    min_section_m: float | None = None
    max_order: int = 4
    folds: int = 5
    holdout_share: float = 0.2
    load_class_t: float = 500.0
    seed: int = 1
    lower_entry: str = "division"  # "section": eq. II's V_KS0, the section's entry speed; "division": the previous point's
    lower_interactions: bool = True  # position x every other input (the shape along a section may vary)
    lower_by_type: bool = True  # one set of eq. II coefficients per section type S

    def entry(self, speeds_row: np.ndarray, k: int) -> float:
        """The entry speed the lower layer reads for division point k (1..p) of a section."""
        return float(speeds_row[0] if self.lower_entry == "section" else speeds_row[k - 1])

    @property
    def interact(self) -> str | None:
        return "position" if self.lower_interactions else None

    def check(self) -> None:
        from .. import bounds

        finite = math.isfinite
        rules = [("--divisions", 1 <= self.divisions <= 100, "must be 1 .. 100 (equal divisions per section; the patent uses 8)"),
                 ("--max-order", 1 <= self.max_order <= 6, "must be 1..6"),
                 ("--folds", 2 <= self.folds <= 100, "must be 2 .. 100"),
                 ("--holdout", finite(self.holdout_share) and 0 <= self.holdout_share < 0.9, "must be in [0, 0.9)"),
                 ("--load-class", finite(self.load_class_t) and 0 < self.load_class_t <= 100_000, "must be in (0, 100,000] t"),
                 ("--level", finite(self.level_permille) and 0 <= self.level_permille <= 40, "must be in [0, 40] per mille"),
                 ("--lower-entry", self.lower_entry in ("section", "division"), "must be 'section' or 'division'")]
        for name, ok, why in rules:
            if not ok:
                raise InputError(Problem("<command line>", name, why))
        bounds.seed(self.seed)


# ------------------------------------------------------------------------------------------ the line
@dataclass(frozen=True)
class LineModel:
    """A route and a train: the sections, their division points and the limits the lower layer reads
    (per section i: ``points_m[i]`` the p + 1 division points [m], ``division_limit_kmh[i]`` the lowest
    train-length-aware limit over each division, ``envelope_kmh[i]`` the braking-envelope speed at each
    point, which carries every lower limit ahead and the stop)."""

    route: Route
    train: Train
    calc: TractionCalculator
    sections: tuple[Section, ...]
    divisions: int
    points_m: np.ndarray
    division_limit_kmh: np.ndarray
    envelope_kmh: np.ndarray

    @property
    def fastest_time_s(self) -> float:
        return self.calc.fastest_time_s

    def upper_inputs(self, mass_t: float, time_s: float) -> tuple[np.ndarray, list[str], np.ndarray]:
        """Eq. I inputs per section (n_sections, len(UPPER_FEATURES)), their types, and L / L_line."""
        ratio = time_s / self.fastest_time_s
        X = np.array([[mass_t, ratio, s.length_m, s.gradient_permille, s.mean_limit_kmh] for s in self.sections])
        return X, [s.kind for s in self.sections], np.array([s.length_m for s in self.sections]) / self.route.length_m

    def lower_inputs(self, i: int, k: int, entry_kmh: float, share: float, mass_t: float, time_s: float) -> np.ndarray:
        """Eq. II inputs of division k (1..p) of section i."""
        sec = self.sections[i]
        mean_speed = KMH_PER_MS * sec.length_m / max(share * time_s, 1e-9)
        ahead = self.sections[i + 1].gradient_permille if i + 1 < len(self.sections) else 0.0
        return np.array([entry_kmh, k / self.divisions, share, sec.length_m, sec.gradient_permille, mass_t,
                         time_s / self.fastest_time_s, mean_speed, self.division_limit_kmh[i, k - 1],
                         self.envelope_kmh[i, k], ahead])


def line_model(route: Route, train: Train, options: ModelOptions, settings: LearnSettings) -> LineModel:
    calc = TractionCalculator(route, train, options)
    sections = segment_route(route, train, settings.level_permille, settings.min_section_m)
    p = settings.divisions
    points = np.array([s.division_points_m(p) for s in sections])
    s, lim = calc.s_m, calc.limit_kmh
    limits = np.empty((len(sections), p))
    for i in range(len(sections)):
        for k in range(p):
            cells = (s[1:] > points[i, k] + 1e-9) & (s[:-1] < points[i, k + 1] - 1e-9)
            limits[i, k] = lim[cells].min() if cells.any() else lim[min(int(np.searchsorted(s, points[i, k])), len(lim) - 1)]
    envelope = kmh_from_e(np.interp(points, s, calc.e_envelope))
    return LineModel(route, train, calc, sections, p, points, limits, envelope)


# ------------------------------------------------------------------------------------------ one layer
@dataclass(frozen=True)
class PolyLayer:
    """One layer: y = b0 + offset(S) + sum_i sum_f b_if z_f^(2i-1), z the standardised inputs."""

    features: tuple[str, ...]
    order: int
    mean: np.ndarray
    std: np.ndarray
    coef: np.ndarray  # [intercept, one offset per SECTION_TYPES, odd powers feature-major per order, interactions]
    interact: str | None = None  # a feature whose (standardised) value multiplies every other one
    low: np.ndarray | None = None  # the learned range of each input: outside it the input is held at its edge
    high: np.ndarray | None = None

    @property
    def n_coef(self) -> int:
        n = 1 + len(SECTION_TYPES) + self.order * len(self.features)
        return n + (len(self.features) - 1 if self.interact else 0)

    def design(self, X: np.ndarray, kinds) -> np.ndarray:
        """The design matrix (rows of X, ``n_coef`` columns in the order of ``coef``), filled in place: at
        20,000 logs it has most of a million rows, and joining its columns would hold it twice. Each row
        depends on its own inputs only, so the rows of a part of X are those rows of the whole."""
        X = np.atleast_2d(X)
        # no polynomial extrapolation beyond the data: a 7th power explodes there
        Z = np.clip(X, self.low, self.high) if self.low is not None else np.array(X, dtype=float)
        np.subtract(Z, self.mean, out=Z)  # standardised in place
        np.divide(Z, self.std, out=Z)
        n, m = Z.shape
        A = np.empty((n, self.n_coef))
        A[:, 0] = 1.0
        A[:, 1:1 + len(SECTION_TYPES)] = np.asarray(kinds, dtype=str).reshape(n, 1) == np.array(SECTION_TYPES)
        c = 1 + len(SECTION_TYPES)
        for i in range(1, self.order + 1):  # [Z, Z^3, ..., Z^(2 order - 1)]: the odd-power terms of eq. I / II
            np.power(Z, 2 * i - 1, out=A[:, c:c + m])
            c += m
        if self.interact:
            j = self.features.index(self.interact)
            for q in (q for q in range(m) if q != j):
                np.multiply(Z[:, j], Z[:, q], out=A[:, c])
                c += 1
        return A

    def block_rows(self) -> int:
        """Rows of the design matrix in one block of ``BLOCK_BYTES``."""
        return max(1, BLOCK_BYTES // (8 * self.n_coef))

    def predict(self, X: np.ndarray, kinds) -> np.ndarray:
        X = np.atleast_2d(X)
        types = None if self.coef.ndim == 1 else np.array([SECTION_TYPES.index(k) for k in kinds], dtype=int)
        out = np.empty(len(X))
        # each row's value is the same in a block as in the whole matrix; with coefficients per type each row's
        # are copied beside it, so the blocks are smaller
        step = self.block_rows() if types is None else max(1, self.block_rows() // 8)
        for a in range(0, len(X), step):
            A = self.design(X[a:a + step], kinds[a:a + step])
            # one set of coefficients per section type: each row with its own
            out[a:a + step] = A @ self.coef if types is None else np.einsum("ij,ij->i", A, self.coef[types[a:a + step]])
        return out

    def normal_equations(self, X: np.ndarray, kinds, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A^T A and A^T y of the design matrix A of the rows X, summed a block of rows at a time."""
        G = r = None
        step = self.block_rows()
        for a in range(0, len(X), step):
            A = self.design(X[a:a + step], kinds[a:a + step])
            g, q = A.T @ A, A.T @ y[a:a + step]
            G, r = (g, q) if G is None else (G + g, r + q)
        return G, r

    def to_dict(self) -> dict:
        return {"features": list(self.features), "order": self.order, "types": list(SECTION_TYPES),
                "interact": self.interact, "mean": self.mean.tolist(), "std": self.std.tolist(),
                "low": None if self.low is None else self.low.tolist(), "high": None if self.high is None else self.high.tolist(),
                "coef": self.coef.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "PolyLayer":
        bound = lambda key: None if d.get(key) is None else np.asarray(d[key], float)  # noqa: E731
        return cls(tuple(d["features"]), int(d["order"]), np.asarray(d["mean"], float), np.asarray(d["std"], float),
                   np.asarray(d["coef"], float), d.get("interact"), bound("low"), bound("high"))


def standardisation(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of each input (1 where an input does not vary)."""
    mean = X.mean(axis=0)
    std = X.std(axis=0)
    return mean, np.where(std > 1e-12 * np.maximum(np.abs(mean), 1.0), std, 1.0)


def fit_layer(X: np.ndarray, kinds: list[str], y: np.ndarray, order: int, features: tuple[str, ...],
              interact: str | None = None, by_type: bool = False, scale: tuple | None = None) -> PolyLayer:
    """Least squares (with ``RIDGE``) of one layer at a given order. ``by_type``: one set of
    coefficients per section type, each shrunk towards the pooled fit (weight ``TYPE_SHRINK`` per
    row), so that a type with few rows stays close to the pooled fit and an absent one equals it."""
    mean, std = scale if scale is not None else standardisation(X)
    low, high = X.min(axis=0), X.max(axis=0)
    layer = PolyLayer(features, order, mean, std, np.zeros(0), interact, low, high)
    G, r = layer.normal_equations(X, kinds, y)
    penalty = np.full(layer.n_coef, RIDGE * len(y))
    penalty[0] = 0.0
    pooled = np.linalg.solve(G + np.diag(penalty), r)
    if not by_type:
        return PolyLayer(features, order, mean, std, pooled, interact, low, high)
    coef = np.tile(pooled, (len(SECTION_TYPES), 1))
    types = np.array([SECTION_TYPES.index(k) for k in kinds], dtype=np.int8)
    for i, kind in enumerate(SECTION_TYPES):
        sel = types == i
        if sel.sum() == 0:
            continue
        G, r = layer.normal_equations(X[sel], [kind] * int(sel.sum()), y[sel])
        lam = TYPE_SHRINK * (1.0 + sel.sum() * 0.0) * np.ones(layer.n_coef)
        coef[i] = np.linalg.solve(G + np.diag(lam), r + lam * pooled)
    return PolyLayer(features, order, mean, std, coef, interact, low, high)


def r2(y: np.ndarray, pred: np.ndarray) -> float:
    ss = float(np.sum((y - y.mean()) ** 2))
    return 1.0 - float(np.sum((y - pred) ** 2)) / ss if ss > 0 else float("nan")


def rmse(y: np.ndarray, pred: np.ndarray) -> float:
    return float(np.sqrt(np.mean((y - pred) ** 2)))


def select_order(X, kinds, y, groups, features, max_order, folds, rng, score: Callable | None = None,
                 interact: str | None = None, by_type: bool = False) -> tuple[int, list[dict]]:
    """Cross-validated error of each order 1..max_order, folds made of whole runs (``groups``); the
    chosen order is the smallest within ``ORDER_TOLERANCE`` of the best. ``score(pred, rows)`` maps a
    fold's predictions to (target, predicted) arrays for the error (default: y itself)."""
    runs = np.unique(groups)
    scale = standardisation(X)  # one set of z-scores for every fold, so that a fold fits the same polynomial family
    perm = rng.permutation(runs)
    fold_of = {r: i % min(folds, len(runs)) for i, r in enumerate(perm)}
    fold = np.array([fold_of[g] for g in groups])
    kinds = list(kinds)
    table = []
    for order in range(1, max_order + 1):
        errs, count = 0.0, 0
        for f in np.unique(fold):
            test = fold == f
            layer = fit_layer(X[~test], [k for k, t in zip(kinds, test) if not t], y[~test], order, features, interact, by_type, scale)
            pred = layer.predict(X[test], [k for k, t in zip(kinds, test) if t])
            target, p = score(pred, np.flatnonzero(test)) if score else (y[test], pred)
            errs += float(np.sum((target - p) ** 2))
            count += len(target)
        full = fit_layer(X, kinds, y, order, features, interact, by_type, scale)
        table.append({"order": order, "cv_rmse": math.sqrt(errs / count), "in_sample_r2": r2(y, full.predict(X, kinds))})
    best = min(r["cv_rmse"] for r in table)
    chosen = next(r["order"] for r in table if r["cv_rmse"] <= best * (1 + ORDER_TOLERANCE) + 1e-15)
    return chosen, table


# ------------------------------------------------------------------------------------------ good drivers
def group_key(run: LoggedRun, load_class_t: float) -> tuple:
    """The same job: route, load class, planned time."""
    return (str(run.route_file), round(run.mass_t / load_class_t), round(run.scheduled_time_s))


def tolerance_s(route: Route, time_s: float) -> float:
    """Punctuality window +- [s]: the route's schedule tolerance, else 1 % of the time."""
    return route.schedule.tolerance_s if route.schedule else 0.01 * time_s


def good_drivers(runs: list[LoggedRun], load_class_t: float) -> tuple[np.ndarray, list[dict]]:
    """Claim 3: per group, drivers whose mean energy is below the mean of all drivers; returns a mask
    of good runs (a good driver's punctual runs) and a table of the groups."""
    keys = [group_key(r, load_class_t) for r in runs]
    energy = np.array([r.traction_energy_kwh for r in runs])
    good = np.zeros(len(runs), dtype=bool)
    table = []
    for key in sorted(set(keys)):
        idx = [i for i, k in enumerate(keys) if k == key]
        mean_all = float(energy[idx].mean())
        drivers = sorted({runs[i].driver_id for i in idx})
        per_driver = {d: float(np.mean([energy[i] for i in idx if runs[i].driver_id == d])) for d in drivers}
        good_ids = {d for d, e in per_driver.items() if e < mean_all}
        for i in idx:
            r = runs[i]
            good[i] = r.driver_id in good_ids and abs(r.running_time_s - r.scheduled_time_s) <= tolerance_s(r.route, r.scheduled_time_s)
        g = [i for i in idx if good[i]]
        table.append({"route": runs[idx[0]].route.name, "route_file": key[0], "load_class_t": key[1] * load_class_t,
                      "mean_mass_t": round(float(np.mean([runs[i].mass_t for i in idx])), 1),
                      "scheduled_time_s": float(key[2]), "runs": len(idx), "drivers": len(drivers),
                      "good_drivers": len(good_ids), "good_runs": len(g), "mean_energy_kwh": round(mean_all, 2),
                      "good_mean_energy_kwh": round(float(energy[g].mean()), 2) if g else None,
                      "best_energy_kwh": round(float(energy[idx].min()), 2)})
    return good, table


# ------------------------------------------------------------------------------------------ data
@dataclass
class LayerData:
    X: np.ndarray
    kinds: list[str]
    y: np.ndarray
    run: np.ndarray  # run index of each row
    extra: np.ndarray  # upper: L / L_line per row; lower: section index per row

    def rows(self, sel: np.ndarray) -> "LayerData":
        """The rows where ``sel`` (a mask), in their order."""
        return LayerData(self.X[sel], [k for k, s in zip(self.kinds, sel) if s], self.y[sel], self.run[sel], self.extra[sel])

    def split(self, runs: np.ndarray) -> tuple["LayerData", "LayerData", np.ndarray]:
        """The rows of the given runs, the others, and the mask of the first: two parts that hold the rows once
        (at 20,000 logs the lower layer's rows are 100 MB), joined again by :meth:`joined`."""
        sel = np.isin(self.run, runs)
        return self.rows(sel), self.rows(~sel), sel

    @staticmethod
    def joined(first: "LayerData", other: "LayerData", sel: np.ndarray) -> "LayerData":
        """The rows of ``first`` where ``sel``, of ``other`` elsewhere: what :meth:`split` split."""
        def merge(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            out = np.empty((len(sel),) + a.shape[1:], dtype=a.dtype)
            out[sel], out[~sel] = a, b
            return out
        kinds_a, kinds_b = iter(first.kinds), iter(other.kinds)
        return LayerData(merge(first.X, other.X), [next(kinds_a) if s else next(kinds_b) for s in sel],
                         merge(first.y, other.y), merge(first.run, other.run), merge(first.extra, other.extra))


def observed(run: LoggedRun, line: LineModel) -> tuple[np.ndarray, np.ndarray]:
    """A run's time shares per section (n_sections,) and its speeds at every section's division points
    (n_sections, p + 1) [km/h], read from its log."""
    d = run.data
    pos, first = np.unique(d.position_m, return_index=True)  # first row at each position (a stop's start)
    t_at = lambda x: np.interp(x, pos, d.time_s[first])  # noqa: E731
    v_at = lambda x: np.interp(x, pos, d.speed_kmh[first])  # noqa: E731
    bounds = np.array([s.from_m for s in line.sections] + [line.sections[-1].to_m])
    t_b = t_at(bounds)
    t_b[0], t_b[-1] = d.time_s[0], d.time_s[-1]
    shares = np.diff(t_b) / (t_b[-1] - t_b[0])
    speeds = v_at(line.points_m)
    speeds[0, 0], speeds[-1, -1] = d.speed_kmh[0], d.speed_kmh[-1]
    return shares, speeds


def layer_data(runs: list[LoggedRun], lines: list[LineModel], settings: LearnSettings) -> tuple[LayerData, LayerData, list]:
    """Rows of both layers from the given runs (each with its line model), each run's log read in turn."""
    n_up = sum(len(line.sections) for line in lines)
    n_lo = sum(len(line.sections) * line.divisions for line in lines)
    ux, uy, ur, ul = np.empty((n_up, len(UPPER_FEATURES))), np.empty(n_up), np.empty(n_up, dtype=int), np.empty(n_up)
    lx, ly, lr, ls = np.empty((n_lo, len(LOWER_FEATURES))), np.empty(n_lo), np.empty(n_lo, dtype=int), np.empty(n_lo, dtype=int)
    uk: list[str] = []
    lk: list[str] = []
    obs = []
    u = lo = 0
    for j, (run, line) in enumerate(zip(runs, lines)):
        shares, speeds = observed(run, line)
        obs.append((shares, speeds))
        T = run.running_time_s
        X, kinds, ell = line.upper_inputs(run.mass_t, T)
        n = len(shares)
        ux[u:u + n], uy[u:u + n], ur[u:u + n], ul[u:u + n] = X, shares, j, ell
        uk += kinds
        u += n
        for i in range(len(line.sections)):
            for k in range(1, line.divisions + 1):
                lx[lo] = line.lower_inputs(i, k, settings.entry(speeds[i], k), shares[i], run.mass_t, T)
                ly[lo], lr[lo], ls[lo] = speeds[i, k], j, i
                lk.append(line.sections[i].kind)
                lo += 1
    return LayerData(ux, uk, uy, ur, ul), LayerData(lx, lk, ly, lr, ls), obs


def upper_response(form: str, share: np.ndarray, ell: np.ndarray) -> np.ndarray:
    return share / ell if form == "pace" else share


def shares_from(form: str, pred: np.ndarray, ell: np.ndarray, run: np.ndarray) -> np.ndarray:
    """Predicted shares from a layer's output, floored at 0.1 % and normalised to 1 within each run."""
    alpha = np.maximum(pred * ell if form == "pace" else pred, 1e-3)
    out = alpha.copy()
    for r in np.unique(run):
        sel = run == r
        out[sel] = alpha[sel] / alpha[sel].sum()
    return out


# ------------------------------------------------------------------------------------------ patterns
@dataclass(frozen=True)
class Patterns:
    """The learned double-layer pattern: what ``locoplan advise`` needs, plus the fit report."""

    settings: LearnSettings
    model: dict  # the train model the pattern was learned with (ModelOptions fields)
    upper_form: str
    upper: PolyLayer
    lower: PolyLayer
    report: dict = field(default_factory=dict)

    def shares(self, line: LineModel, mass_t: float, time_s: float) -> np.ndarray:
        """Upper layer: each section's share of ``time_s`` (sums to 1)."""
        X, kinds, ell = line.upper_inputs(mass_t, time_s)
        return shares_from(self.upper_form, self.upper.predict(X, kinds), ell, np.zeros(len(ell), dtype=int))

    def speeds(self, line: LineModel, mass_t: float, time_s: float, shares: np.ndarray | None = None,
               entry_kmh: float = 0.0) -> np.ndarray:
        """Lower layer, chained: the speed at every section's division points (n_sections, p + 1)
        [km/h], from rest at the start; each prediction kept between ``PATTERN_FLOOR`` of its cap and
        the cap (the division's limit, and the braking envelope there), the last point 0 (the stop)."""
        shares = self.shares(line, mass_t, time_s) if shares is None else shares
        p = line.divisions
        out = np.zeros((len(line.sections), p + 1))
        v = entry_kmh
        for i, sec in enumerate(line.sections):
            out[i, 0] = v
            cap = np.minimum(line.division_limit_kmh[i], line.envelope_kmh[i, 1:])
            for k in range(1, p + 1):
                x = line.lower_inputs(i, k, self.settings.entry(out[i], k), shares[i], mass_t, time_s)
                v = float(np.clip(self.lower.predict(x[None, :], [sec.kind])[0], PATTERN_FLOOR * cap[k - 1], cap[k - 1]))
                out[i, k] = v
        out[-1, -1] = 0.0
        return out

    def to_dict(self) -> dict:
        return {"schema": PATTERN_SCHEMA, "locoplan_version": __version__, "settings": asdict(self.settings),
                "model": self.model, "upper": {"form": self.upper_form, **self.upper.to_dict()},
                "lower": self.lower.to_dict(), "report": self.report}

    @classmethod
    def from_dict(cls, data: dict, name: str) -> "Patterns":
        """The patterns of a patterns.json's content (``io.patterns.read_patterns_file``: its keys and
        types checked), checked against this locoplan's inputs; ``name`` is the file's, for the messages.
        A pattern made for other inputs is an input error (exit 2)."""
        problems = []
        if data["schema"] != PATTERN_SCHEMA:
            problems.append(Problem(name, "schema", f"expected {PATTERN_SCHEMA!r}, got {data['schema']!r}"))
        for key, features in (("upper", UPPER_FEATURES), ("lower", LOWER_FEATURES)):
            layer = data[key]
            if tuple(layer["features"]) != features or tuple(layer["types"]) != SECTION_TYPES:
                problems.append(Problem(name, f"{key}.features", f"made for other inputs ({layer['features']}); learn "
                                        f"again with this locoplan ({__version__})"))
                continue
            interact, coef = layer["interact"], layer["coef"]
            n_coef = 1 + len(SECTION_TYPES) + layer["order"] * len(features) + (len(features) - 1 if interact else 0)
            if interact is not None and interact not in features:
                problems.append(Problem(name, f"{key}.interact", f"{interact!r} is not one of the inputs"))
            elif (np.shape(coef)[-1] != n_coef or np.ndim(coef) == 2 and len(coef) != len(SECTION_TYPES)
                  or len(layer["mean"]) != len(features) or len(layer["std"]) != len(features)):
                problems.append(Problem(name, f"{key}.coef", f"expected {n_coef} coefficients and {len(features)} means "
                                        f"and deviations for order {layer['order']}"))
        if data["upper"]["form"] not in UPPER_FORMS:
            problems.append(Problem(name, "upper.form", f"one of {', '.join(UPPER_FORMS)} (got {data['upper']['form']!r})"))
        try:
            settings = LearnSettings(**data["settings"])
        except TypeError as exc:
            problems.append(Problem(name, "settings", str(exc)))
        if problems:
            raise InputError(problems)
        up = dict(data["upper"])
        form = up.pop("form")
        return cls(settings, data["model"], form, PolyLayer.from_dict(up), PolyLayer.from_dict(data["lower"]), data["report"])


@dataclass(frozen=True)
class Learned:
    """What ``learn`` found: the patterns, and the good runs they came from (for the fit plot)."""

    patterns: Patterns
    runs: list[LoggedRun]
    lines: list[LineModel]
    observed: list  # per run: (shares, speeds at the division points)
    heldout: np.ndarray  # per run: held out of the fit


def smooth_curve(points_m: np.ndarray, speeds_kmh: np.ndarray):
    """The division points' speeds joined smoothly (claim 1 step 4): a monotone cubic (PCHIP) through
    them, which never overshoots between two points; a callable of position [m] -> speed [km/h]."""
    from scipy.interpolate import PchipInterpolator

    x, idx = np.unique(points_m, return_index=True)
    return PchipInterpolator(x, speeds_kmh[idx])


def learn(runs: list[LoggedRun], settings: LearnSettings, options: ModelOptions) -> Learned:
    """Claims 1-3 and eq. I-II: pick the good drivers' runs, choose each layer's order by grouped
    cross-validation, report R^2 and errors on held-out runs, refit on all good runs."""
    settings.check()
    rng = np.random.default_rng(settings.seed)
    cache: dict[tuple, LineModel] = {}

    def line_of(run: LoggedRun) -> LineModel:
        key = (str(run.route_file), str(run.consist_file))
        if key not in cache:
            cache[key] = line_model(run.route, run.train, options, settings)
        return cache[key]

    good, groups = good_drivers(runs, settings.load_class_t)
    chosen = [r for r, g in zip(runs, good) if g]
    if len(chosen) < 3:
        raise InputError(Problem("<logs>", "", f"only {len(chosen)} good drivers' punctual runs among {len(runs)} "
                                 "runs: at least 3 are needed to learn from"))
    lines = [line_of(r) for r in chosen]
    n = len(chosen)
    order = rng.permutation(n)
    n_hold = int(round(settings.holdout_share * n)) if n >= 5 else 0
    held = np.zeros(n, dtype=bool)
    held[order[:n_hold]] = True
    fit_idx, hold_idx = np.flatnonzero(~held), np.flatnonzero(held)
    up_all, lo_all, obs = layer_data(chosen, lines, settings)

    def choose(up: LayerData, lo: LayerData):
        """Form and order of the upper layer, order of the lower layer, by grouped CV."""
        tables = {}
        best = None
        for form in UPPER_FORMS:
            y = upper_response(form, up.y, up.extra)
            score = (lambda form: lambda pred, r: (up.y[r], shares_from(form, pred, up.extra[r], up.run[r])))(form)
            o, table = select_order(up.X, up.kinds, y, up.run, UPPER_FEATURES, settings.max_order, settings.folds,
                                    np.random.default_rng([settings.seed, 1]), score)
            err = next(t["cv_rmse"] for t in table if t["order"] == o)
            tables[form] = table
            if best is None or err < best[2] * (1 - ORDER_TOLERANCE):
                best = (form, o, err)
        lo_order, lo_table = select_order(lo.X, lo.kinds, lo.y, lo.run, LOWER_FEATURES, settings.max_order,
                                          settings.folds, np.random.default_rng([settings.seed, 2]), interact=settings.interact,
                                          by_type=settings.lower_by_type)
        return best[0], best[1], tables, lo_order, lo_table

    # the rows of the fit runs, and of the held-out runs apart: together they hold every row once
    (up_fit, up_held, up_sel), (lo_fit, lo_held, lo_sel) = up_all.split(fit_idx), lo_all.split(fit_idx)
    del up_all, lo_all
    form, up_order, up_tables, lo_order, lo_table = choose(up_fit, lo_fit)
    upper = fit_layer(up_fit.X, up_fit.kinds, upper_response(form, up_fit.y, up_fit.extra), up_order, UPPER_FEATURES)
    lower = fit_layer(lo_fit.X, lo_fit.kinds, lo_fit.y, lo_order, LOWER_FEATURES, settings.interact,
                      settings.lower_by_type)
    trial = Patterns(settings, {}, form, upper, lower)
    held_report = evaluate(trial, [chosen[i] for i in hold_idx], [lines[i] for i in hold_idx], [obs[i] for i in hold_idx])
    fit_report = evaluate(trial, [chosen[i] for i in fit_idx], [lines[i] for i in fit_idx], [obs[i] for i in fit_idx])
    up_all, lo_all = LayerData.joined(up_fit, up_held, up_sel), LayerData.joined(lo_fit, lo_held, lo_sel)
    del up_fit, up_held, lo_fit, lo_held
    # the saved pattern: the same forms and orders, refitted on every good run
    upper = fit_layer(up_all.X, up_all.kinds, upper_response(form, up_all.y, up_all.extra), up_order, UPPER_FEATURES)
    lower = fit_layer(lo_all.X, lo_all.kinds, lo_all.y, lo_order, LOWER_FEATURES, settings.interact,
                      settings.lower_by_type)
    model = {"point_mass": options.point_mass, "air_brake": options.air_brake, "step_m": options.step_m,
             "rotating_mass": options.rotating_mass}
    routes = sorted({(r.route.name, str(r.route_file)) for r in runs})
    report = {
        "data": {"runs": len(runs), "synthetic_runs": int(sum(r.synthetic for r in runs)),
                 "drivers": len({r.driver_id for r in runs}), "good_runs": n, "fit_runs": len(fit_idx),
                 "heldout_runs": len(hold_idx), "routes": [{"name": a, "file": b} for a, b in routes],
                 "masses_t": sorted({r.mass_t for r in runs}), "times_s": sorted({r.scheduled_time_s for r in runs}),
                 "groups": groups},
        "upper": {"form": form, "order": up_order, "cv": {f: t for f, t in up_tables.items()}},
        "lower": {"order": lo_order, "cv": lo_table},
        "heldout": held_report, "fit": fit_report,
    }
    return Learned(Patterns(settings, model, form, upper, lower, _rounded(report)), chosen, lines, obs, held)


def evaluate(pat: Patterns, runs: list[LoggedRun], lines: list[LineModel], obs: list) -> dict:
    """Errors of both layers on the given runs: shares (R^2, RMSE, mean absolute error in seconds), the
    lower layer one division ahead from the logged entry speed, and the whole chained speed curve."""
    if not runs:
        return {"runs": 0}
    a_obs, a_pred, sec_err = [], [], []
    v1_obs, v1_pred, vc_obs, vc_pred = [], [], [], []
    for run, line, (shares, speeds) in zip(runs, lines, obs):
        T = run.running_time_s
        pred = pat.shares(line, run.mass_t, T)
        a_obs.append(shares)
        a_pred.append(pred)
        sec_err.append(np.abs(pred - shares) * T)
        for i, sec in enumerate(line.sections):
            X = np.array([line.lower_inputs(i, k, pat.settings.entry(speeds[i], k), shares[i], run.mass_t, T)
                          for k in range(1, line.divisions + 1)])
            v1_obs.append(speeds[i, 1:])
            v1_pred.append(pat.lower.predict(X, [sec.kind] * line.divisions))
        chained = pat.speeds(line, run.mass_t, T, shares=pred)
        vc_obs.append(speeds.ravel())
        vc_pred.append(chained.ravel())
    a_obs, a_pred = np.concatenate(a_obs), np.concatenate(a_pred)
    v1_obs, v1_pred = np.concatenate(v1_obs), np.concatenate(v1_pred)
    vc_obs, vc_pred = np.concatenate(vc_obs), np.concatenate(vc_pred)
    return {"runs": len(runs),
            "upper": {"r2": r2(a_obs, a_pred), "rmse_share": rmse(a_obs, a_pred),
                      "mean_abs_error_s": float(np.mean(np.concatenate(sec_err)))},
            "lower": {"one_step_r2": r2(v1_obs, v1_pred), "one_step_rmse_kmh": rmse(v1_obs, v1_pred),
                      "chained_r2": r2(vc_obs, vc_pred), "chained_rmse_kmh": rmse(vc_obs, vc_pred)}}


def _rounded(x, digits: int = 6):
    if isinstance(x, dict):
        return {k: _rounded(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_rounded(v, digits) for v in x]
    if isinstance(x, (float, np.floating)):
        return round(float(x), digits) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x
