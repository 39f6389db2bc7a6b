"""Equivalent (additional-resistance-inclusive) gradient along a route [per mille = N/kN].

Equivalent gradient = gradient + curve term + tunnel term (TB/T 1407; the pattern-curve patent's claims 5-6):
curve 600 / R, tunnel 0.00013 * L_tunnel. For a curve shorter than the train, the pattern-curve patent's claim 6
spreads it over the train: 600 * Lc / (Rc * L_train).
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np


class Track(Protocol):
    """What the gradient functions read of a line (``model.route.Route`` is one): its length and its
    gradient, curve and tunnel sections, each with ``from_m`` / ``to_m`` and ``permille`` (gradients) or
    ``radius_m`` (curves)."""

    length_m: float
    gradients: Sequence
    curves: Sequence
    tunnels: Sequence


def curve_gradient_permille(radius_m, curve_length_m=None, train_length_m=None):
    """Curve additional resistance [N/kN]: 600 / R, or 600 Lc / (R L_train) when the curve is shorter
    than the train (the pattern-curve patent's claim 6, eq. IV)."""
    r = np.asarray(radius_m, dtype=float)
    if curve_length_m is None or train_length_m is None:
        return 600.0 / r
    share = np.minimum(1.0, np.asarray(curve_length_m, float) / float(train_length_m))
    return 600.0 * share / r


def tunnel_gradient_permille(tunnel_length_m):
    """Tunnel additional resistance [N/kN] = 0.00013 * tunnel length [m] (the pattern-curve patent's claim 6, eq. V)."""
    return 0.00013 * np.asarray(tunnel_length_m, dtype=float)


def _step_function(edges_from, edges_to, values, s_m):
    """Sum of box functions value_k on [from_k, to_k) evaluated at positions s_m."""
    s = np.asarray(s_m, dtype=float)
    out = np.zeros_like(s)
    for a, b, val in zip(edges_from, edges_to, values):
        out += np.where((s >= a) & (s < b), val, 0.0)
    return out


def point_gradient_permille(route: Track, s_m, train_length_m: float | None = None):
    """Equivalent gradient at the train's head position ``s_m`` for a point-mass train [per mille].

    A curve longer than the train counts 600/R over its own extent; a shorter one counts
    600 Lc / (R L_train) while the head runs one train length from the curve's start (the pattern-curve patent's
    claim 6). Both give the same work as the train passing the curve. ``train_length_m=None`` uses
    600/R over each curve's own extent.
    """
    s = np.asarray(s_m, dtype=float)
    g = route.gradients
    starts = np.array([x.from_m for x in g])
    idx = np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(g) - 1)
    total = np.array([x.permille for x in g])[idx]
    for c in route.curves:
        lc = c.to_m - c.from_m
        if train_length_m is not None and lc < train_length_m:
            total = total + _step_function([c.from_m], [c.from_m + train_length_m],
                                           [curve_gradient_permille(c.radius_m, lc, train_length_m)], s)
        else:
            total = total + _step_function([c.from_m], [c.to_m], [curve_gradient_permille(c.radius_m)], s)
    for t in route.tunnels:
        total = total + _step_function([t.from_m], [t.to_m], [tunnel_gradient_permille(t.to_m - t.from_m)], s)
    return total


def point_gradient_knots(route: Track) -> tuple[np.ndarray, np.ndarray]:
    """The point-mass equivalent gradient (curves at 600/R over their own extent) as a step function:
    knots [m] (every section boundary) and the value on each piece between them [per mille]."""
    knots = {0.0, float(route.length_m)}
    for sections in (route.gradients, route.curves, route.tunnels):
        for sec in sections:
            knots.update((float(sec.from_m), float(sec.to_m)))
    x = np.array(sorted(k for k in knots if 0.0 <= k <= route.length_m))
    return x, point_gradient_permille(route, 0.5 * (x[1:] + x[:-1]))


def strip_gradient_permille(route: Track, s_m, train_length_m: float):
    """Equivalent gradient averaged over the train's body [s - L, s] (train as a uniform strip) [per mille].

    A 650 m train on a 600 m curve is not a point: this is the mean of the point-mass equivalent
    gradient (curves at 600/R over their extent) under the train (:func:`mean_gradient_permille`).
    """
    s = np.asarray(s_m, dtype=float)
    return mean_gradient_permille(route, s - train_length_m, s)


def mean_gradient_permille(route: Track, from_m, to_m):
    """Mean of the point-mass equivalent gradient (curves at 600/R over their extent) over [from_m, to_m]
    [per mille] (arrays of equal shape, to_m > from_m): computed exactly from the running integral of the
    step function (piecewise linear between its knots). Before the start the first piece's value is
    assumed (the train stands in the station), beyond the end the last piece's. The strip train's gradient
    is this over its body; one vehicle's is this over its own length (``physics.couplers``)."""
    a = np.asarray(from_m, dtype=float)
    b = np.asarray(to_m, dtype=float)
    x, val = point_gradient_knots(route)
    cum = np.concatenate([[0.0], np.cumsum(val * np.diff(x))])
    pad = float(max(np.max(b - a, initial=0.0), np.max(-a, initial=0.0), np.max(b - x[-1], initial=0.0))) + 1.0
    xs = np.concatenate([[x[0] - pad], x, [x[-1] + pad]])
    cs = np.concatenate([[-val[0] * pad], cum, [cum[-1] + val[-1] * pad]])
    return (np.interp(b, xs, cs) - np.interp(a, xs, cs)) / (b - a)


def equivalent_gradient_permille(route: Track, s_m, train_length_m: float, strip: bool = False):
    """Equivalent gradient along the route at head positions ``s_m`` [per mille]."""
    if strip:
        return strip_gradient_permille(route, s_m, train_length_m)
    return point_gradient_permille(route, s_m, train_length_m)
