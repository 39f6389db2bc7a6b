"""railtoolkit running-path and rolling-stock files (YAML, schema 2022.05, as read by TrainRuns.jl)
to locoplan route, vehicle and consist files.

Each file is recognised by its ``schema:`` key, so paths and trains may come in any order.

Running path: ``characteristic_sections`` rows [s_m, v_limit_kmh, f_Rp_permille] each start a
section that runs to the next row; the last row marks the path's end (its values are unused, as in
TrainRuns.jl). f_Rp is the *path resistance*: gradient plus curve (and any other line) resistance
per mille. It becomes the route's ``gradients`` (so the route has no separate ``curves``): the force
is the same, f_Rp / 1000 * m * g.

Rolling stock: each vehicle becomes a vehicle file, each train a consist file. Resistance formulas
(TrainRuns.jl, after Wende 2003 pp. 151-153; v in km/h, v00 = 100 km/h, dv_air = 15 km/h, the
coefficients in per mille of the vehicle's weight):

- traction unit / multiple unit: F = g [f_Rtd0 m_td + f_Rtc0 m_tc + f_Rt2 m ((v + dv_air) / v00)^2] / 1000
  with f_Rtd0 = base_resistance (driving axles, mass m_td = mass_traction), f_Rtc0 =
  rolling_resistance (carrying axles, m_tc = m - m_td), f_Rt2 = air_resistance;
- freight wagon (Strahl): F = g m [f_Rw0 + f_Rw2 (v / v00)^2] / 1000;
- passenger wagon (Sauthoff): F = g m [f_Rw0 + f_Rw1 v / v00 + f_Rw2 ((v + dv_air) / v00)^2] / 1000.

Each is a quadratic in v, so it is exactly locoplan's w0 = a + b v + c v^2 [N/kN] (per mille of the
vehicle's own weight) with the coefficients of ``davis_coefficients``. locoplan applies w0 to each
vehicle's own mass, loaded; TrainRuns.jl applies one set of wagon coefficients (the unweighted mean
over the wagons) to all wagons' mass: the two agree whenever the wagons share their coefficients.
"""

from __future__ import annotations

from itertools import groupby
from pathlib import Path
from typing import Any

from ..load import _line_for, read_yaml
from . import emit
from .base import Imported, ImportedFile, ImportOptions, SourceChecker, increasing, licence_near, path_str

PATH_SCHEMA = "https://railtoolkit.org/schema/running-path.json"
STOCK_SCHEMA = "https://railtoolkit.org/schema/rolling-stock.json"
SCHEMA_VERSIONS = ("2022.05",)

V00_KMH = 100.0
"""TrainRuns.jl's velocity factor v00 = 100 km/h."""
DV_AIR_KMH = 15.0
"""TrainRuns.jl's Delta v_air = 15 km/h: the air speed relative to the train exceeds its ground speed."""
DEFAULT_ROTATION_MASS = {"traction unit": 1.09, "multiple unit": 1.09, "freight": 1.06, "passenger": 1.06}
"""TrainRuns.jl's rotating-mass factors when a vehicle gives none (xi_loco, xi_cars; Wende 2003 p. 13)."""
DEFAULT_BRAKING_MS2 = {"freight": 0.225, "passenger": 0.375}
"""TrainRuns.jl's constant braking deceleration when no traction unit gives ``a_braking`` [m/s^2]
(Bruenger and Dahlhaus 2014, p. 74): passenger when any vehicle is a passenger car or multiple unit."""
KINDS = {"traction unit": "locomotive", "multiple unit": "locomotive", "freight": "wagon", "passenger": "wagon"}


def davis_coefficients(vehicle_type: str, base: float = 0.0, rolling: float = 0.0, air: float = 0.0,
                       mass_t: float = 1.0, mass_traction_t: float | None = None) -> tuple[float, float, float]:
    """(a, b, c) of w0 = a + b v + c v^2 [N/kN], v in km/h, equal for every v to TrainRuns.jl's
    resistance of one vehicle of ``vehicle_type`` divided by its weight.

    ``base``, ``rolling``, ``air``: railtoolkit's base_resistance, rolling_resistance and
    air_resistance [per mille]; ``mass_t`` the vehicle's mass and ``mass_traction_t`` the mass on its
    driving axles (traction units; default: all of it). With u = v / v00 and d = dv_air / v00:
    traction unit  w0 = (base m_td + rolling m_tc) / m + air (u + d)^2,
    freight wagon  w0 = base + air u^2,
    passenger car  w0 = base + rolling u + air (u + d)^2.
    """
    d = DV_AIR_KMH / V00_KMH
    c = air / V00_KMH ** 2
    if vehicle_type in ("traction unit", "multiple unit"):
        m_td = mass_t if mass_traction_t is None else mass_traction_t
        a0 = (base * m_td + rolling * (mass_t - m_td)) / mass_t
        return a0 + air * d * d, 2.0 * air * d / V00_KMH, c
    if vehicle_type == "freight":
        return base, 0.0, c
    if vehicle_type == "passenger":
        return base + air * d * d, rolling / V00_KMH + 2.0 * air * d / V00_KMH, c
    raise ValueError(f"unknown vehicle type {vehicle_type!r}")


def _open(path: Path) -> tuple[dict, SourceChecker, str]:
    data, lines = read_yaml(path)
    check = SourceChecker(str(path), lambda loc: _line_for(lines, loc))
    schema = data.get("schema")
    if schema not in (PATH_SCHEMA, STOCK_SCHEMA):
        check.fail(("schema",), f"not a railtoolkit file: schema {schema!r} (expected {PATH_SCHEMA} or {STOCK_SCHEMA})")
    version = data.get("schema_version")
    if version not in SCHEMA_VERSIONS:
        check.fail(("schema_version",), f"unsupported schema version {version!r} (supported: {', '.join(SCHEMA_VERSIONS)}; "
                   "quote it: \"2022.05\")")
    return data, check, schema


class RailtoolkitReader:
    name = "railtoolkit"
    options = frozenset({"cap_kmh", "load_fraction"})
    min_files = 1
    max_files = 50

    def read(self, sources: list[Path], options: ImportOptions) -> Imported:
        files: list[ImportedFile] = []
        licence, copyright_line = None, ""
        for path in sources:
            data, check, schema = _open(path)
            lic, line = licence_near(path)
            licence, copyright_line = licence or lic, copyright_line or line
            if schema == PATH_SCHEMA:
                files += self._paths(path, data, check, options, line)
            else:
                files += self._stock(path, data, check, options, line)
        return Imported(files, licence, "railtoolkit", [])

    # ------------------------------------------------------------------------------------ running paths
    def _paths(self, path: Path, data: dict, check: SourceChecker, options: ImportOptions, copyright_line: str):
        paths = check.get(data, ("paths",), list, "a list of paths")
        check.raise_if_any()
        if not paths:
            check.fail(("paths",), "is empty")
        out = []
        for p, item in enumerate(paths):
            if not isinstance(item, dict):
                check.add(("paths", p), f"expected a path (name, id, characteristic_sections), got {item!r}"[:200])
                continue
            name = check.get(item, ("paths", p, "name"), str, "a name")
            pid = check.identifier(item.get("id"), ("paths", p, "id"), "the path id")
            rows = check.get(item, ("paths", p, "characteristic_sections"), list,
                             "a list of [s_m, v_limit_kmh, f_Rp_permille] rows")
            if rows is None or name is None or pid is None:
                continue
            loc = ("paths", p, "characteristic_sections")
            if len(rows) < 2:
                check.add(loc, "needs at least two rows (a section's start and the path's end)")
                continue
            s, v, f = [], [], []
            for i, row in enumerate(rows):
                if not isinstance(row, list) or len(row) != 3:
                    check.add(loc + (i,), f"expected [s_m, v_limit_kmh, f_Rp_permille], got {row!r}"[:200])
                    s.append(None)
                    continue
                s.append(check.number(row[0], loc + (i, 0), "station s"))
                v.append(check.speed_kmh(row[1], loc + (i, 1)))
                if i < len(rows) - 1:
                    f.append(check.gradient_permille(row[2], loc + (i, 2), what="path resistance f_Rp"))
                else:  # the path's end: its values are unused
                    f.append(check.number(row[2], loc + (i, 2), "path resistance f_Rp"))
            increasing(check, s, lambda i: loc + (i, 0), "stations")
            if check.problems:
                continue
            s0, length = s[0], round(s[-1] - s[0], 3)
            cap = options.cap_kmh
            limits = _merge([(s[i] - s0, s[i + 1] - s0, min(v[i], cap) if cap else v[i]) for i in range(len(s) - 1)])
            grads = _merge([(s[i] - s0, s[i + 1] - s0, f[i]) for i in range(len(s) - 1)])
            relpath = f"{pid}.yaml"
            head = [f"{name}: railtoolkit running path '{pid}'"
                    + (f" (UUID {item['UUID']})" if isinstance(item.get("UUID"), str) else "") + ".",
                    f"Source: {path} (schema {data['schema']}, version {data['schema_version']}).",
                    _licence_line(copyright_line),
                    _command_line(options, "railtoolkit"),
                    "Conversion: characteristic_sections [s_m, v_limit_kmh, f_Rp_permille]: each row starts a section "
                    f"that runs to the next row; the last row (s = {emit.num(s[-1])} m) is the path's end. Positions are "
                    f"metres from the first row (s = {emit.num(s0)} m). f_Rp is the path resistance (gradient plus curve "
                    "resistance) per mille: it is written as the gradient, so the route has no separate curves."]
            if cap:
                head.append(f"Speed limits capped at {emit.num(cap)} km/h (the source's: "
                            f"{emit.num(min(v[:-1]))} to {emit.num(max(v[:-1]))} km/h).")
            text = emit.route_yaml(head, f"{name} (railtoolkit)", length, limits, grads)
            summary = f"{relpath}: {emit.num(length / 1000)} km, {len(limits)} speed-limit, {len(grads)} gradient section(s)"
            out.append(ImportedFile(relpath, "route", text, summary, str(path),
                                    {"speed_limits": path_str(loc), "gradients": path_str(loc), "length_m": path_str(loc)},
                                    {"speed_limits": check.line_of(loc) or 0}))
        check.raise_if_any()
        return out

    # ------------------------------------------------------------------------------------ rolling stock
    def _stock(self, path: Path, data: dict, check: SourceChecker, options: ImportOptions, copyright_line: str):
        vehicles = check.get(data, ("vehicles",), list, "a list of vehicles")
        trains = check.get(data, ("trains",), list, "a list of trains", required=False) or []
        check.raise_if_any()
        if not vehicles:
            check.fail(("vehicles",), "is empty")
        parsed: dict[str, dict[str, Any]] = {}
        out = []
        for i, item in enumerate(vehicles):
            veh = self._vehicle(check, item, i)
            if veh is None:
                continue
            if veh["id"] in parsed:
                check.add(("vehicles", i, "id"), f"vehicle id {veh['id']!r} is given twice (also vehicles[{parsed[veh['id']]['index']}])")
                continue
            parsed[veh["id"]] = veh
        check.raise_if_any()
        for veh in parsed.values():
            out.append(self._vehicle_file(path, data, check, veh, options, copyright_line))
        for t, train in enumerate(trains):
            consist = self._train(check, train, t, parsed, options)
            if consist is not None:
                out.append(self._consist_file(path, data, check, consist, options, copyright_line))
        check.raise_if_any()
        return out

    def _vehicle(self, check: SourceChecker, item: Any, i: int) -> dict | None:
        loc = ("vehicles", i)
        if not isinstance(item, dict):
            check.add(loc, f"expected a vehicle (name, id, vehicle_type, length, mass, ...), got {item!r}"[:200])
            return None
        before = len(check.problems)
        veh: dict[str, Any] = {"index": i, "loc": loc}
        veh["name"] = check.get(item, loc + ("name",), str, "a name")
        veh["id"] = check.identifier(item.get("id"), loc + ("id",), "the vehicle id")
        vtype = check.get(item, loc + ("vehicle_type",), str, "one of: " + ", ".join(KINDS))
        if vtype is not None and vtype not in KINDS:
            check.add(loc + ("vehicle_type",), f"unknown vehicle type {vtype!r} (one of: {', '.join(KINDS)})")
        veh["type"] = vtype

        def positive(key: str, what: str, required: bool, minimum: float = 0.0, strict: bool = True):
            if key not in item:
                if required:
                    check.add(loc + (key,), f"required field is missing ({what})")
                return None
            x = check.number(item[key], loc + (key,), what)
            if x is not None and (x <= minimum if strict else x < minimum):
                check.add(loc + (key,), f"{what} must be {'>' if strict else '>='} {minimum:g} (got {x:g})")
                return None
            return x

        veh["length"] = positive("length", "length [m]", True)
        veh["mass"] = positive("mass", "mass [t]", True)
        veh["load_limit"] = positive("load_limit", "load limit [t]", False, strict=False)
        veh["speed_limit"] = positive("speed_limit", "speed limit [km/h] (locoplan needs each vehicle's top speed)", True)
        veh["rotation_mass"] = positive("rotation_mass", "rotating-mass factor", False, 1.0, strict=False)
        for key in ("base_resistance", "rolling_resistance", "air_resistance"):
            veh[key] = positive(key, f"{key} [per mille]", False, strict=False) or 0.0
        veh["mass_traction"] = positive("mass_traction", "mass on driving axles [t]", False)
        if veh["mass_traction"] is not None and veh["mass"] is not None and veh["mass_traction"] > veh["mass"]:
            check.add(loc + ("mass_traction",), f"mass on driving axles {veh['mass_traction']:g} t exceeds the "
                      f"vehicle's mass {veh['mass']:g} t")
        veh["a_braking"] = None
        if "a_braking" in item:
            a = check.number(item["a_braking"], loc + ("a_braking",), "braking deceleration a_braking [m/s^2]")
            if a is not None and a == 0:
                check.add(loc + ("a_braking",), "braking deceleration must not be 0")
            veh["a_braking"] = None if a is None else abs(a)  # TrainRuns.jl writes it negative
        veh["traction"] = None
        if vtype in ("traction unit", "multiple unit"):
            curve = check.get(item, loc + ("tractive_effort",), list, "a list of [speed_kmh, force_N] pairs "
                              "(a traction unit's tractive effort)")
            if curve is not None:
                veh["traction"] = self._curve(check, curve, loc + ("tractive_effort",))
        if len(check.problems) > before:
            return None
        return veh

    @staticmethod
    def _curve(check: SourceChecker, curve: list, loc: tuple) -> list[tuple[float, float]] | None:
        points: list[tuple[float, float]] = []
        if len(curve) < 2:
            check.add(loc, "needs at least two [speed_kmh, force_N] pairs")
            return None
        for j, pair in enumerate(curve):
            if not isinstance(pair, list) or len(pair) != 2:
                check.add(loc + (j,), f"expected [speed_kmh, force_N], got {pair!r}"[:200])
                return None
            v = check.number(pair[0], loc + (j, 0), "speed")
            f = check.number(pair[1], loc + (j, 1), "tractive effort")
            if v is None or f is None:
                return None
            if v < 0 or f < 0:
                check.add(loc + (j,), f"speed and force must be >= 0 (got [{v:g}, {f:g}])")
                return None
            points.append((v, f / 1000.0))
        increasing(check, [p[0] for p in points], lambda j: loc + (j, 0), "speeds")
        return points

    def _vehicle_file(self, path: Path, data: dict, check: SourceChecker, veh: dict, options: ImportOptions,
                      copyright_line: str) -> ImportedFile:
        vtype, kind = veh["type"], KINDS[veh["type"]]
        coeffs = davis_coefficients(vtype, veh["base_resistance"], veh["rolling_resistance"], veh["air_resistance"],
                                    veh["mass"], veh["mass_traction"])
        rot = veh["rotation_mass"] if veh["rotation_mass"] is not None else DEFAULT_ROTATION_MASS[vtype]
        head = [f"{veh['name']}: railtoolkit vehicle '{veh['id']}' ({vtype}).",
                f"Source: {path} (schema {data['schema']}, version {data['schema_version']}).",
                _licence_line(copyright_line),
                _command_line(options, "railtoolkit"),
                *_resistance_lines(veh, coeffs)]
        if veh["rotation_mass"] is None:
            head.append(f"rotation_mass not given: TrainRuns.jl's default {rot:g} for a {vtype}.")
        traction = brake = None
        load = veh["load_limit"] if kind == "wagon" else None
        if kind == "locomotive":
            traction = veh["traction"]
            brake = [(0.0, 0.0), (veh["speed_limit"], 0.0)]
            head.append("tractive_effort [km/h, N] / 1000 -> traction_kn. railtoolkit gives no brake force: brake_kn is "
                        "zero (no electric brake); the consist's brake_deceleration_ms2 (a_braking) carries all braking.")
            if veh["load_limit"]:
                head.append(f"load_limit {veh['load_limit']:g} t not carried over: a locoplan locomotive carries no load.")
        else:
            head.append("No air-brake data in railtoolkit: braking is the consist's constant deceleration (a_braking).")
        text = emit.vehicle_yaml(head, veh["id"], kind, veh["mass"], veh["length"], veh["speed_limit"], coeffs, rot,
                                 max_load_t=load, traction_kn=traction, brake_kn=brake)
        loc = veh["loc"]
        fields = {"mass_t": path_str(loc + ("mass",)), "length_m": path_str(loc + ("length",)),
                  "max_speed_kmh": path_str(loc + ("speed_limit",)), "max_load_t": path_str(loc + ("load_limit",)),
                  "rotating_mass_factor": path_str(loc + ("rotation_mass",)),
                  "resistance_n_per_kn": path_str(loc) + ".base_resistance/rolling_resistance/air_resistance",
                  "traction_kn": path_str(loc + ("tractive_effort",)), "name": path_str(loc + ("id",))}
        lines = {k: check.line_of(loc + (k2,)) or check.line_of(loc) or 0 for k, k2 in
                 (("mass_t", "mass"), ("length_m", "length"), ("max_speed_kmh", "speed_limit"),
                  ("traction_kn", "tractive_effort"), ("rotating_mass_factor", "rotation_mass"))}
        summary = f"rolling_stock/{veh['id']}.yaml: {kind} '{veh['id']}', {veh['mass']:g} t, {veh['length']:g} m"
        return ImportedFile(f"rolling_stock/{veh['id']}.yaml", "vehicle", text, summary, str(path), fields, lines)

    def _train(self, check: SourceChecker, train: Any, t: int, parsed: dict, options: ImportOptions) -> dict | None:
        loc = ("trains", t)
        if not isinstance(train, dict):
            check.add(loc, f"expected a train (name, id, formation), got {train!r}"[:200])
            return None
        before = len(check.problems)
        name = check.get(train, loc + ("name",), str, "a name")
        tid = check.identifier(train.get("id"), loc + ("id",), "the train id")
        formation = check.get(train, loc + ("formation",), list, "a list of vehicle ids")
        if formation is not None:
            if not formation:
                check.add(loc + ("formation",), "is empty")
            for j, vid in enumerate(formation):
                if vid not in parsed:
                    check.add(loc + ("formation", j), f"vehicle {vid!r} is not among this file's vehicles "
                              f"({', '.join(parsed)})")
            if formation and all(v in parsed for v in formation) and \
                    not any(KINDS[parsed[v]["type"]] == "locomotive" for v in formation):
                check.add(loc + ("formation",), "no traction unit or multiple unit in the formation")
        if len(check.problems) > before:
            return None
        types = [parsed[v]["type"] for v in formation]
        braking = next((parsed[v]["a_braking"] for v in formation if parsed[v]["a_braking"] is not None), None)
        source = "a_braking of the traction unit"
        if braking is None:
            kind = "passenger" if any(x in ("passenger", "multiple unit") for x in types) else "freight"
            braking = DEFAULT_BRAKING_MS2[kind]
            source = f"TrainRuns.jl's default for a {kind} train (no a_braking given)"
        entries = []
        for vid, group in groupby(formation):
            veh = parsed[vid]
            load = (veh["load_limit"] or 0.0) * options.load_fraction if KINDS[veh["type"]] == "wagon" else 0.0
            entries.append((vid, len(list(group)), round(load, 3)))
        return {"name": name, "id": tid, "loc": loc, "entries": entries, "braking": braking, "braking_source": source}

    def _consist_file(self, path: Path, data: dict, check: SourceChecker, c: dict, options: ImportOptions,
                      copyright_line: str) -> ImportedFile:
        share = options.load_fraction
        head = [f"{c['name']}: railtoolkit train '{c['id']}'.",
                f"Source: {path} (schema {data['schema']}, version {data['schema_version']}).",
                _licence_line(copyright_line),
                _command_line(options, "railtoolkit"),
                "formation -> vehicles (consecutive equal vehicles grouped); wagons carry "
                + ("their full load_limit (as TrainRuns.jl does)." if share == 1 else f"{share:g} x their load_limit."),
                f"brake_deceleration_ms2: {c['braking_source']}. TrainRuns.jl decelerates at exactly this rate; "
                "locoplan brakes with the force inertial mass x rate, on top of resistance and gradient."]
        text = emit.consist_yaml(head, c["name"], c["entries"], c["braking"])
        total = sum(n for _, n, _ in c["entries"])
        summary = f"consists/{c['id']}.yaml: '{c['name']}', {total} vehicles"
        fields = {"vehicles": path_str(c["loc"] + ("formation",)), "brake_deceleration_ms2": path_str(c["loc"]),
                  "name": path_str(c["loc"] + ("name",))}
        lines = {"vehicles": check.line_of(c["loc"] + ("formation",)) or 0}
        return ImportedFile(f"consists/{c['id']}.yaml", "consist", text, summary, str(path), fields, lines)


def _merge(rows: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
    """Sections rounded to 1 mm with equal neighbours merged (contiguous by construction)."""
    out: list[list[float]] = []
    for a, b, v in rows:
        a_r, b_r = (out[-1][1] if out else round(a, 3)), round(b, 3)
        if b_r <= a_r:
            continue
        if out and out[-1][2] == v:
            out[-1][1] = b_r
        else:
            out.append([a_r, b_r, v])
    return [tuple(x) for x in out]  # type: ignore[misc]


def _licence_line(copyright_line: str) -> str:
    return ("Licence: ISC (TrainRuns.jl test data)" + (f"; {copyright_line}" if copyright_line else "")
            + "; full text in LICENSE-railtoolkit.txt in the import's output folder.")


def _command_line(options: ImportOptions, fmt: str) -> str:
    return f"Converted by: {options.command}" if options.command else f"Converted by locoplan's {fmt} importer."


def _resistance_lines(veh: dict, coeffs: tuple[float, float, float]) -> list[str]:
    a, b, c = coeffs
    f0, f1, f2 = veh["base_resistance"], veh["rolling_resistance"], veh["air_resistance"]
    vtype = veh["type"]
    if vtype in ("traction unit", "multiple unit"):
        m, mtd = veh["mass"], veh["mass_traction"] if veh["mass_traction"] is not None else veh["mass"]
        formula = [f"Resistance (TrainRuns.jl, traction unit): w0 = (f_Rtd0 m_td + f_Rtc0 m_tc) / m + f_Rt2 ((v + 15) / 100)^2 "
                   f"with f_Rtd0 = base_resistance {f0:g}, f_Rtc0 = rolling_resistance {f1:g}, f_Rt2 = air_resistance {f2:g} "
                   f"per mille, m_td = {mtd:g} t of m = {m:g} t on driving axles, v in km/h."]
    elif vtype == "freight":
        formula = ["Resistance (TrainRuns.jl, freight wagon, Strahl): w0 = f_Rw0 + f_Rw2 (v / 100)^2 "
                   f"with f_Rw0 = base_resistance {f0:g}, f_Rw2 = air_resistance {f2:g} per mille, v in km/h"
                   + (f" (rolling_resistance {f1:g} is not in the freight formula)." if f1 else ".")]
    else:
        formula = ["Resistance (TrainRuns.jl, passenger car, Sauthoff): w0 = f_Rw0 + f_Rw1 v / 100 + f_Rw2 ((v + 15) / 100)^2 "
                   f"with f_Rw0 = base_resistance {f0:g}, f_Rw1 = rolling_resistance {f1:g}, f_Rw2 = air_resistance {f2:g} "
                   "per mille, v in km/h."]
    return formula + [f"Expanded exactly: a = {emit.coef(a)}, b = {emit.coef(b)}, c = {emit.coef(c)} (w0 in N/kN)."]
