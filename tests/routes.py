"""Hand-made routes for the tests (one helper, shared by every test module that builds a line by hand)."""

from locoplan.model.route import Route


def hand_made_route(limits, grades, length=None, schedule=None):
    """A route from limits [(to_m, kmh)] and grades [(to_m, permille)], each contiguous from 0 m;
    ``length`` defaults to the last limit's end [m]; ``schedule`` an optional {run_time_s, tolerance_s}."""
    def sections(items, key):
        out, a = [], 0.0
        for b, val in items:
            out.append({"from_m": a, "to_m": b, key: val})
            a = b
        return out
    length = length or limits[-1][0]
    data = {"schema": "locoplan/route@1", "name": "hand-made", "length_m": length,
            "speed_limits": sections(limits, "kmh"), "gradients": sections(grades, "permille")}
    if schedule is not None:
        data["schedule"] = schedule
    return Route.model_validate(data)
