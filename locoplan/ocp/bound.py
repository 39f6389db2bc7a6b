"""The yardstick: the least traction energy E* a train can use on a route in a running time.

E* is the MPOC paper's minimum-energy problem (neutral sections included) of the same train model the
calculator runs, solved on the calculator's own cells by a structured interior-point method
(``ocp/cells.py``, ``ocp/ipm.py``) on successively halved grids until two agree to ``E_STAR_TOL``: the
finer grid's optimum is E*, their difference its stated accuracy. Every plan's
``gap_to_optimum_percent`` is ``(E - E*(T)) / E*(T) x 100`` with ``T`` the plan's own running time.

``check_bound`` solves the same problem a second, independent way, by the multi-phase Radau collocation
with hp mesh refinement of ``ocp --objective energy`` (CasADi, IPOPT): ``bound --check`` and
benchmarks/bench_bound.py print both.

Solutions are cached per (route, train, model options, time) in this process, and the last solution of a
route and train starts the next solve at another time (the energy-time curve: each point after the first
starts from its neighbour). Results are also kept on disk (``LOCOPLAN_CACHE_DIR``, default
``~/.cache/locoplan``; empty = off), keyed by a hash of everything E* depends on, the source of every module it imports
included (``code_digest``), so that a command run twice, or a batch over the same cases, solves each E* once.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import tempfile
from dataclasses import asdict, dataclass, fields, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import InfeasibleError, LocoplanError
from ..model.route import Route
from ..model.train import Train
from ..physics.units import KJ_PER_KWH, kwh, ms
from ..sim.calculator import ModelOptions, TractionCalculator

DEFAULT_MESH_TOL = 1e-5
DEFAULT_MAX_DEGREE = 10
"""The Radau method's defaults (as ``ocp --objective energy``), for the check and the fallback."""

E_STAR_TOL = 4e-5
"""E* is refined until two grids agree to this share (of E*, or of ``percent_floor_kwh`` where E* is
smaller): inside the 0.005 % a gap's last printed digit needs (``GAP_DIGIT_PERCENT``)."""

FASTEST_SHARE = 1e-3
"""Within this share of the fastest run's time the minimum-energy problem has (nearly) one feasible run,
no interior for the interior-point method: where its solve and the Radau method's both fail there, E* is the
fastest run's energy."""

METHOD = "cells"
CHECK_METHOD = "radau"

_BOUNDS: dict[tuple, "Bound"] = {}
_WARM: dict[tuple, object] = {}


@dataclass(frozen=True)
class Bound:
    """E* at one running time: ``energy_kwh``, whether the grids agreed to the tolerance (``converged``),
    the finest grid's cells and cell length [m], the wall time of the solve [s] (0 when it came from the
    cache), ``accuracy``: E*'s estimated relative accuracy (the last two grids' difference; None when
    unknown), the curve's slope there, and the method that solved it."""

    time_s: float
    energy_kwh: float
    converged: bool
    cells: int
    step_m: float
    solve_time_s: float
    accuracy: float | None = None
    slope_kwh_per_s: float | None = None
    """dE*/dT at this time [kWh/s] (the running time's multiplier): what a second more saves."""
    method: str = METHOD
    objective: str = "traction"
    """What E* minimises: ``traction`` (the traction work) or ``net`` (less what the electric brake recovers)."""
    traction_kwh: float | None = None
    recovered_kwh: float | None = None
    """The optimum's own traction work and the energy its electric brake returns [kWh] (None when unknown):
    E* is the first, or with the ``net`` objective their difference."""

    @property
    def accuracy_percent(self) -> float | None:
        return None if self.accuracy is None else 100.0 * self.accuracy


def relaxed(options: ModelOptions | None) -> ModelOptions:
    """The model E* is computed in: ``options`` with the air brake relaxed to a continuous force the run may
    modulate at will (no cycle: ``ModelOptions.air_cycle`` False). Every run that keeps the cycle's rules is a
    run of the relaxation, so E* stays a lower bound on the energy of any plan the calculator accepts."""
    return replace(options or ModelOptions(), air_cycle=False)


def _train_key(train: Train) -> tuple:
    arrays = (train.traction_speed_kmh, train.traction_kn, train.electric_brake_speed_kmh, train.electric_brake_kn,
              train.air_brake_speed_kmh, train.air_brake_kn)
    return (train.name, train.mass_t, train.inertial_mass_t, train.length_m, train.max_speed_kmh, train.resistance_kn,
            tuple(np.asarray(a, float).tobytes() for a in arrays))


def _base_key(route: Route, train: Train, options: ModelOptions) -> tuple:
    # the grid of the calculator is E*'s own (ocp.cells): the calculator's step is not part of the problem
    return (route.model_dump_json(), _train_key(train), replace(options, step_m=0.0))


PACKAGE_DIR = Path(__file__).resolve().parents[1]
"""The locoplan package's folder, whose sources ``code_digest`` hashes."""

# ``from``/``import`` first, for the regex engine's fast literal search; a match must begin its line
_FROM_IMPORT = re.compile(r"from[ \t]+(\.*)([\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n]*)")
_PLAIN_IMPORT = re.compile(r"import[ \t]+locoplan\.([\w.]+)")


def _statements(pattern: re.Pattern, text: str) -> list[tuple]:
    return [m.groups() for m in pattern.finditer(text)
            if text[text.rfind("\n", 0, m.start()) + 1:m.start()].strip(" \t") == ""]


def code_sources(roots: tuple[str, ...], package: Path = PACKAGE_DIR) -> list[str]:
    """Every locoplan source file (relative to ``package``, with ``/``) the modules ``roots`` (a ``.py`` file, or a
    folder for all of its modules) import, directly or through others, themselves included: the imports are
    read from the text (function-level ones too), each module brings its packages' ``__init__.py``, and a
    package that imports its modules by name at run time (``importlib.import_module``) brings all of them.
    The top-level ``__init__.py`` only maps the public names for users, so its run-time imports are not
    followed."""
    files = {os.path.relpath(os.path.join(d, f), package).replace(os.sep, "/")
             for d, _, names in os.walk(package) for f in names if f.endswith(".py")}

    def under(folder: str) -> list[str]:
        return [f for f in files if f.startswith(folder + "/")]

    todo = [f for r in roots for f in ([r] if r.endswith(".py") else under(r))]
    seen: set[str] = set()
    while todo:
        f = todo.pop()
        if f in seen or f not in files:
            continue
        seen.add(f)
        parts = f.split("/")[:-1]
        todo.extend("/".join(parts[:i] + ["__init__.py"]) for i in range(len(parts) + 1))
        text = (package / f).read_text(encoding="utf-8")
        if parts and f.endswith("__init__.py") and "import_module(" in text:
            todo.extend(under("/".join(parts)))
        targets = [(m.split("."), ()) for (m,) in _statements(_PLAIN_IMPORT, text)]
        for dots, module, names in _statements(_FROM_IMPORT, text):
            if dots:
                base = parts[:len(parts) - (len(dots) - 1)] if len(dots) > 1 else parts
            elif module.split(".")[0] == "locoplan":
                base, module = [], module.partition(".")[2]
            else:
                continue  # another package's
            names = re.sub(r"#[^\n]*", "", names).strip("() \n")
            targets.append((base + [m for m in module.split(".") if m],
                            [n.split()[0] for n in names.split(",") if n.strip()]))
        for path, names in targets:
            where = "/".join(path) + "/" if path else ""
            todo.extend([where[:-1] + ".py", where + "__init__.py"] if path else ["__init__.py"])
            todo.extend(x for n in names for x in (f"{where}{n}.py", f"{where}{n}/__init__.py"))
    return sorted(seen)


@lru_cache(maxsize=None)
def code_digest(roots: tuple[str, ...], package: Path = PACKAGE_DIR) -> str:
    """A hash of every source ``code_sources(roots)`` finds: a result cached on disk is only as good as the code
    it was computed with, all of it, not only the package that computed it."""
    h = hashlib.sha256()
    for f in code_sources(roots, package):
        h.update(f.encode() + b"\0" + (package / f).read_bytes())
    return h.hexdigest()[:16]


E_STAR_SOURCES = ("ocp",)
"""E*'s code: the optimal-control package and all it imports (the calculator's grid and speed envelope in
sim/, the route and train in model/, the formulas in physics/, ...)."""


def _code_digest() -> str:
    return code_digest(E_STAR_SOURCES, PACKAGE_DIR)


def _cache_file(key: tuple) -> Path | None:
    root = os.environ.get("LOCOPLAN_CACHE_DIR", str(Path.home() / ".cache" / "locoplan"))
    if not root:
        return None
    digest = hashlib.sha256(repr((key, _code_digest())).encode()).hexdigest()[:32]
    return Path(root) / "bounds" / f"{digest}.json"


def cache_load(key: tuple) -> dict | None:
    """What ``cache_store`` kept under ``key`` (a hash of it and of the code, ``_cache_file``), or None."""
    f = _cache_file(key)
    try:
        return json.loads(f.read_text()) if f is not None and f.is_file() else None
    except (OSError, ValueError):
        return None


def cache_store(key: tuple, data: dict) -> None:
    """Keep ``data`` (plain JSON) on disk under ``key``: atomic; a cache that cannot be written is simply not kept,
    nor its temporary file."""
    f = _cache_file(key)
    if f is None:
        return
    tmp = None
    try:
        f.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=f.parent, suffix=".tmp")
        with os.fdopen(fd, "w") as out:
            json.dump(data, out)
        os.replace(tmp, f)
    except (OSError, TypeError, ValueError):
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def _cache_read(key: tuple) -> "Bound | None":
    """The E* kept on disk under ``key``, or None when there is none or it is not one E* could be: a field missing,
    unknown or of the wrong type, a number not finite, an energy, a grid or a time out of its range, or a time other
    than the one asked (a damaged or foreign file is ignored, and E* solved again)."""
    data = cache_load(key)
    if data is None or bound_problem(data, key[1]) is not None:
        return None
    return Bound(**data)


_REAL = (int, float)
NEGATIVE_TOLERANCE_KWH = 0.01
"""How far below 0 a kept traction energy may lie and still be the solver's tolerance, not a damaged entry [kWh]."""


def bound_problem(data, time_s: float | None = None) -> str | None:
    """What is wrong with ``data`` read back as a :class:`Bound` (the fields ``asdict`` wrote), or None. ``time_s``:
    the (rounded) time its key names; the stored time must round to it."""
    if not isinstance(data, dict):
        return "not a JSON object"
    names = [f.name for f in fields(Bound)]
    if set(data) - set(names):
        return f"unknown fields {sorted(set(data) - set(names))}"
    required = ("time_s", "energy_kwh", "converged", "cells", "step_m", "solve_time_s")
    if any(n not in data for n in required):
        return "a field is missing"

    def number(name, low=None, optional=False, integer=False):
        v = data.get(name)
        if v is None and optional:
            return None
        if isinstance(v, bool) or not isinstance(v, int if integer else _REAL) or not math.isfinite(v):
            return f"{name} is not a finite {'integer' if integer else 'number'} ({v!r})"
        if low is not None and v < low:
            return f"{name} is {v!r}, below {low}"
        return None

    objective = data.get("objective", "traction")
    if objective not in ("traction", "net"):
        return f"objective is {objective!r}"
    if not isinstance(data["converged"], bool) or not isinstance(data.get("method", METHOD), str):
        return "converged or method of the wrong type"
    # a traction E* is never negative beyond the solver's tolerance (a net one may be: the brake returns energy)
    for why in (number("time_s", 1e-9), number("energy_kwh", -NEGATIVE_TOLERANCE_KWH if objective == "traction" else None),
                number("cells", 1, integer=True), number("step_m", 0.0), number("solve_time_s", 0.0),
                number("accuracy", 0.0, optional=True), number("slope_kwh_per_s", optional=True),
                number("traction_kwh", -NEGATIVE_TOLERANCE_KWH, optional=True),
                number("recovered_kwh", -NEGATIVE_TOLERANCE_KWH, optional=True)):
        if why:
            return why
    if time_s is not None and round(float(data["time_s"]), 2) != time_s:
        return f"time_s {data['time_s']!r} is not the time {time_s:g} s its key names"
    return None


def _cache_write(key: tuple, b: "Bound") -> None:
    cache_store(key, asdict(b))


def net_regen(train: Train, objective: str) -> float:
    """The share of the electric brake's work E* credits: the train's ``regen_efficiency`` with the ``net``
    objective, else 0 (the traction work; for a train that regenerates nothing the two are one problem)."""
    return float(train.regen_efficiency) if objective == "net" else 0.0


def energy_bound(route: Route, train: Train, options: ModelOptions | None = None, time_s: float | None = None, *,
                 calc: TractionCalculator | None = None, objective: str = "traction") -> Bound:
    """E* of ``train`` on ``route`` in ``time_s`` seconds (default: the route's schedule) [kWh]: the least
    traction work, or with ``objective="net"`` the least net energy (traction less what the electric brake
    recovers, ``ocp.cells.NetCellEnergyProblem``).

    Raises ``InfeasibleError`` when no run takes that little time, the consist cannot run the route, or
    the solver finds no optimum."""
    from .train_energy import check_runnable

    options = relaxed(options)
    time_s = float(time_s if time_s is not None else route.schedule.run_time_s)
    regen = net_regen(train, objective)
    base = _problem_key(route, train, options, regen)
    calc = calc if calc is not None and calc.options == options and calc.route == route else TractionCalculator(route, train, options)
    check_runnable(calc, time_s)  # first: a cached E* (keyed by the time to 0.01 s) never answers a time below the fastest run
    known = _known(base, time_s, E_STAR_TOL)
    if known is not None:
        return known
    from .cells import solve_estar

    floor = percent_floor_kwh(route, train)
    try:
        try:
            es = solve_estar(route, train, options, time_s, tol=E_STAR_TOL, floor_kwh=floor, warm=_WARM.get(base),
                             regen=regen)
        except InfeasibleError:
            if _WARM.get(base) is None:
                raise
            es = solve_estar(route, train, options, time_s, tol=E_STAR_TOL, floor_kwh=floor, regen=regen)  # cold
    except InfeasibleError:
        fastest = calc.evaluate(("T",), np.zeros((1, 0)), recovered=True)
        near = time_s <= float(fastest.running_time_s[0]) * (1 + FASTEST_SHARE)
        try:  # the interior-point solve did not converge: the Radau method, slower but with IPOPT's restoration
            b = check_bound(route, train, options, time_s, mesh_tol=DEFAULT_MESH_TOL, max_degree=DEFAULT_MAX_DEGREE,
                            objective=objective)
        except InfeasibleError:
            if not near:
                raise
            # at the fastest run's time that run is the only one: its energy, with no accuracy to state (a few
            # tenths of a per cent slower, runs may already use several per cent less: the Radau method first)
            e_tr, e_rec = float(fastest.traction_energy_kwh[0]), float(fastest.recovered_energy_kwh[0])
            b = Bound(time_s, e_tr - (e_rec if regen > 0 else 0.0), False, len(calc.h_m), calc.options.step_m, 0.0,
                      None, None, "fastest run", objective, e_tr, e_rec)
    else:
        _WARM[base] = es.solution
        b = Bound(time_s, es.energy_kwh, es.converged, es.cells[-1], es.steps_m[-1], es.solve_time_s, es.accuracy,
                  es.slope_kwh_per_s, METHOD, objective, es.solution.traction_kwh, es.solution.recovered_kwh)
    return _remember(base, time_s, E_STAR_TOL, METHOD, b)


@dataclass(frozen=True)
class OptimumRun:
    """E*'s own run at one running time, on the finest grid of its solve: ``bound`` (E*, its accuracy, dE*/dT), the
    node positions [m] and speeds [m/s] and each cell's traction force [kN]. Its traction work, sum h F over the
    cells, is ``bound.energy_kwh``; its running time, sum 2 h / (v0 + v1), is ``bound.time_s`` to the solver's
    tolerance."""

    bound: Bound
    s_m: np.ndarray
    v_ms: np.ndarray
    traction_kn: np.ndarray
    kinetic_price: np.ndarray
    """Each cell's price of kinetic energy [kWh of traction per kWh of kinetic energy]: what one more kWh of the
    train's kinetic energy there saves the optimum from there on (the multiplier of the cell's work-energy balance;
    1 where the optimum holds a speed with part of its traction, above 1 under full traction, falling towards 0
    while it coasts, 0 where it holds a speed by braking)."""
    mass_t: float
    """The mass [t] whose kinetic energy that is (the train's inertial mass in the model)."""

    def cell_times_s(self) -> np.ndarray:
        """Each cell's running time [s], ``2 h / (v0 + v1)`` (constant acceleration over the cell, as E*'s scheme)."""
        v = self.v_ms
        return 2.0 * np.diff(self.s_m) / np.maximum(v[:-1] + v[1:], 1e-12)


_RUNS: dict[tuple, OptimumRun] = {}
_RUN_CALCS: dict[tuple, TractionCalculator] = {}


def optimum_run(route: Route, train: Train, options: ModelOptions | None, time_s: float) -> OptimumRun:
    """E* at ``time_s`` (the traction objective) with its run: what ``energy_bound`` solves, to the same tolerance,
    kept with the finest grid's solution, so that the run's energy and time can be split along the line (``locoplan
    replay``). Kept in this process and on disk (``LOCOPLAN_CACHE_DIR``, as E*); the E* found is also what
    ``energy_bound`` answers for that time afterwards. Raises ``InfeasibleError`` as ``energy_bound`` (a time below
    the fastest run, a consist that cannot run the route, a solve that does not converge)."""
    from .cells import solve_estar
    from .train_energy import check_runnable

    options = relaxed(options)
    time_s = float(time_s)
    base = _problem_key(route, train, options, 0.0)
    if base not in _RUN_CALCS:  # built once per route, train and model: a log set has many runs of one line
        if len(_RUN_CALCS) > 16:
            _RUN_CALCS.pop(next(iter(_RUN_CALCS)))
        _RUN_CALCS[base] = TractionCalculator(route, train, options)
    # first: a kept run (keyed by the time to 0.01 s) never answers a time below the fastest run
    check_runnable(_RUN_CALCS[base], time_s)
    key = (base, round(time_s, 2), "run", E_STAR_TOL)
    if key in _RUNS:
        return _RUNS[key]
    kept = _run_read(key, time_s)
    if kept is None:
        floor = percent_floor_kwh(route, train)
        try:
            es = solve_estar(route, train, options, time_s, tol=E_STAR_TOL, floor_kwh=floor, warm=_WARM.get(base))
        except InfeasibleError:
            if _WARM.get(base) is None:
                raise
            es = solve_estar(route, train, options, time_s, tol=E_STAR_TOL, floor_kwh=floor)  # cold
        _WARM[base] = es.solution
        sol = es.solution
        b = Bound(time_s, es.energy_kwh, es.converged, es.cells[-1], es.steps_m[-1], es.solve_time_s, es.accuracy,
                  es.slope_kwh_per_s, METHOD, "traction", sol.traction_kwh, sol.recovered_kwh)
        kept = OptimumRun(b, np.asarray(sol.s_m, float), np.asarray(sol.v_ms, float), np.asarray(sol.traction_kn, float),
                          kinetic_price(es.calc, time_s, sol), float(es.calc.m_eff_t))
        _run_write(key, kept)
    _remember(base, time_s, E_STAR_TOL, METHOD, replace(kept.bound, time_s=time_s))  # bound and gaps say the same E*
    if len(_RUNS) > 64:
        _RUNS.pop(next(iter(_RUNS)))
    _RUNS[key] = kept
    return kept


def kinetic_price(calc: TractionCalculator, time_s: float, sol) -> np.ndarray:
    """Each cell's price of kinetic energy in E*'s solution ``sol`` on ``calc``'s cells (``OptimumRun.kinetic_price``):
    the multiplier of the cell's balance, ``M (v1^2 - v0^2) / 2 - h (F - B - R - G) = 0`` scaled by ``h F_ref``, in
    kWh of the objective per kWh of kinetic energy (where the optimum applies part of its traction the objective's
    gradient h on F meets the balance's, so the price is 1 there)."""
    from .cells import cell_problem

    prob = cell_problem(calc, time_s)
    return np.asarray(sol.result.y, float) * prob.e_ref * KJ_PER_KWH / (calc.h_m * prob.f_ref)


_RUN_META = ("energy_kwh", "converged", "cells", "step_m", "solve_time_s", "accuracy", "slope_kwh_per_s", "traction_kwh",
             "recovered_kwh", "mass_t")


def _run_read(key: tuple, time_s: float) -> "OptimumRun | None":
    """A run ``optimum_run`` kept on disk, or None (none, unreadable, or not a run: shapes that disagree, a value not
    finite, a speed or force below 0, an energy that is not the cells' sum: a damaged file is solved again)."""
    f = _cache_file(key)
    if f is None:
        return None
    try:
        with np.load(f.with_suffix(".run.npz"), allow_pickle=False) as z:
            s, v, tr, mu, meta = (np.array(z[k], dtype=float) for k in ("s_m", "v_ms", "traction_kn", "kinetic_price", "meta"))
    except (OSError, ValueError, KeyError, TypeError, EOFError):
        return None
    n = s.size - 1
    if not (n >= 1 and v.shape == (n + 1,) and tr.shape == mu.shape == (n,) and meta.shape == (len(_RUN_META),)):
        return None
    if not (all(np.all(np.isfinite(a)) for a in (s, v, tr, mu, meta[-1:])) and np.all(np.diff(s) > 0)
            and v.min() >= 0 and tr.min() >= -1e-6 and meta[-1] > 0):
        return None
    data = dict(zip(_RUN_META, (float(x) for x in meta)))
    if not math.isfinite(data["energy_kwh"]) or abs(kwh(float(np.sum(np.diff(s) * tr))) - data["energy_kwh"]) > 1e-6 * max(1.0, abs(data["energy_kwh"])):
        return None
    b = Bound(time_s, data["energy_kwh"], bool(data["converged"]), int(data["cells"]), data["step_m"], 0.0,
              None if math.isnan(data["accuracy"]) else data["accuracy"], data["slope_kwh_per_s"], METHOD, "traction",
              data["traction_kwh"], data["recovered_kwh"])
    return OptimumRun(b, s, v, tr, mu, data["mass_t"])


def _run_write(key: tuple, run: OptimumRun) -> None:
    f = _cache_file(key)
    if f is None:
        return
    f = f.with_suffix(".run.npz")
    b = run.bound
    meta = np.array([b.energy_kwh, float(b.converged), b.cells, b.step_m, b.solve_time_s,
                     math.nan if b.accuracy is None else b.accuracy, b.slope_kwh_per_s, b.traction_kwh, b.recovered_kwh,
                     run.mass_t],
                    dtype=float)
    tmp = None
    try:  # atomic, as the bounds' JSON files
        f.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=f.parent, suffix=".tmp.npz")
        with os.fdopen(fd, "wb") as out:
            np.savez(out, s_m=run.s_m, v_ms=run.v_ms, traction_kn=run.traction_kn, kinetic_price=run.kinetic_price,
                     meta=meta)
        os.replace(tmp, f)
    except OSError:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


STRUCTURE_STEP_M = (10.0, 40.0)
STRUCTURE_CELLS = 1500
"""E*'s solution for its structure (``optimum_solution``): one grid of about ``STRUCTURE_CELLS`` cells, their
length kept within ``STRUCTURE_STEP_M`` [m]: fine enough to place each switch within a cell or two, a few
times cheaper than E* to its tolerance."""

_SOLUTIONS: dict[tuple, object] = {}


def optimum_solution(route: Route, train: Train, options: ModelOptions | None, time_s: float, *,
                     objective: str = "traction", step_m: float | None = None):
    """E*'s optimum at ``time_s`` on one grid, (its calculator, its solution: node speeds, each cell's traction and
    braking, ``ocp.cells.CellSolution`` or from the disk cache ``StructureSolution``), for where the optimum
    drives, holds a speed, coasts and brakes: the condition structure of a plan near it. The grid's cells are
    ``step_m`` long (default: about ``STRUCTURE_CELLS`` of them within ``STRUCTURE_STEP_M``), graded towards the
    rest points as E*'s; solved from a cold start, so that the structure, hence the plan read off it, does not
    depend on which E* this process solved before. Kept in this process and on disk (as E*,
    ``LOCOPLAN_CACHE_DIR``). Raises ``InfeasibleError`` as ``energy_bound``."""
    from .cells import cell_calculator, solve_cells
    from .train_energy import check_runnable

    options = relaxed(options)
    regen = net_regen(train, objective)
    base = _problem_key(route, train, options, regen)
    if step_m is None:
        step_m = float(np.clip(route.length_m / STRUCTURE_CELLS, *STRUCTURE_STEP_M))
    key = (base, round(float(time_s), 2), float(step_m))
    if key in _SOLUTIONS:
        check_runnable(_SOLUTIONS[key][0], time_s)  # the key rounds the time: never an answer below the fastest run
    else:
        calc = cell_calculator(route, train, options, step_m)
        check_runnable(calc, time_s)
        sol = _structure_read(key, len(calc.h_m))
        if sol is None:  # (a cold start: the structure a plan is read from must not depend on what was solved
            sol = solve_cells(calc, time_s, regen=regen)  # before; a warm start saves only a few hundredths of a s)
            _structure_write(key, sol)
        if len(_SOLUTIONS) > 32:
            _SOLUTIONS.pop(next(iter(_SOLUTIONS)))
        _SOLUTIONS[key] = (calc, sol)
    return _SOLUTIONS[key]


@dataclass(frozen=True)
class StructureSolution:
    """E*'s solution as ``optimum_solution`` keeps it on disk: what reading its structure needs (node speeds
    [m/s], each cell's traction and braking [kN], the optimum [kWh] and dE*/dT [kWh/s])."""

    v_ms: np.ndarray
    traction_kn: np.ndarray
    brake_kn: np.ndarray
    energy_kwh: float
    slope_kwh_per_s: float


def _structure_read(key: tuple, n_cells: int) -> "StructureSolution | None":
    """A solution ``optimum_solution`` kept on disk, or None (none, unreadable, or not of this grid's shape and
    finite: a damaged or foreign file is ignored and solved again)."""
    f = _cache_file(key)
    if f is None:
        return None
    f = f.with_suffix(".npz")
    try:
        with np.load(f, allow_pickle=False) as z:
            v, tr, br, meta = (np.array(z[k], dtype=float) for k in ("v_ms", "traction_kn", "brake_kn", "meta"))
    except (OSError, ValueError, KeyError, TypeError, EOFError):
        return None
    ok = (v.shape == (n_cells + 1,) and tr.shape == br.shape == (n_cells,) and meta.shape == (2,)
          and all(np.all(np.isfinite(a)) for a in (v, tr, br, meta)) and v.min() >= 0 and tr.min() >= 0 and br.min() >= 0)
    return StructureSolution(v, tr, br, float(meta[0]), float(meta[1])) if ok else None


def _structure_write(key: tuple, sol) -> None:
    f = _cache_file(key)
    if f is None:
        return
    f = f.with_suffix(".npz")
    tmp = None
    try:  # atomic, as the bounds' JSON files
        f.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=f.parent, suffix=".tmp.npz")
        with os.fdopen(fd, "wb") as out:
            np.savez(out, v_ms=sol.v_ms, traction_kn=sol.traction_kn, brake_kn=sol.brake_kn,
                     meta=np.array([sol.energy_kwh, sol.slope_kwh_per_s]))
        os.replace(tmp, f)
    except OSError:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


CURVE_TOL = 1e-4
"""The tolerance of an energy-time curve (``energy_bounds``): E* at each time known to 0.01 %. A single E*
(``energy_bound``) is held to ``E_STAR_TOL``, the finer digit a plan's gap needs."""
CURVE_METHOD = "cells, curve mesh"
CURVE_MIN_TIMES = 4
"""Fewer times than this are each solved on their own (``energy_bound``)."""


def energy_bounds(route: Route, train: Train, options: ModelOptions, times_s: list[float], *,
                  calc: TractionCalculator | None = None, objective: str = "traction",
                  progress=lambda time_s: None) -> list["Bound | LocoplanError"]:
    """E* at each of ``times_s`` (an energy-time curve), one mesh for all: the longest time (the least E*) is
    solved on successively halved grids to ``CURVE_TOL`` as ``energy_bound`` does, the shortest until its
    error in kWh is as small against the longest time's E*; every time between is solved once, on the finer
    of the two final grids, started from its neighbour's solution. Their stated accuracy is the mesh's: the
    larger of the two ends' errors in kWh, relative to each time's own E* (at most ``CURVE_TOL``, E* falling
    with the time). A time without an optimum is its ``LocoplanError``; a time already solved alone is
    taken from there. ``objective``: as :func:`energy_bound`'s. ``progress(time_s)`` is told of each time
    as its solve begins (or it is found solved)."""
    from .cells import WARM_MU, cell_problem, solve_cells, solve_estar, warm_point
    from .train_energy import check_runnable

    options = relaxed(options)
    calc = calc if calc is not None and calc.options == options and calc.route == route else TractionCalculator(route, train, options)
    regen = net_regen(train, objective)
    base = _problem_key(route, train, options, regen)

    def alone(t: float):  # E* at one time on its own nested grids
        try:
            return energy_bound(route, train, options, t, calc=calc, objective=objective)
        except LocoplanError as exc:
            return exc

    def bound(t, e, converged, cells, step_m, solve_s, acc, slope, method, sol) -> Bound:
        return Bound(t, e, converged, cells, step_m, solve_s, acc, slope, method, objective, sol.traction_kwh,
                     sol.recovered_kwh)

    out: dict[float, Bound | LocoplanError] = {}
    todo = []
    for t in dict.fromkeys(float(x) for x in times_s):
        try:
            check_runnable(calc, t)  # first, as in energy_bound: no cached E* answers a time below the fastest run
        except LocoplanError as exc:
            progress(t)
            out[t] = exc
            continue
        known = _known(base, t, E_STAR_TOL) or _known(base, t, CURVE_TOL, CURVE_METHOD)
        if known is not None:
            progress(t)
            out[t] = known
            continue
        todo.append(t)
    todo.sort()
    if len(todo) < CURVE_MIN_TIMES:
        for t in todo:
            progress(t)
            out[t] = alone(t)
        return [out[float(t)] for t in times_s]
    floor = percent_floor_kwh(route, train)
    try:  # the longest time has the least E*: the other end's error in kWh must be as small against it
        progress(todo[-1])
        hi = solve_estar(route, train, options, todo[-1], tol=CURVE_TOL, floor_kwh=floor, regen=regen)
        progress(todo[0])
        lo = solve_estar(route, train, options, todo[0], tol=CURVE_TOL, floor_kwh=floor,
                         scale_kwh=max(abs(hi.energy_kwh), floor), regen=regen)
        ends = [lo, hi]
    except InfeasibleError:  # an end without an optimum on the grids: every time on its own
        ends = None
    if ends is None:
        for t in todo:
            progress(t)
            out[t] = alone(t)
        return [out[float(t)] for t in times_s]
    error_kwh = max(e.accuracy * max(abs(e.energy_kwh), floor) for e in ends)
    mesh = min(ends, key=lambda e: e.steps_m[-1])
    for t, e in zip((todo[0], todo[-1]), ends):
        out[t] = _remember(base, t, CURVE_TOL, CURVE_METHOD,
                           bound(t, e.energy_kwh, e.converged, e.cells[-1], e.steps_m[-1], e.solve_time_s, e.accuracy,
                                 e.slope_kwh_per_s, METHOD, e.solution))
    prev = mesh.solution
    for t in todo[1:-1]:
        progress(t)
        try:
            try:
                sol = solve_cells(mesh.calc, t, mu_init=WARM_MU, point=warm_point(cell_problem(mesh.calc, t, regen), prev)[0],
                                  regen=regen)
            except InfeasibleError:
                sol = solve_cells(mesh.calc, t, regen=regen)
        except InfeasibleError:
            out[t] = alone(t)
            continue
        prev = sol
        acc = error_kwh / max(abs(sol.energy_kwh), floor, 1e-9)
        out[t] = _remember(base, t, CURVE_TOL, CURVE_METHOD,
                           bound(t, sol.energy_kwh, acc <= CURVE_TOL, len(mesh.calc.h_m), mesh.steps_m[-1],
                                 sol.solve_time_s, acc, sol.slope_kwh_per_s, CURVE_METHOD, sol))
    return [out[float(t)] for t in times_s]


def _problem_key(route: Route, train: Train, options: ModelOptions, regen: float) -> tuple:
    """The key of E*'s problem: route, train and model, and the regenerative credit of the ``net`` objective
    (the traction problem keeps the keys it always had)."""
    base = _base_key(route, train, options)
    return (base, "net", regen) if regen > 0 else base


def _known(base: tuple, time_s: float, tol: float, method: str = METHOD) -> "Bound | None":
    """E* at ``time_s`` solved before (this process, or the disk cache), or None."""
    key = (base, round(time_s, 2), method, tol)
    if key not in _BOUNDS:
        cached = _cache_read(key)
        if cached is None:
            return None
        _BOUNDS[key] = cached
    return replace(_BOUNDS[key], solve_time_s=0.0)


def _remember(base: tuple, time_s: float, tol: float, method: str, b: "Bound") -> "Bound":
    key = (base, round(time_s, 2), method, tol)
    _BOUNDS[key] = b
    _cache_write(key, b)
    return b


def check_bound(route: Route, train: Train, options: ModelOptions, time_s: float, *, mesh_tol: float,
                max_degree: int, objective: str = "traction") -> Bound:
    """E* by the second, independent method: multi-phase Radau (LGR) collocation with hp mesh refinement
    (``ocp/energy.py``, the solver of ``ocp --objective energy``; with the ``net`` objective, its regenerative
    credit at the train's ``regen_efficiency``), refined until E* moves by at most 2e-5 over a refinement or
    the mesh meets ``mesh_tol``; its accuracy is that last move."""
    from ..physics.energy import EnergyModel
    from .energy import solve_energy
    from .train_energy import EnergyOptions, build_problem, check_runnable

    options = relaxed(options)
    calc = TractionCalculator(route, train, options)
    check_runnable(calc, time_s)
    regen = net_regen(train, objective)
    tep = build_problem(route, train, options, time_s,
                        EnergyOptions(energy=EnergyModel(regen_credit=regen)) if regen > 0 else EnergyOptions())
    es = solve_energy(tep, calc, mesh_tol=mesh_tol, max_degree=max_degree, energy_tol=2e-5)
    accuracy = es.accuracy
    if route.length_m <= SHORT_LEG_M:  # a second start: the lower of two local optima
        try:
            other = solve_energy(tep, calc, mesh_tol=mesh_tol, max_degree=max_degree, energy_tol=2e-5, **SECOND_START)
        except LocoplanError:
            other = None
        if other is not None and other.success:
            best, rest = (other, es) if other.objective_kwh < es.objective_kwh else (es, other)
            best.wall_time_s = es.wall_time_s + other.wall_time_s
            es, accuracy = best, best.accuracy
            if rest.accuracy is not None:  # the other start's optimum and its accuracy bound this one's too
                apart = abs(best.objective_kwh - rest.objective_kwh) / max(abs(best.objective_kwh), 1e-9)
                acc = max(apart, rest.accuracy)
                accuracy = acc if best.accuracy is None else min(best.accuracy, acc)
    return Bound(time_s, es.objective_kwh, es.converged, es.solution.mesh.n_points, 0.0, es.wall_time_s, accuracy,
                 es.slope_kwh_per_s, CHECK_METHOD, objective)


SHORT_LEG_M = 5000.0
"""On a route up to this long the Radau check is solved from two starting meshes, the usual one (intervals up
to 500 m, 5 LGR points, departure and stop intervals up to 200 m) and a fine one (``SECOND_START``), and the
lower optimum is kept: on short legs, where departure and stop are most of the run, the refinement from the
coarse mesh can settle on a local optimum 1-4 % above the optimum (CN_Songjiazhuang_Yizhuang leg 12, HXD1
+ 50 x C80 at 189.2 s: 69.71 kWh, against 67.88 from the fine start and from the cells)."""
SECOND_START = {"interval_m": 100.0, "degree": 4, "end_interval_m": 50.0}


PERCENT_FLOOR_SHARE = 0.02
"""A gap is given in per cent only where E* is at least this share of the train's kinetic energy at the
route's highest limit: below it the least-energy run is nearly all coasting (a falling line), E* is a few
kWh or less, and a percentage of it would mostly measure the solver's tolerance (a plan 0.7 kWh under an
E* of 0.7 kWh is "-100 %"). The gap in kWh is always given."""


GAP_DIGIT_PERCENT = 0.01
"""A gap in per cent is printed to this digit (``+0.07 %``)."""


@dataclass(frozen=True)
class Gap:
    """A plan against the optimum at its own running time: E* [kWh], E - E* [kWh], (E - E*) / E* [%],
    and E*'s estimated accuracy [%] (``Bound.accuracy``; None when unknown).

    The percentage is given only where it means what it says: E* at least ``PERCENT_FLOOR_SHARE`` of the
    train's kinetic energy, and E* known better than half the percentage's last printed digit
    (``GAP_DIGIT_PERCENT``); otherwise it is None and a report says "E* within X %"."""

    optimum_kwh: float
    gap_kwh: float
    gap_percent: float | None
    accuracy_percent: float | None = None


def within_percent(accuracy_percent: float | None) -> str:
    """E*'s accuracy as a report gives it: two significant digits, rounded up ("0.012 %"; below
    0.0001 %: "< 0.0001 %")."""
    if accuracy_percent is None:
        return "unknown (not converged)"
    if accuracy_percent < 1e-4:
        return "< 0.0001 %"
    step = 10.0 ** (math.floor(math.log10(accuracy_percent)) - 1)  # the second significant digit
    return f"{float(f'{math.ceil(accuracy_percent / step - 1e-9) * step:.2g}'):g} %"


def percent_digits(accuracy_percent: float | None) -> int | None:
    """Decimals a percentage of E* may show (2, 1, 0, or None for none): its last digit must be surer than
    half of it, as a plan's gap (``GAP_DIGIT_PERCENT``) with two."""
    if accuracy_percent is None:
        return None
    for d in (2, 1, 0):
        if accuracy_percent < 0.5 * 10.0 ** -d:
            return d
    return None


def percent_floor_kwh(route: Route, train: Train) -> float:
    """``PERCENT_FLOOR_SHARE`` x the kinetic energy [kWh] of ``train`` at ``route``'s highest limit."""
    v_top = ms(min(max(x.kmh for x in route.speed_limits), float(train.max_speed_kmh)))
    return kwh(PERCENT_FLOOR_SHARE * 0.5 * float(train.inertial_mass_t) * v_top ** 2)


def gap_to_optimum(route: Route, train: Train, options: ModelOptions, time_s: float, energy_kwh: float,
                   calc: TractionCalculator | None = None, objective: str = "traction") -> Gap | None:
    """The plan's energy ``energy_kwh`` (what ``objective`` counts) against E* of that objective at its own
    running time ``time_s``; None when there is no E* there (an infeasible plan, a time the optimum cannot
    reach, a solver failure)."""
    if not (math.isfinite(time_s) and math.isfinite(energy_kwh)):
        return None
    try:
        b = energy_bound(route, train, options, time_s, calc=calc, objective=objective)
    except LocoplanError:
        return None
    # traction work is never negative: below 0 is the solver's tolerance (a net energy may be)
    e_star = b.energy_kwh if net_regen(train, objective) > 0 else max(b.energy_kwh, 0.0)
    acc = b.accuracy_percent
    sure = acc is not None and acc < 0.5 * GAP_DIGIT_PERCENT
    pct = (round(100.0 * (energy_kwh - e_star) / e_star, 2) if sure and e_star >= percent_floor_kwh(route, train)
           else None)
    return Gap(round(e_star, 2), round(energy_kwh - e_star, 2), pct, None if acc is None else float(f"{acc:.2g}"))


def gap_to_optimum_percent(route: Route, train: Train, options: ModelOptions, time_s: float, energy_kwh: float,
                           calc: TractionCalculator | None = None, objective: str = "traction") -> float | None:
    """``(E - E*) / E* x 100`` at the plan's own running time ``time_s`` (see :func:`gap_to_optimum`)."""
    g = gap_to_optimum(route, train, options, time_s, energy_kwh, calc, objective)
    return None if g is None else g.gap_percent
