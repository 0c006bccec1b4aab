"""Maps: metres <-> pixels round-trip, obstacles drawn to scale, the old top-down API still works."""

from __future__ import annotations

import math

import numpy as np
import pytest

from orbitdata.scenario.spec import Obstacle, Scenario
from orbitdata.viz.topdown import BG, GRID, PlaneMap, paired_views


def _scenario(*obstacles):
    return Scenario(obstacles=tuple(obstacles), goal=(10.0, 1.0, -2.0))


def _path():
    s = np.linspace(0, 1, 50)[:, None]
    return s * np.array([10.0, 1.0, -2.0]) + np.sin(np.pi * s) * np.array([0.0, 1.5, 0.8])  # (50, 3) metres


@pytest.mark.parametrize("axes", [(0, 1), (0, 2)])
def test_pixels_round_trip_to_metres(axes):
    path = _path()
    view = PlaneMap(_scenario(), (300, 180), path, axes=axes)
    px = view.polyline(path)
    assert (px >= 0).all() and (px[:, 0] < 300).all() and (px[:, 1] < 180).all()
    back = view.world(px)
    assert np.abs(back - path[:, list(axes)]).max() <= 0.5 / view.scale * math.sqrt(2) + 1e-9
    # up is up: a higher point is drawn on a smaller row
    assert view.px((0, 0, 0))[1] > view.px((0, 1, 1))[1]


def _colour(img, view, point):
    u, v = view.px(point)
    return tuple(int(c) for c in img[v, u])


def test_a_sphere_is_drawn_to_scale():
    grey = (0.5, 0.5, 0.5, 1.0)
    view = PlaneMap(_scenario(Obstacle("sphere", (5.0, 0.0, 0.0), (1.0, 0, 0), rgba=grey)), (400, 400))
    img = view.background()
    assert _colour(img, view, (5.0, 0.0)) == (127, 127, 127)
    assert _colour(img, view, (5.85, 0.0)) == (127, 127, 127)
    assert _colour(img, view, (6.2, 0.3)) in (BG, GRID)


def test_a_capsule_is_its_hull_not_an_ellipsoid():
    # radius 0.5, half-length 1, lying along world x (local z -> world x)
    q = (math.cos(math.pi / 4), 0.0, math.sin(math.pi / 4), 0.0)
    view = PlaneMap(
        _scenario(Obstacle("capsule", (5.0, 0.0, 0.0), (0.5, 1.0, 0.0), quat=q, rgba=(1, 1, 1, 1))), (400, 400)
    )
    img = view.background()
    assert _colour(img, view, (6.2, 0.4)) == (255, 255, 255)  # inside the capsule, outside an ellipsoid fit
    assert _colour(img, view, (6.7, 0.0)) in (BG, GRID)


def test_top_and_side_share_one_scale():
    top, side = paired_views(_scenario(), (300, 200), (300, 120), _path())
    assert top.scale == side.scale
    assert top.axis_names == ("x", "y") and side.axis_names == ("x", "z")


def test_too_small_a_map_is_refused():
    with pytest.raises(ValueError, match="too small"):
        PlaneMap(_scenario(), (4, 100))
