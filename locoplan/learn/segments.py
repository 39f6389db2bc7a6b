"""The route split into sections by equivalent gradient (the pattern-curve patent's claims 4-6).

Equivalent gradient (claim 5) = gradient + curve term + tunnel term, with the curve term of claim 6,
``600 Lc / (Rc L_train)`` spread over one train length for a curve shorter than the train (600 / R
over a longer curve's own extent), and the tunnel term ``0.00013 Lt``: ``physics.gradient``'s
point-mass equivalent gradient with the train's length.

Each piece of constant equivalent gradient i is one of five types (claim 4), judged for the train at
the piece's lowest speed limit v (the speed a driver would like to hold there):

- ``steep-up``: the locomotives' full traction cannot accelerate the train: F(v) <= R(v) + M g i;
- ``steep-down``: the locomotives' full (electric) braking cannot decelerate it:
  B_loco(v) + R(v) + M g i <= 0 — claim 4 speaks of the locomotive's braking force; the wagons' air
  brake is only applied in cycles on a long descent, so it does not count here;
- ``level``: |i| <= ``LEVEL_PERMILLE`` (claim 4: "less than a certain value");
- ``gentle-up`` / ``gentle-down``: the other up- / down-grades.

Neighbouring pieces of one type are merged; a section shorter than ``min_length_m`` (default: the
train's length, below which the train never lies on one section alone) is absorbed into the
neighbour whose gradient is closest. A section's gradient is the length-weighted mean of its pieces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.route import Route
from ..model.train import Train
from ..physics.gradient import point_gradient_permille
from ..physics.resistance import train_resistance_kn
from ..physics.traction import gradient_force_kn, max_force_kn

SECTION_TYPES = ("steep-up", "steep-down", "gentle-up", "gentle-down", "level")

LEVEL_PERMILLE = 2.0
"""|equivalent gradient| at or below which a section is level [per mille]. At 2 per mille gravity is
about a loaded freight train's basic resistance at 60-70 km/h (HXD1 + C80: 1.9 N/kN at 65 km/h), so
on such a section coasting neither gains much speed nor loses much more than on the flat."""


@dataclass(frozen=True)
class Section:
    """One section of the route [m], its type, mean equivalent gradient [per mille] and speed limits
    [km/h] (the lowest, and the length-weighted mean, of the route's static limits over it)."""

    index: int
    from_m: float
    to_m: float
    kind: str
    gradient_permille: float
    min_limit_kmh: float
    mean_limit_kmh: float

    @property
    def length_m(self) -> float:
        return self.to_m - self.from_m

    def division_points_m(self, p: int) -> np.ndarray:
        """The p + 1 points that split the section into p equal divisions (both ends included)."""
        return np.linspace(self.from_m, self.to_m, p + 1)


def equivalent_gradient_pieces(route: Route, train_length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Knots [m] and the constant equivalent gradient [per mille] on each piece between them (claims 5-6)."""
    knots = {0.0, float(route.length_m)}
    for sections in (route.gradients, route.curves, route.tunnels):
        for sec in sections:
            knots.update((float(sec.from_m), float(sec.to_m)))
    for c in route.curves:  # a short curve counts over one train length from its start
        knots.add(min(float(c.from_m) + train_length_m, float(route.length_m)))
    x = np.array(sorted(k for k in knots if 0.0 <= k <= route.length_m))
    return x, point_gradient_permille(route, 0.5 * (x[1:] + x[:-1]), train_length_m)


def _limits_over(route: Route, a: float, b: float) -> tuple[float, float]:
    """(lowest, length-weighted mean) static speed limit over [a, b] [km/h]."""
    lo, acc = np.inf, 0.0
    for sl in route.speed_limits:
        overlap = min(b, sl.to_m) - max(a, sl.from_m)
        if overlap > 0:
            lo = min(lo, sl.kmh)
            acc += overlap * sl.kmh
    return float(lo), float(acc / (b - a))


def classify_gradient(train: Train, gradient_permille: float, speed_kmh: float,
                      level_permille: float = LEVEL_PERMILLE) -> str:
    """The claim-4 type of a constant equivalent gradient for ``train`` at ``speed_kmh``."""
    v = min(speed_kmh, train.max_speed_kmh)
    resistance = float(train_resistance_kn(v, train.resistance_kn))
    gravity = float(gradient_force_kn(gradient_permille, train.mass_t))
    traction = float(max_force_kn(v, train.traction_speed_kmh, train.traction_kn))
    brake = float(max_force_kn(v, train.electric_brake_speed_kmh, train.electric_brake_kn))
    if traction - resistance - gravity <= 0:
        return "steep-up"
    if brake + resistance + gravity <= 0:
        return "steep-down"
    if abs(gradient_permille) <= level_permille:
        return "level"
    return "gentle-up" if gradient_permille > 0 else "gentle-down"


def segment_route(route: Route, train: Train, level_permille: float = LEVEL_PERMILLE,
                  min_length_m: float | None = None) -> tuple[Section, ...]:
    """Claims 4-6: the route as sections of one type each (see the module docstring)."""
    min_len = train.length_m if min_length_m is None else float(min_length_m)
    x, grad = equivalent_gradient_pieces(route, train.length_m)
    # [from, to, kind, gradient x length]
    parts: list[list] = []
    for a, b, g in zip(x[:-1], x[1:], grad):
        kind = classify_gradient(train, float(g), _limits_over(route, a, b)[0], level_permille)
        if parts and parts[-1][2] == kind:
            parts[-1][1] = b
            parts[-1][3] += g * (b - a)
        else:
            parts.append([a, b, kind, g * (b - a)])
    # absorb short sections, shortest first, into the neighbour with the closest mean gradient
    while len(parts) > 1:
        lengths = [p[1] - p[0] for p in parts]
        i = int(np.argmin(lengths))
        if lengths[i] >= min_len:
            break
        g_i = parts[i][3] / lengths[i]
        near = [j for j in (i - 1, i + 1) if 0 <= j < len(parts)]
        j = min(near, key=lambda j: abs(parts[j][3] / (parts[j][1] - parts[j][0]) - g_i))
        a, b = min(parts[i][0], parts[j][0]), max(parts[i][1], parts[j][1])
        parts[j] = [a, b, parts[j][2], parts[i][3] + parts[j][3]]
        del parts[i]
        merged: list[list] = []
        for p in parts:  # neighbours of one type join again
            if merged and merged[-1][2] == p[2]:
                merged[-1][1] = p[1]
                merged[-1][3] += p[3]
            else:
                merged.append(p)
        parts = merged
    out = []
    for i, (a, b, kind, gl) in enumerate(parts):
        lo, mean = _limits_over(route, a, b)
        out.append(Section(i, float(a), float(b), kind, float(gl / (b - a)), lo, mean))
    return tuple(out)
