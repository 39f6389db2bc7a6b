"""Stations and kilometre posts in route files: the schema, the posts at any position, a route cut into legs."""

import pytest
import yaml

from locoplan.model.route import Route, format_post, kilometre_post, route_slice


def _route(**extra):
    data = {"schema": "locoplan/route@1", "name": "posts", "length_m": 10000.0,
            "speed_limits": [{"from_m": 0.0, "to_m": 10000.0, "kmh": 80.0}],
            "gradients": [{"from_m": 0.0, "to_m": 10000.0, "permille": 0.0}]}
    data.update(extra)
    return Route.model_validate(data)


def test_a_route_without_chainage_has_no_posts():
    assert kilometre_post(_route(), 500.0) is None


def test_a_single_post_counts_up_with_the_distance():
    r = _route(chainage=12.5)
    assert kilometre_post(r, 0.0) == pytest.approx(12.5, abs=1e-12)
    assert kilometre_post(r, 2345.0) == pytest.approx(14.845, abs=1e-12)


def test_mileage_changes_jump_and_count_down():
    r = _route(chainage=[{"at_m": 0.0, "km": 100.0}, {"at_m": 4000.0, "km": 37.2, "descending": True}])
    posts = kilometre_post(r, [0.0, 3999.0, 4000.0, 9000.0])
    assert list(posts) == pytest.approx([100.0, 103.999, 37.2, 32.2], abs=1e-9)


@pytest.mark.parametrize("km, form, text", [(12.3454, "km", "12.345 km"), (12.3456, "plus", "12+346"),
                                            (0.05, "plus", "0+050"), (7.0, "plus", "7+000")])
def test_posts_as_people_write_them(km, form, text):
    assert format_post(km, form) == text


def test_a_leg_keeps_its_stations_and_posts():
    r = _route(stations=[{"name": "A", "at_m": 0.0}, {"name": "B", "at_m": 6000.0}, {"name": "C", "at_m": 10000.0}],
               chainage=[{"at_m": 0.0, "km": 100.0}, {"at_m": 4000.0, "km": 37.2, "descending": True}])
    leg = route_slice(r, 3000.0, 10000.0, "leg")
    assert [(s.name, s.at_m) for s in leg.stations] == [("B", 3000.0), ("C", 7000.0)]
    for s in (0.0, 500.0, 1000.0, 4000.0, 7000.0):
        assert kilometre_post(leg, s) == pytest.approx(kilometre_post(r, s + 3000.0), abs=1e-9)


@pytest.mark.parametrize("extra, field", [
    ({"stations": [{"name": "A", "at_m": 12000.0}]}, "stations"),
    ({"stations": [{"name": "B", "at_m": 500.0}, {"name": "A", "at_m": 100.0}]}, "stations"),
    ({"chainage": [{"at_m": 100.0, "km": 3.0}]}, "chainage"),
    ({"chainage": [{"at_m": 0.0, "km": 3.0}, {"at_m": 0.0, "km": 5.0}]}, "chainage"),
    ({"chainage": []}, "chainage"),
])
def test_bad_places_are_refused_at_their_field(extra, field, tmp_path, capsys):
    from locoplan.cli import app
    from typer.testing import CliRunner

    data = _route().model_dump(by_alias=True, exclude_none=True) | extra
    path = tmp_path / "route.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2
    assert field in result.output and "Traceback" not in result.output
