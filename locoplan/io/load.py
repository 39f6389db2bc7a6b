"""Read route, vehicle and consist files into validated models; every problem names file, line and field."""

from __future__ import annotations

import difflib
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from ..errors import InputError, Problem
from ..model.common import RuleViolations
from ..model.consist import PLAUSIBLE, Consist, Vehicle
from ..model.route import Route
from ..model.train import Train

SCHEMAS: dict[str, type[BaseModel]] = {
    "locoplan/route@1": Route,
    "locoplan/vehicle@1": Vehicle,
    "locoplan/consist@1": Consist,
}

CATALOGUE = resources.files("locoplan") / "catalogue"


def _line_map(node: yaml.Node, path: tuple = (), out: dict | None = None) -> dict[tuple, int]:
    """Map each key path, e.g. ('speed_limits', 2, 'kmh'), to its 1-based line in the YAML text."""
    out = {} if out is None else out
    out.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            sub = path + (key.value,)
            out[sub] = key.start_mark.line + 1
            _line_map(value, sub, out)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            out[path + (i,)] = item.start_mark.line + 1
            _line_map(item, path + (i,), out)
    return out


def _duplicate_keys(node: yaml.Node, name: str, path: tuple = ()) -> list[Problem]:
    """Every key written twice in one mapping (YAML would silently keep the last one)."""
    out: list[Problem] = []
    if isinstance(node, yaml.MappingNode):
        seen: dict = {}
        for key, value in node.value:
            k = key.value
            if k in seen:
                out.append(Problem(name, field_name(path + (k,)),
                                   f"duplicate key: written on line {seen[k]} and again on line {key.start_mark.line + 1} "
                                   "(YAML would silently keep the last; remove one)", key.start_mark.line + 1))
            else:
                seen[k] = key.start_mark.line + 1
            out += _duplicate_keys(value, name, path + (k,))
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            out += _duplicate_keys(item, name, path + (i,))
    return out


def field_name(loc: tuple) -> str:
    """('speed_limits', 2, 'kmh') -> 'speed_limits[2].kmh'."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _line_for(lines: dict[tuple, int], loc: tuple) -> int | None:
    loc = tuple(loc)
    while loc not in lines and loc:
        loc = loc[:-1]
    return lines.get(loc)


def read_text(path: Path) -> str:
    """A file's text (UTF-8); a missing, unreadable file or a folder raises ``InputError``."""
    name = str(path)
    if not path.exists():
        raise InputError(Problem(name, "", "no such file"))
    if path.is_dir():
        raise InputError(Problem(name, "", "is a directory, not a file"))
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(Problem(name, "", f"cannot read: {exc}")) from None


def read_yaml(path: Path) -> tuple[Any, dict[tuple, int]]:
    """Parse a YAML file; missing, unreadable, empty or malformed files raise ``InputError``."""
    name = str(path)
    text = read_text(path)
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark else None
        what = getattr(exc, "problem", None) or str(exc)
        raise InputError(Problem(name, "", f"not valid YAML: {what}", line)) from None
    if node is None or data is None:
        raise InputError(Problem(name, "", "file is empty"))
    duplicates = _duplicate_keys(node, name)
    if duplicates:
        raise InputError(duplicates)
    if not isinstance(data, dict):
        raise InputError(Problem(name, "", f"expected a mapping of keys (schema: ..., name: ...), got {type(data).__name__}", 1))
    return data, _line_map(node)


def _allowed_keys(model: type[BaseModel], loc: tuple) -> list[str]:
    """Keys allowed at ``loc`` (for the 'did you mean' hint on an unknown key)."""
    current: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        fields = getattr(current, "model_fields", {})
        info = next((f for n, f in fields.items() if (f.alias or n) == part), None)
        if info is None:
            return []
        ann = info.annotation
        for arg in getattr(ann, "__args__", ()) or (ann,):
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                current = arg
                break
            for sub in getattr(arg, "__args__", ()):
                if isinstance(sub, type) and issubclass(sub, BaseModel):
                    current = sub
                    break
        else:
            if isinstance(ann, type) and issubclass(ann, BaseModel):
                current = ann
    fields = getattr(current, "model_fields", {})
    return [f.alias or n for n, f in fields.items()]


def _message(model: type[BaseModel], err: dict) -> str:
    kind, loc = err["type"], err["loc"]
    if kind == "extra_forbidden":
        key = str(loc[-1])
        allowed = _allowed_keys(model, tuple(loc))
        stem = key.rsplit("_", 1)[0]
        same_stem = [k for k in allowed if k.rsplit("_", 1)[0] == stem and k != key]
        close = same_stem or difflib.get_close_matches(key, allowed, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        if same_stem:
            hint += " (units live in key names: _m, _kmh, _s, _t, _kn, _permille)"
        return f"unknown key{hint} (allowed: {', '.join(allowed)})"
    if kind == "missing":
        return "required field is missing"
    msg = err["msg"]
    if "input" in err and kind not in ("literal_error",):
        msg += f" (got {err['input']!r})"
    return msg


def validate_data(data: dict, name: str, lines: dict[tuple, int], expect: str | None = None) -> BaseModel:
    """Validate parsed YAML against the schema its ``schema:`` key names (or ``expect``)."""
    schema = data.get("schema")
    if schema not in SCHEMAS:
        known = ", ".join(SCHEMAS)
        raise InputError(Problem(name, "schema", f"unknown or missing schema {schema!r} (one of: {known})",
                                 _line_for(lines, ("schema",))))
    if expect is not None and schema != expect:
        raise InputError(Problem(name, "schema", f"expected a {expect} file, got {schema}", _line_for(lines, ("schema",))))
    return validate_model(SCHEMAS[schema], data, name, lines)


def validate_model(model: type[BaseModel], data: dict, name: str, lines: dict[tuple, int]) -> BaseModel:
    """Validate parsed YAML against ``model``; every problem as file:line: field: message."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = []
        for err in exc.errors():
            violation = (err.get("ctx") or {}).get("error")
            if isinstance(violation, RuleViolations):
                for loc, msg in violation.problems:
                    full = tuple(err["loc"]) + tuple(loc)
                    problems.append(Problem(name, field_name(full), msg, _line_for(lines, full)))
            else:
                loc = tuple(err["loc"])
                problems.append(Problem(name, field_name(loc), _message(model, err), _line_for(lines, loc)))
        raise InputError(problems) from None


def load_file(path: str | Path, expect: str | None = None) -> BaseModel:
    path = Path(path)
    data, lines = read_yaml(path)
    return validate_data(data, str(path), lines, expect)


def load_route(path: str | Path) -> Route:
    return load_file(path, "locoplan/route@1")  # type: ignore[return-value]


def load_vehicle(path: str | Path) -> Vehicle:
    return load_file(path, "locoplan/vehicle@1")  # type: ignore[return-value]


def stock_dirs_for(consist_path: Path, stock_dir: str | Path | None = None) -> list[Path]:
    """Where vehicle types are looked up, in order (SPEC section 1)."""
    dirs = [Path(stock_dir)] if stock_dir else []
    dirs.append(consist_path.parent.parent / "rolling_stock")
    dirs.append(Path(str(CATALOGUE / "rolling_stock")))
    return dirs


def _vehicle_index(directory: Path) -> tuple[dict[str, Path], dict[str, list[Path]]]:
    """Vehicle name -> file in a folder (a file's ``name:`` is authoritative, its stem the fallback),
    and the names that more than one file of the folder declares (ambiguous: which file is meant?)."""
    index: dict[str, Path] = {}
    declared: dict[str, list[Path]] = {}
    if not directory.is_dir():
        return index, {}
    for file in sorted(directory.glob("*.yaml")):
        index.setdefault(file.stem, file)
        try:
            data = yaml.safe_load(file.read_text(encoding="utf-8"))
        except (OSError, yaml.YAMLError, UnicodeDecodeError):
            continue
        if isinstance(data, dict) and isinstance(data.get("name"), str):
            declared.setdefault(data["name"], []).append(file)
    for vehicle, files in declared.items():
        index[vehicle] = files[0]
    return index, {k: v for k, v in declared.items() if len(v) > 1}


def resolve_consist_path(spec: str | Path) -> Path:
    """A consist given as a path, or as a name from ``configs/consists`` / the shipped catalogue."""
    path = Path(spec)
    if path.exists() or path.suffix in (".yaml", ".yml") or "/" in str(spec):
        if not path.exists() and not path.is_absolute():
            shipped = Path(str(CATALOGUE / "consists")) / path.name
            if str(spec) == f"configs/consists/{path.name}" and shipped.exists():
                return shipped  # the default path works from any directory
        return path
    for folder in (Path("configs/consists"), Path(str(CATALOGUE / "consists"))):
        candidate = folder / f"{spec}.yaml"
        if candidate.exists():
            return candidate
    return path


def load_train(consist_spec: str | Path, stock_dir: str | Path | None = None) -> Train:
    """Load a consist, resolve each vehicle type, and build the whole-train quantities."""
    consist, vehicles, _, path, lines = load_consist(consist_spec, stock_dir)
    return build_train(consist, vehicles, str(path), lines)


def load_consist(consist_spec: str | Path, stock_dir: str | Path | None = None):
    """A consist and its vehicles, unbuilt: (Consist, {type: Vehicle}, {type: vehicle file}, consist path,
    line map). For callers that change the consist (e.g. its wagon count or load) before building it."""
    path = resolve_consist_path(consist_spec)
    data, lines = read_yaml(path)
    consist: Consist = validate_data(data, str(path), lines, "locoplan/consist@1")  # type: ignore[assignment]
    dirs = stock_dirs_for(path, stock_dir)
    indexes = [(d, *_vehicle_index(d)) for d in dirs]
    vehicles: dict[str, Vehicle] = {}
    files: dict[str, Path] = {}
    problems: list[Problem] = []
    for i, entry in enumerate(consist.vehicles):
        loc = ("vehicles", i, "type")
        folder = next(((d, idx, dup) for d, idx, dup in indexes if entry.type in idx), None)
        found = None if folder is None else folder[1][entry.type]
        if folder is not None and entry.type in folder[2]:
            both = " and ".join(str(f) for f in folder[2][entry.type])
            problems.append(Problem(str(path), field_name(loc), f"vehicle type '{entry.type}' is ambiguous: {both} "
                                    "both declare this name (rename one)", _line_for(lines, loc)))
            continue
        if found is None:
            looked = ", ".join(str(d) for d in dirs)
            known = sorted({k for _, idx, _ in indexes for k in idx})
            close = difflib.get_close_matches(entry.type, known, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            problems.append(Problem(str(path), field_name(loc), f"unknown vehicle type '{entry.type}'{hint} (looked in {looked})",
                                    _line_for(lines, loc)))
            continue
        vehicle = load_vehicle(found)
        vehicles[entry.type] = vehicle
        files[entry.type] = found
        if vehicle.kind == "locomotive" and entry.load_t:
            loc = ("vehicles", i, "load_t")
            problems.append(Problem(str(path), field_name(loc), "a locomotive carries no load", _line_for(lines, loc)))
        if vehicle.max_load_t is not None and entry.load_t > vehicle.max_load_t:
            loc = ("vehicles", i, "load_t")
            problems.append(Problem(str(path), field_name(loc),
                                    f"{entry.load_t:g} t exceeds {vehicle.name}'s max_load_t {vehicle.max_load_t:g} t",
                                    _line_for(lines, loc)))
    if not problems and not any(v.kind == "locomotive" for v in vehicles.values()):
        problems.append(Problem(str(path), "vehicles", "the consist has no locomotive", _line_for(lines, ("vehicles",))))
    if problems:
        raise InputError(problems)
    return consist, vehicles, files, path, lines


def build_train(consist: Consist, vehicles: dict[str, Vehicle], name: str = "", lines: dict | None = None) -> Train:
    """``Train.from_consist`` with the plausibility bounds on the whole train (mass, length)."""
    problems: list[Problem] = []
    train = Train.from_consist(consist, vehicles)
    where = _line_for(lines or {}, ("vehicles",))
    if train.mass_t > PLAUSIBLE["train_mass_t"]:
        problems.append(Problem(name, "vehicles", f"total mass {train.mass_t:,.0f} t is implausible: the heaviest train "
                                f"ever run weighed 99,734 t (limit {PLAUSIBLE['train_mass_t']:,.0f} t)", where))
    if train.length_m > PLAUSIBLE["train_length_m"]:
        problems.append(Problem(name, "vehicles", f"train length {train.length_m:,.0f} m is implausible: the longest "
                                f"train ever run was 7.35 km (limit {PLAUSIBLE['train_length_m']:,.0f} m)", where))
    if problems:
        raise InputError(problems)
    return train
