"""Tests of the replay's visual meshes: geometry, material colours and their precedence."""

from __future__ import annotations

import struct
import warnings
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

import coal
import example_robot_data as erd
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import cKDTree

from multiarm_pin.app.replay_meshes import mesh_object, read_collada_parts, visual_mesh

MP6 = Path(__file__).resolve().parents[1] / "robots" / "mp6" / "mp6.urdf"
NS = {"c": "http://www.collada.org/2005/11/COLLADASchema"}


@pytest.fixture(scope="module")
def ur5_visuals() -> pin.GeometryModel:
    return erd.load("ur5").visual_model


def _floats(element) -> np.ndarray:
    return np.array(element.text.split(), dtype=float)


def _dae_triangles(path: str) -> tuple[np.ndarray, list[tuple]]:
    """((T, 3, 3) triangle corners [m], T diffuse RGBAs rounded to 1e-6), from the XML alone.

    Follows <triangles material=symbol> -> <instance_material symbol target> -> <material>
    -> <instance_effect> -> <effect> <diffuse><color>, reads the corners through the
    VERTEX input's offset into <p> and applies the instancing node's <matrix>. Only what
    the UR5's files use: <triangles> (no polylists) in nodes directly under the scene.
    """
    root = ET.parse(path).getroot()
    diffuse = {e.get("id"): tuple(round(x, 6) for x in _floats(e.find(".//c:diffuse/c:color",
                                                                      NS)))
               for e in root.iterfind(".//c:library_effects/c:effect", NS)}
    material_effect = {m.get("id"): m.find("c:instance_effect", NS).get("url")[1:]
                       for m in root.iterfind(".//c:library_materials/c:material", NS)}
    sources = {e.get("id"): e for e in root.iter(f"{{{NS['c']}}}source")}
    vertices = {e.get("id"): e for e in root.iter(f"{{{NS['c']}}}vertices")}
    geometries = {g.get("id"): g for g in root.iterfind(".//c:library_geometries/c:geometry", NS)}
    assert not root.findall(".//c:polylist", NS) and not root.findall(".//c:polygons", NS)
    corners, colours = [], []
    for node in root.iterfind(".//c:visual_scene/c:node", NS):
        T = _floats(node.find("c:matrix", NS)).reshape(4, 4)
        for inst in node.iterfind("c:instance_geometry", NS):
            bind = {m.get("symbol"): m.get("target")[1:]
                    for m in inst.iterfind(".//c:instance_material", NS)}
            for tris in geometries[inst.get("url")[1:]].iterfind(".//c:triangles", NS):
                inputs = tris.findall("c:input", NS)
                stride = 1 + max(int(i.get("offset")) for i in inputs)
                vin = next(i for i in inputs if i.get("semantic") == "VERTEX")
                pos_input = vertices[vin.get("source")[1:]].find("c:input", NS)
                pos = _floats(sources[pos_input.get("source")[1:]].find("c:float_array", NS))
                pos = pos.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
                p = _floats(tris.find("c:p", NS)).astype(int).reshape(-1, stride)
                corners.append(pos[p[:, int(vin.get("offset"))].reshape(-1, 3)])
                colours += [diffuse[material_effect[bind[tris.get("material")]]]] * \
                    int(tris.get("count"))
    return np.vstack(corners), colours


def _faces_and_colours(mesh) -> Counter:
    """Counter of (sorted vertex ids, RGBA rounded to 1e-6) over the mesh's faces."""
    group = np.repeat(np.arange(len(mesh.colors)), mesh.counts)
    return Counter((tuple(sorted(f)), tuple(round(c, 6) for c in mesh.colors[k]))
                   for f, k in zip(mesh.faces.tolist(), group, strict=True))


def test_ur5_meshes_are_their_dae_triangles_in_their_material_colours(ur5_visuals):
    cache = {}
    arm_colours = set()
    for g in ur5_visuals.geometryObjects:
        assert g.meshPath.endswith(".dae") and not g.overrideMaterial
        mesh = visual_mesh(g, None, cache)
        corners, colours = _dae_triangles(g.meshPath)
        # Corners matched to the mesh's distinct float32 vertices: float32 rounding is
        # < 1e-8 m here and distinct vertices are > 1e-7 m apart.
        dist, ids = cKDTree(mesh.vertices.astype(float)).query(corners.reshape(-1, 3))
        assert dist.max() < 2e-8, g.name
        expected = Counter((tuple(sorted(t)), c)
                           for t, c in zip(ids.reshape(-1, 3).tolist(), colours, strict=True))
        # each triangle of the file, once, in its material's colour
        assert _faces_and_colours(mesh) == expected, g.meshPath
        assert len(mesh.colors) >= 2 and len(mesh.colors) == len(set(colours)), g.name
        assert sum(mesh.counts) == len(mesh.faces)
        assert list(mesh.starts) == list(np.cumsum((0,) + mesh.counts[:-1]))
        arm_colours |= set(colours)
    # dark joints, grey tubes and the blue caps ("blau", 0.3136 0.4344 0.512 in shoulder.dae)
    assert len(arm_colours) >= 5
    assert (0.3136, 0.4344, 0.512, 1.0) in arm_colours
    assert all(np.allclose(g.meshColor, [0.9, 0.9, 0.9, 1.0]) for g in ur5_visuals.geometryObjects)


def test_ur5_mesh_vertices_are_the_ones_coal_loaded(ur5_visuals):
    # The drawn points are coal's, to float32 parsing (assimp's differs from pycollada's by
    # up to ~1e-10 m). Coal's triangles are not all the file's: for 6829 of the UR5's
    # ~95700 faces (base 137, shoulder 136, upper arm 272, wrists 2924 + 2924 + 436,
    # measured with coal 3) its loader joins other vertices than the file's <p> names,
    # which drew ragged wrists in the grey replay; the test above checks the drawn faces
    # against the file.
    n_differ, n_faces = 0, 0
    for g in ur5_visuals.geometryObjects:
        mesh = visual_mesh(g, None, {})
        bvh = g.geometry
        coal_faces = np.array([[bvh.tri_indices(k)[i] for i in range(3)]
                               for k in range(bvh.num_tris)])
        cv = np.asarray(bvh.vertices(), dtype=float)
        mv = mesh.vertices.astype(float)
        dist, to_mesh = cKDTree(mv).query(cv)
        assert dist[np.unique(coal_faces)].max() < 1e-8, g.name
        assert cKDTree(cv).query(mv)[0].max() < 1e-8, g.name
        coal_tris = Counter(tuple(sorted(t)) for t in to_mesh[coal_faces].tolist())
        n_faces += bvh.num_tris
        n_differ += sum((coal_tris - Counter(tuple(sorted(f)) for f in mesh.faces.tolist()))
                        .values())
    assert n_differ < 0.1 * n_faces, (n_differ, n_faces)


def test_panda_meshes_are_coloured():
    cache = {}
    colours = set()
    for g in erd.load("panda").visual_model.geometryObjects:
        colours |= set(visual_mesh(g, None, cache).colors)
    assert len(colours) >= 3
    assert (1.0, 1.0, 1.0, 1.0) in colours  # the white shells


def _urdf_with_mesh(tmp_path: Path, mesh: str, material: str) -> Path:
    urdf = tmp_path / "one_link.urdf"
    urdf.write_text(f"""<robot name="one">
  <link name="base"><visual><geometry><mesh filename="{mesh}"/></geometry>{material}</visual>
  </link></robot>""")
    return urdf


def test_a_urdf_material_overrides_the_file_colours(tmp_path, ur5_visuals):
    shoulder = ur5_visuals.geometryObjects[ur5_visuals.getGeometryId("shoulder_link_0")]
    red = '<material name="red"><color rgba="0.8 0.1 0.1 1"/></material>'
    urdf = _urdf_with_mesh(tmp_path, shoulder.meshPath, red)
    model = pin.buildModelFromUrdf(str(urdf))
    g = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.VISUAL).geometryObjects[0]
    assert g.overrideMaterial  # what Pinocchio's URDF parser says when a material is given
    mesh = visual_mesh(g, None, {})
    assert mesh.colors == (pytest.approx((0.8, 0.1, 0.1, 1.0)),)
    assert mesh.counts == (len(mesh.faces),) == (g.geometry.num_tris,)
    # Without the URDF material, the same file is drawn in its own three colours.
    urdf = _urdf_with_mesh(tmp_path, shoulder.meshPath, "")
    g = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.VISUAL).geometryObjects[0]
    assert not g.overrideMaterial
    assert len(visual_mesh(g, None, {}).colors) == 3


def test_an_explicit_colour_overrides_everything(ur5_visuals):
    g = ur5_visuals.geometryObjects[0]
    mesh = visual_mesh(g, (0.2, 0.6, 1.0, 0.5), {})
    assert mesh.colors == ((0.2, 0.6, 1.0, 0.5),)
    lowered = mesh_object(mesh).lower()
    assert lowered["object"]["material"] == lowered["materials"][0]["uuid"]
    assert lowered["materials"][0]["color"] == 0x3399FF and lowered["materials"][0]["transparent"]


def _write_stl(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A binary STL: 80-byte header, uint32 count, then (normal, 3 vertices, attr) per face."""
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(faces)))
        for tri in faces:
            f.write(struct.pack("<12fH", 0, 0, 0, *vertices[tri].ravel(), 0))


TET_VERTICES = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
TET_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _geometry(path: Path, color=(0.9, 0.9, 0.9, 1.0), scale=(1.0, 1.0, 1.0),
              geometry_file: Path | None = None) -> pin.GeometryObject:
    bvh = coal.MeshLoader().load(str(geometry_file or path), np.array(scale))
    return pin.GeometryObject("g", 0, 0, pin.SE3.Identity(), bvh, str(path),
                              np.array(scale), False, np.array(color))


def test_an_stl_mesh_keeps_its_mesh_color(tmp_path):
    stl = tmp_path / "tet.stl"
    _write_stl(stl, TET_VERTICES, TET_FACES)
    mesh = visual_mesh(_geometry(stl, color=(0.2, 0.3, 0.4, 1.0), scale=(2, 2, 2)), None, {})
    assert mesh.colors == ((0.2, 0.3, 0.4, 1.0),) and mesh.counts == (4,)
    np.testing.assert_allclose(np.sort(mesh.vertices, axis=0), np.sort(2 * TET_VERTICES, axis=0))


def test_the_urdf_mesh_scale_is_applied_once(tmp_path):
    # Pinocchio's URDF parser loads coal's BVH already scaled; the replay used to scale it
    # a second time (a mesh in millimetres with scale 0.001 would have shrunk to microns).
    stl, dae = tmp_path / "tet.stl", tmp_path / "tet.dae"
    _write_stl(stl, TET_VERTICES, TET_FACES)
    dae.write_text(_dae())
    for path in (stl, dae):
        urdf = tmp_path / "scaled.urdf"
        urdf.write_text(f"""<robot name="one"><link name="base"><visual><geometry>
          <mesh filename="{path}" scale="2 2 0.5"/></geometry></visual></link></robot>""")
        model = pin.buildModelFromUrdf(str(urdf))
        g = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.VISUAL).geometryObjects[0]
        np.testing.assert_allclose(g.meshScale, [2, 2, 0.5])
        mesh = visual_mesh(g, None, {})
        np.testing.assert_allclose(mesh.vertices.max(axis=0), [2.0, 4.0, 1.5], err_msg=path.name)


def test_a_primitive_is_left_to_pinocchio():
    model, visual = pin.buildModelsFromUrdf(str(MP6), str(MP6.parent),
                                            geometry_types=pin.GeometryType.VISUAL)
    cylinder = visual.geometryObjects[0]
    assert isinstance(cylinder.geometry, coal.Cylinder)
    assert visual_mesh(cylinder, None, {}) is None


def _dae(matrix: str = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", blue_target: str = "#blue-mat") -> str:
    """A tetrahedron: one red <triangles> face and a blue <polylist> of three faces."""
    return f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>
  <library_effects>
    <effect id="red-fx"><profile_COMMON><technique sid="common"><lambert>
      <diffuse><color sid="diffuse">0.8 0.1 0.1 1</color></diffuse>
    </lambert></technique></profile_COMMON></effect>
    <effect id="blue-fx"><profile_COMMON><technique sid="common"><phong>
      <diffuse><color sid="diffuse">0.1 0.2 0.9 0.5</color></diffuse>
    </phong></technique></profile_COMMON></effect>
  </library_effects>
  <library_materials>
    <material id="red-mat"><instance_effect url="#red-fx"/></material>
    <material id="blue-mat"><instance_effect url="#blue-fx"/></material>
  </library_materials>
  <library_geometries><geometry id="tet"><mesh>
    <source id="tet-pos">
      <float_array id="tet-pos-a" count="12">0 0 0 1 0 0 0 2 0 0 0 3</float_array>
      <technique_common><accessor source="#tet-pos-a" count="4" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
      </accessor></technique_common></source>
    <vertices id="tet-v"><input semantic="POSITION" source="#tet-pos"/></vertices>
    <triangles material="m0" count="1"><input semantic="VERTEX" source="#tet-v" offset="0"/>
      <p>0 2 1</p></triangles>
    <polylist material="m1" count="3"><input semantic="VERTEX" source="#tet-v" offset="0"/>
      <vcount>3 3 3</vcount><p>0 1 3 0 3 2 1 2 3</p></polylist>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n"><matrix>{matrix}</matrix>
    <instance_geometry url="#tet"><bind_material><technique_common>
      <instance_material symbol="m0" target="#red-mat"/>
      <instance_material symbol="m1" target="{blue_target}"/>
    </technique_common></bind_material></instance_geometry></node></visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>"""


def test_collada_triangles_and_polylists_are_grouped_by_colour(tmp_path):
    dae = tmp_path / "tet.dae"
    dae.write_text(_dae(matrix="1 0 0 0.5 0 1 0 0 0 0 1 0 0 0 0 1"))  # node moved 0.5 m in x
    parts = read_collada_parts(dae)
    assert [len(f) for _, f, _ in parts] == [1, 3]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh = visual_mesh(_geometry(dae, scale=(1.0, 1.0, 2.0)), None, {})
    assert mesh.colors == ((0.8, 0.1, 0.1, 1.0), (0.1, 0.2, 0.9, 0.5))
    assert mesh.counts == (1, 3) and mesh.starts == (0, 1)
    expected = (TET_VERTICES + [0.5, 0, 0]) * [1, 1, 2]
    np.testing.assert_allclose(np.sort(mesh.vertices, axis=0), np.sort(expected, axis=0))
    red = mesh.vertices[mesh.faces[0]]
    np.testing.assert_allclose(red, expected[[0, 2, 1]])  # winding kept
    lowered = mesh_object(mesh).lower()
    geometry = lowered["geometries"][0]
    assert geometry["data"]["groups"] == [{"start": 0, "count": 3, "materialIndex": 0},
                                          {"start": 3, "count": 9, "materialIndex": 1}]
    assert geometry["data"]["index"]["type"] == "Uint16Array"
    assert lowered["object"]["material"] == [m["uuid"] for m in lowered["materials"]]
    assert [m["color"] for m in lowered["materials"]] == [0xCC1A1A, 0x1A33E6]
    assert [m["transparent"] for m in lowered["materials"]] == [False, True]


def test_an_unreadable_or_mismatched_collada_file_falls_back_to_mesh_color(tmp_path):
    broken = tmp_path / "broken.dae"
    broken.write_text(_dae(blue_target="#no-such-material"))
    with pytest.warns(UserWarning, match=r"broken\.dae: cannot read its COLLADA materials"):
        mesh = visual_mesh(_geometry(broken, color=(0.3, 0.3, 0.3, 1.0)), None, {})
    assert mesh.colors == ((0.3, 0.3, 0.3, 1.0),) and mesh.counts == (4,)
    # The file read for the colours is not the geometry coal holds: drawn as coal's.
    moved, plain = tmp_path / "moved.dae", tmp_path / "plain.dae"
    moved.write_text(_dae(matrix="1 0 0 0.5 0 1 0 0 0 0 1 0 0 0 0 1"))
    plain.write_text(_dae())
    with pytest.warns(UserWarning, match=r"moved\.dae: the COLLADA geometry .* bounding box"):
        mesh = visual_mesh(_geometry(moved, geometry_file=plain), None, {})
    assert mesh.colors == ((0.9, 0.9, 0.9, 1.0),)
    np.testing.assert_allclose(mesh.vertices.min(axis=0), [0, 0, 0])


def test_unique_rows_is_numpys_unique_of_rows():
    from multiarm_pin.app.replay_meshes import unique_rows

    rng = np.random.default_rng(5)
    # few distinct values per column: many duplicate rows and ties on x and on (x, y)
    a = rng.integers(-3, 4, size=(5000, 3)).astype(np.float32) * np.float32(0.37)
    a[1::2] = a[::2]  # every row twice
    unique, inverse = unique_rows(a)
    ref_unique, ref_inverse = np.unique(a, axis=0, return_inverse=True)
    np.testing.assert_array_equal(unique, ref_unique)
    np.testing.assert_array_equal(inverse, ref_inverse.reshape(-1))
    np.testing.assert_array_equal(unique[inverse], a)
    one, idx = unique_rows(np.ones((1, 3), dtype=np.float32))
    assert one.shape == (1, 3) and list(idx) == [0]
