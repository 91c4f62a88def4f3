"""The arms' visual meshes as compact Meshcat objects, coloured by their materials.

A mesh geometry (a :class:`coal.BVHModelBase` in a Pinocchio ``GeometryObject``) is sent to
the viewer as binary arrays rather than as its mesh file's text (COLLADA's text is several
times larger). Coal's BVH is one merged triangle soup
without materials, so the colours come from elsewhere, in this order of precedence:

1. an explicit colour (``ReplayArm.color``) paints the whole geometry;
2. a URDF ``<material>`` (Pinocchio's URDF parser then sets ``overrideMaterial`` and
   ``meshColor``) paints the whole geometry;
3. a COLLADA (``.dae``) file's own materials: each triangle group (``<triangles>``,
   ``<polylist>``, ``<polygons>``) takes its material's diffuse colour, read with
   pycollada (its alpha is the opacity; COLLADA's ``<transparency>``, whose meaning
   exporters disagree on, is ignored); the geometry is then the file's as pycollada
   reads it (node transforms applied, ``meshScale`` applied), after checking that its
   bounding box is coal's, so the drawn mesh sits where Pinocchio's does. (The points
   are coal's; the triangles are the file's ``<p>`` lists: coal's loader joins other
   vertices for about 7 % of the UR5's faces, which showed as ragged wrists.)
4. otherwise (STL, OBJ, a COLLADA file that cannot be read, a textured material), the
   geometry's ``meshColor`` (Pinocchio's default light grey when the URDF names none).

The triangles of one colour are contiguous in the index buffer and drawn as one three.js
geometry group with its own ``MeshLambertMaterial`` (one buffer, several materials), so
the page holds each vertex once. Vertices are in the geometry's frame, ``meshScale``
applied [m]. COLLADA's ``<unit>`` and ``<up_axis>`` are ignored, as coal ignores them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import meshcat.geometry as mg
import numpy as np
import umsgpack

from multiarm_pin.exceptions import InputError

RGBA = tuple[float, float, float, float]

EXTENT_RTOL = 1e-5
"""Relative tolerance on the bounding box (of its diagonal) when a COLLADA file's geometry
is compared with coal's: beyond it the file's materials are not used."""


@dataclass(frozen=True)
class VisualMesh:
    """A triangle mesh whose faces are sorted into colour groups.

    Attributes:
        vertices: (V, 3) float32 vertex positions in the geometry frame, scale applied [m].
        faces: (F, 3) uint32 vertex indices, in the mesh file's winding (the materials
            are double-sided); the faces of group ``k`` are rows
            ``starts[k] : starts[k] + counts[k]``.
        starts: first face of each group.
        counts: number of faces of each group (all positive, summing to F).
        colors: RGBA in [0, 1] of each group, all different.
    """

    vertices: np.ndarray
    faces: np.ndarray
    starts: tuple[int, ...]
    counts: tuple[int, ...]
    colors: tuple[RGBA, ...]


def _rgba(values) -> RGBA:
    r, g, b, a = (float(c) for c in values)
    return (r, g, b, a)


def _bvh(geometry_object):
    """Coal's BVH triangle mesh of the geometry, or None (primitive, octree, no triangle)."""
    try:
        import coal
    except ImportError:  # pragma: no cover - pinocchio wheels ship coal
        return None
    geom = geometry_object.geometry
    if not isinstance(geom, coal.BVHModelBase) or geom.num_tris == 0:
        return None
    return geom


def _bvh_vertices(bvh) -> np.ndarray:
    """(V, 3) float32 vertices [m] of coal's BVH, in the geometry frame.

    Pinocchio loads the BVH with ``meshScale`` already applied (its URDF parser calls
    coal's ``MeshLoader.load(path, scale)``), so they are used as they are.
    """
    return np.asarray(bvh.vertices(), dtype=np.float32)


def _bvh_faces(bvh) -> np.ndarray:
    """(F, 3) uint32 vertex indices of coal's BVH triangles (a Python loop over the triangles)."""
    faces = np.empty((bvh.num_tris, 3), dtype=np.uint32)
    for k in range(bvh.num_tris):
        tri = bvh.tri_indices(k)
        faces[k] = (tri[0], tri[1], tri[2])
    return faces


def _diffuse(material) -> RGBA | None:
    """A pycollada material's diffuse RGBA, or None (no material, a texture, no colour)."""
    if material is None or getattr(material, "effect", None) is None:
        return None
    diffuse = material.effect.diffuse
    if not isinstance(diffuse, tuple | list) or len(diffuse) not in (3, 4):
        return None  # a texture map (collada.material.Map) or nothing
    rgba = np.clip(np.array(list(diffuse) + [1.0] * (4 - len(diffuse)), dtype=float), 0, 1)
    return _rgba(rgba)


def read_collada_parts(path) -> list[tuple[np.ndarray, np.ndarray, RGBA | None]]:
    """The triangle groups of a COLLADA file's scene, with their diffuse colours.

    Args:
        path: the ``.dae`` file.

    Returns:
        One ``(vertices (n, 3) float [m, file units], faces (m, 3) int, rgba or None)`` per
        triangle group of every geometry instance in the scene, node transforms applied;
        ``rgba`` is None when the group has no material or a textured one. Line sets are
        skipped; polygons are triangulated.

    Raises:
        InputError: the file cannot be read as COLLADA (the message names the file).
    """
    import collada

    try:
        with warnings.catch_warnings():  # pycollada builds numpy.matrix transforms
            warnings.simplefilter("ignore", PendingDeprecationWarning)
            doc = collada.Collada(str(path))
            parts = _triangle_parts(doc, path)
    except InputError:
        raise
    except Exception as exc:  # pycollada raises DaeError subclasses, lxml/expat errors, ...
        raise InputError(f"{path}: cannot read its COLLADA materials "
                         f"({type(exc).__name__}: {exc})") from exc
    if not parts:
        raise InputError(f"{path}: the COLLADA scene has no triangles")
    return parts


def _triangle_parts(doc, path) -> list[tuple[np.ndarray, np.ndarray, RGBA | None]]:
    """``read_collada_parts`` on a parsed pycollada document."""
    from collada.lineset import BoundLineSet
    from collada.polylist import BoundPolylist

    if doc.scene is None:
        raise InputError(f"{path}: the COLLADA file has no <scene>")
    parts = []
    for bound in doc.scene.objects("geometry"):
        for prim in bound.primitives():
            if isinstance(prim, BoundLineSet):
                continue
            if isinstance(prim, BoundPolylist):  # BoundPolygons too
                prim = prim.triangleset()
            if len(prim) == 0:
                continue
            parts.append((np.asarray(prim.vertex, dtype=float),
                          np.asarray(prim.vertex_index, dtype=np.int64).reshape(-1, 3),
                          _diffuse(prim.material)))
    return parts


def unique_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(a, axis=0, return_inverse=True)`` of a (N, 3) array, by one ``lexsort``.

    The same sorted rows and indices (rows compared by value, x then y then z), several times
    faster than ``np.unique``'s sort of a structured view. Only where equal values have
    different bits (``-0.0`` and ``0.0``) may the row kept differ.

    Returns:
        ``(unique (U, 3), inverse (N,))`` with ``unique[inverse] == a``.
    """
    order = np.lexsort((a[:, 2], a[:, 1], a[:, 0]))
    rows = a[order]
    first = np.empty(len(a), dtype=bool)
    first[:1] = True
    first[1:] = np.any(rows[1:] != rows[:-1], axis=1)
    inverse = np.empty(len(a), dtype=np.intp)
    inverse[order] = np.cumsum(first) - 1
    return rows[first], inverse


def _grouped(vertices: np.ndarray, faces: np.ndarray, face_group: np.ndarray,
             palette: list[RGBA]) -> VisualMesh:
    """Merge identical float32 vertices, drop unused ones, sort faces by colour group.

    Args:
        vertices: (V, 3) positions [m].
        faces: (F, 3) indices into ``vertices``.
        face_group: (F,) index into ``palette`` of each face.
        palette: the distinct RGBA colours.
    """
    unique, inverse = unique_rows(vertices.astype(np.float32))
    faces = inverse.reshape(-1)[faces]
    used, faces = np.unique(faces, return_inverse=True)
    faces = faces.reshape(-1, 3).astype(np.uint32)
    order = np.argsort(face_group, kind="stable")
    counts = np.bincount(face_group, minlength=len(palette))
    keep = counts > 0
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return VisualMesh(unique[used], faces[order], tuple(int(s) for s in starts[keep]),
                      tuple(int(c) for c in counts[keep]),
                      tuple(c for c, k in zip(palette, keep, strict=True) if k))


def _collada_mesh(geometry_object, bvh, cache: dict) -> VisualMesh | None:
    """The geometry's mesh coloured by its COLLADA materials, or None with a warning."""
    path = geometry_object.meshPath
    scale = np.asarray(geometry_object.meshScale, dtype=float)
    grey = _rgba(geometry_object.meshColor)  # for groups without a usable material
    key = ("dae", path, tuple(scale), grey, bvh.num_vertices, bvh.num_tris)
    if key in cache:
        return cache[key]
    try:
        parts = read_collada_parts(path)
    except InputError as exc:
        warnings.warn(f"{exc}; drawn in its meshColor", stacklevel=4)
        cache[key] = None
        return None
    offsets = np.cumsum([0] + [len(v) for v, _, _ in parts])
    vertices = np.vstack([v for v, _, _ in parts]) * scale
    faces = np.vstack([f + o for (_, f, _), o in zip(parts, offsets, strict=False)])
    part_colors = [c if c is not None else grey for _, _, c in parts]
    palette = list(dict.fromkeys(part_colors))  # first-appearance order
    face_group = np.repeat([palette.index(c) for c in part_colors],
                           [len(f) for _, f, _ in parts])
    mesh = _grouped(vertices, faces, face_group, palette)
    # The file's geometry must be the one coal loaded (same loader conventions).
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    bvh_vertices = _bvh_vertices(bvh)
    blo, bhi = bvh_vertices.min(axis=0), bvh_vertices.max(axis=0)
    tol = EXTENT_RTOL * max(float(np.linalg.norm(bhi - blo)), 1e-9)
    if np.max(np.abs(lo - blo)) > tol or np.max(np.abs(hi - bhi)) > tol:
        warnings.warn(f"{path}: the COLLADA geometry read for its materials has the bounding "
                      f"box {lo.tolist()}..{hi.tolist()}, coal's is {blo.tolist()}.."
                      f"{bhi.tolist()} [m]; drawn in its meshColor", stacklevel=4)
        mesh = None
    cache[key] = mesh
    return mesh


def visual_mesh(geometry_object, color: RGBA | None = None,
                cache: dict | None = None) -> VisualMesh | None:
    """The coloured triangle mesh of a visual geometry, or None for a non-mesh geometry.

    Args:
        geometry_object: a ``pin.GeometryObject`` (its ``geometry``, ``meshPath``,
            ``meshScale``, ``meshColor`` and ``overrideMaterial`` are read).
        color: an RGBA in [0, 1] that overrides every material, or None.
        cache: a dict shared between calls, so that a mesh used twice (two arms of one
            robot) is read once.

    Returns:
        The mesh in the geometry frame [m], coloured by the precedence in this module's
        docstring; None when the geometry is not a triangle mesh (the caller draws
        primitives another way).
    """
    cache = {} if cache is None else cache
    bvh = _bvh(geometry_object)
    if bvh is None:
        return None
    if color is None and not geometry_object.overrideMaterial \
            and Path(geometry_object.meshPath).suffix.lower() == ".dae":
        mesh = _collada_mesh(geometry_object, bvh, cache)
        if mesh is not None:
            return mesh
    key = ("bvh", geometry_object.meshPath, tuple(np.asarray(geometry_object.meshScale)),
           bvh.num_vertices, bvh.num_tris)
    if key not in cache:
        cache[key] = (_bvh_vertices(bvh), _bvh_faces(bvh))
    vertices, faces = cache[key]
    rgba = _rgba(color if color is not None else geometry_object.meshColor)
    return VisualMesh(vertices, faces, (0,), (len(faces),), (rgba,))


# ----------------------------------------------------------------------------- Meshcat
def rgba_to_int(rgba) -> int:
    """0xRRGGBB of an RGBA in [0, 1] (alpha dropped)."""
    r, g, b = (int(round(255 * float(c))) for c in rgba[:3])
    return (r << 16) + (g << 8) + b


def lambert_material(rgba) -> mg.MeshLambertMaterial:
    """A matte three.js material of colour ``rgba`` in [0, 1], transparent when alpha < 1."""
    opacity = float(rgba[3])
    return mg.MeshLambertMaterial(color=rgba_to_int(rgba), transparent=opacity < 1.0,
                                  opacity=opacity)


class CompactMesh(mg.TriangularMeshGeometry):
    """A triangle mesh whose index buffer is 16-bit when it can be (halves its size).

    ``groups`` (first face, face count) per material become three.js geometry groups, in
    index units (3 per face); one group needs none.
    """

    def __init__(self, vertices, faces, groups: tuple[tuple[int, int], ...] = ()):
        super().__init__(vertices, faces)
        self.groups = tuple(groups)

    def lower(self, object_data):
        """Meshcat's BufferGeometry JSON, with a 16-bit index and ``groups`` when due."""
        out = super().lower(object_data)
        if len(self.vertices) < 2**16:
            index = out["data"]["index"]
            index["type"] = "Uint16Array"  # msgpack extension 0x14 in meshcat's viewer
            index["array"] = umsgpack.Ext(0x14, self.faces.astype(np.uint16).tobytes("C"))
        if len(self.groups) > 1:
            out["data"]["groups"] = [{"start": 3 * s, "count": 3 * n, "materialIndex": k}
                                     for k, (s, n) in enumerate(self.groups)]
        return out


class _MultiMaterialMesh(mg.Mesh):
    """A three.js ``Mesh`` whose ``material`` is a list, one per geometry group."""

    def __init__(self, geometry: CompactMesh, materials: list[mg.Material]):
        super().__init__(geometry, materials[0])
        self.materials = materials

    def lower(self):
        data = super().lower()  # the geometry and the first material
        for material in self.materials[1:]:
            material.lower_in_object(data)
        data["object"]["material"] = [m.uuid for m in self.materials]
        return data


def mesh_object(mesh: VisualMesh) -> mg.Mesh:
    """The Meshcat object (binary arrays, one Lambert material per colour) of ``mesh``."""
    geometry = CompactMesh(mesh.vertices, mesh.faces, tuple(zip(mesh.starts, mesh.counts,
                                                                strict=True)))
    materials = [lambert_material(c) for c in mesh.colors]
    if len(materials) == 1:
        return mg.Mesh(geometry, materials[0])
    return _MultiMaterialMesh(geometry, materials)
