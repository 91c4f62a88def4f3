"""The collision scene's support slabs (feasibility/collisions.py) against hand-computed
geometry: a finite support's slab is its whole rectangle (``extent`` about ``point``, sides
along ``x_axis`` and ``n × x_axis``), an infinite plane's the rectangle under the object's
support points."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import yaml

from multiarm_pin.app.scenario import build_scenario
from multiarm_pin.app.scenario.schema import parse_scenario
from multiarm_pin.feasibility import CATEGORIES, CollisionScene
from multiarm_pin.feasibility.collisions import SLAB_THICKNESS
from tests.run_helpers import one_arm_scenario

TABLE_POINT = np.array([0.8, 0.11, 0.14])
"""The table's plane point: the one-arm scenario's box rests on it (bottom face z = 0.14)."""

EXTENT = (2.4, 1.4)
"""A table turned 45° about z (x axis (1, 1, 0)) reaching back over the UR5's base: its
rectangle holds the base's origin 0.64 m from its x sides and 0.21 m from its y sides."""


def _scene(extent: bool):
    ext = f"extent: {list(EXTENT)}, x_axis: [1, 1, 0]," if extent else ""
    text = one_arm_scenario(extra=f"""supports:
  - {{name: table, plane: {{point: {TABLE_POINT.tolist()}, normal: [0, 0, 1]}}, {ext}
     points: [[0.2, 0.15, -0.1], [0.2, -0.15, -0.1], [-0.2, 0.15, -0.1], [-0.2, -0.15, -0.1]]}}
""")
    built = build_scenario(parse_scenario(yaml.safe_load(text), "table.yaml"),
                           load_visuals=False)
    st = built.initial_state
    scene = CollisionScene(built.system, st, 0.0)
    return scene, scene.configuration(st.q, st.obj.position, st.obj.quaternion)


def _slab_corners(scene) -> np.ndarray:
    """(8, 3) the support slab's corners from the scene's coal box and placement."""
    obj = scene.hull.geometryObjects[scene.support_index[0]]
    half = np.asarray(obj.geometry.halfSide)
    M = obj.placement
    return np.array([M.act(np.array(s) * half)
                     for s in itertools.product((-1, 1), repeat=3)])


def _same_corners(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = (np.array(sorted(map(tuple, np.round(x, 9)))) for x in (a, b))
    return np.allclose(a, b, atol=1e-12, rtol=0)


@pytest.mark.parametrize("extent", [True, False])
def test_slab_corners_against_the_support(extent):
    """Finite: the corners are ``point ± lx/2 e_x ± ly/2 e_y`` and those less the thickness
    along ``n``, with ``e_x = (1, 1, 0)/√2``, ``e_y = n × e_x``. Infinite: the box's bottom
    face's rectangle (x 0.6-1.0, y -0.04-0.26 m) and the same below it."""
    scene, _ = _scene(extent)
    n = np.array([0.0, 0.0, 1.0])
    if extent:
        ex = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
        ey = np.cross(n, ex)
        top = [TABLE_POINT + sx * EXTENT[0] / 2 * ex + sy * EXTENT[1] / 2 * ey
               for sx in (-1, 1) for sy in (-1, 1)]
    else:
        top = [np.array([x, y, TABLE_POINT[2]]) for x in (0.6, 1.0) for y in (-0.04, 0.26)]
    want = np.array(top + [p - SLAB_THICKNESS * n for p in top])
    assert _same_corners(_slab_corners(scene), want)


def test_a_link_over_the_table_beyond_the_box_collides():
    """The UR5's shoulder is inside the turned table's rectangle, 0.2-0.6 m beside the box's
    footprint: with the extent it penetrates the table's slab by centimetres (it is 4 cm
    into it); the same table without an extent (a stand under the box's support points)
    leaves every link more than 1 cm clear of it."""
    support = CATEGORIES.index("arm_support")
    scene, q = _scene(extent=True)
    hits = [c for c in scene.collisions(q) if c.category == "arm_support"]
    assert any(c.link == "shoulder_link" and c.other == "table" and c.distance < -0.02
               for c in hits), [c.describe() for c in hits]
    scene, q = _scene(extent=False)
    assert not [c for c in scene.collisions(q) if c.category == "arm_support"]
    d = scene.hull_distances(q)
    assert d[scene.category == support].min() > 0.01
