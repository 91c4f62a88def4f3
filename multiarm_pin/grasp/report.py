"""Grasp files (YAML), the analysis report, and its picture.

File format (lengths in metres, points in the object frame)::

    object: {shape: {type: box, size: [2.0, 1.5, 1.0]}}   # or {type: polyhedron, vertices: [...]}
    contacts:
      - {face: +x, point: [1.0, 0.3, 0.2]}                # a face name or index and a point on it
      - {point: [...], normal: [...]}                     # or a point and the inward normal
    seventh_contact_face: +z                              # optional
    length_scale: 1.0                                     # optional, [m], divides moments

The seventh-contact region is computed for one contact on ``seventh_contact_face`` given the
first six contacts (Eq 2.3 and Eq 2.4) when the file has six or seven contacts, and given all
contacts but the last (Eq 2.4) when it has more.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from multiarm_pin.exceptions import GraspError, InputError, MultiArmError
from multiarm_pin.grasp.contacts import Grasp, contact_from_point_normal, contact_on_face
from multiarm_pin.grasp.form_closure import MIN_CONTACTS, form_closure
from multiarm_pin.grasp.independence import check_independence
from multiarm_pin.grasp.seventh_contact import (
    ContactRegion,
    region_by_generators,
    region_by_inverse,
)
from multiarm_pin.grasp.stability import closure_bound, independence_bound, linearised_margins
from multiarm_pin.model.polyhedron import box, from_vertices
from multiarm_pin.yaml_reader import Reader, describe, load_yaml_file


@dataclass(frozen=True)
class GraspFile:
    """A grasp file's content.

    Attributes:
        path: the file.
        grasp: the object and its contacts.
        seventh_contact_face: face name/index for the region, or ``None``.
        length_scale: ``L`` [m] for the margins (moments divided by it).
    """

    path: Path
    grasp: Grasp
    seventh_contact_face: str | int | None
    length_scale: float


def load_grasp_file(path: str | Path) -> GraspFile:
    """Read and validate a grasp YAML file.

    Raises:
        ScenarioError: unreadable or non-UTF-8 file, invalid YAML, a duplicate key, or an
            invalid key (the error names the
            file and the key path, e.g. ``contacts[2].point``).
    """
    path = Path(path)
    data = load_yaml_file(path)  # not found, not UTF-8, syntax, duplicate keys
    return grasp_from_data(data, path)


_TOP_KEYS = ("object", "contacts", "seventh_contact_face", "length_scale", "name", "description")


def grasp_from_data(data, path: str | Path) -> GraspFile:
    """Validate a parsed grasp mapping (as read by :func:`load_grasp_file` from ``path``).

    Read with the scenarios' key-path reader (:class:`~multiarm_pin.yaml_reader.Reader`).

    Raises:
        ScenarioError: an invalid key (names ``path``, the key path and what was expected,
            with a did-you-mean for unknown keys and values).
    """
    path = Path(path)
    root = Reader(str(path), "", data)
    d = root.mapping(_TOP_KEYS, required=("object", "contacts"))
    obj = root.get("object")
    obj.mapping(("shape",), required=("shape",))
    sr = obj.get("shape")
    sd = sr.mapping(("type", "size", "vertices"), required=("type",))
    kind = sr.get("type").string(("box", "polyhedron"))
    key = "size" if kind == "box" else "vertices"
    if key not in sd:
        raise sr.error(f"missing required key {key!r}", f"{sr.path}.{key}")
    try:
        if kind == "box":
            poly = box(sr.get("size").array((3,), "edge lengths [m]"))
        else:
            poly = from_vertices(sr.get("vertices").array((None, 3), "vertices [m]"))
    except InputError as exc:
        raise sr.get(key).error(str(exc)) from exc
    cr = root.get("contacts")
    if not isinstance(cr.value, list):
        raise cr.error(f"expected a list of {{face, point}} or {{point, normal}}, got "
                       f"{describe(cr.value)}")
    contacts = []
    for i, item in enumerate(cr.value):
        c = cr.child(i, item)
        cd = c.mapping(("face", "point", "normal"))
        point = c.get("point").array((3,), "object frame [m]") if "point" in cd else None
        try:
            if "face" in cd:
                face = cd["face"]
                if isinstance(face, str) and face.lstrip("-").isdigit():
                    face = int(face)
                contacts.append(contact_on_face(poly, face, point))
            elif "normal" in cd:
                normal = c.get("normal").array((3,), "inward normal, object frame")
                contacts.append(contact_from_point_normal(point, normal, poly))
            else:
                raise c.error("expected a 'face' or a 'normal' key")
        except (GraspError, InputError) as exc:
            raise c.error(str(exc)) from exc
    face = d.get("seventh_contact_face")
    if face is not None:
        try:
            poly.face_index(face)
        except InputError as exc:
            raise root.get("seventh_contact_face").error(str(exc)) from exc
    L = root.get("length_scale").number(positive=True) if "length_scale" in d else 1.0
    return GraspFile(path, Grasp(tuple(contacts), poly), face, L)


def analyse(gf: GraspFile) -> tuple[dict[str, Any], ContactRegion | None]:
    """Analyse a grasp file: closure, margins, independence, region, stability.

    Returns:
        ``(report, region)``: a JSON-ready dict with at least ``form_closure`` (bool),
        ``margin`` (float), ``independent`` (bool, first six contacts) and
        ``region_vertices`` (list of [x, y, z] in the object frame, in order around the
        region clipped to its face; empty when there is none), and the region itself.
    """
    g = gf.grasp
    N = len(g)
    rep: dict[str, Any] = {"file": str(gf.path), "n_contacts": N, "notes": []}
    if N >= MIN_CONTACTS:
        fc = form_closure(g, length_scale=gf.length_scale)
        rep.update(form_closure=fc.form_closure, margin=fc.margin, rank=fc.rank,
                   ferrari_canny=fc.ferrari_canny, length_scale=gf.length_scale)  # fmt: skip
    else:
        fc = form_closure(g, length_scale=gf.length_scale, allow_fewer=True)
        rep.update(form_closure=False, margin=0.0, rank=fc.rank, ferrari_canny=0.0,
                   length_scale=gf.length_scale)  # fmt: skip
        rep["notes"].append(f"{N} contacts: form closure needs at least {MIN_CONTACTS}")
    if N >= 6:
        ind = check_independence(g)
        rep["independent"] = ind.independent
        rep["independence"] = {
            "sigma_min": ind.sigma_min,
            "violated_conditions": [{"name": n, "contacts": list(c)} for n, c in ind.violated],
            "messages": ind.messages,
        }
        if ind.decomposition is not None:
            rep["independence"]["order"] = list(ind.decomposition.order)
            rep["independence"]["cond_e_A"] = ind.decomposition.cond_e_A
            rep["independence"]["cond_a"] = ind.decomposition.cond_a
    else:
        rep["independent"] = False
        rep["notes"].append(f"{N} contacts: independence needs six")
    region = None
    rep["region_vertices"] = []
    if gf.seventh_contact_face is not None and N >= 6:
        fixed = list(range(6)) if N <= 7 else list(range(N - 1))
        region = region_by_generators(g, gf.seventh_contact_face, fixed)
        rep["region_method"] = "Eq 2.4 (generators)"
        if len(fixed) == 6 and rep["independent"]:
            r23 = region_by_inverse(g, gf.seventh_contact_face, fixed)
            rep["region_methods_agree"] = bool(
                abs(r23.area - region.area) <= 1e-6 * max(1.0, r23.area)
            )
            region = r23
            rep["region_method"] = "Eq 2.3 (inverse), checked against Eq 2.4"
        rep["region_face"] = region.face_name
        rep["region_fixed_contacts"] = fixed
        rep["region_vertices"] = region.vertices_3d.tolist()
        rep["region_area"] = region.area
        rep["region_bounded"] = region.bounded
        rep["region_empty"] = region.empty
        if region.empty:
            rep["notes"].append(
                f"no point of face {region.face_name} completes form closure with contacts "
                f"{fixed}: {region.reason}"
            )
        last = g.contacts[-1]
        if N == len(fixed) + 1 and last.face == region.face:
            s = region.to_face(last.point)
            rep["last_contact_in_region"] = bool(region.contains(s)[0])
    stab: dict[str, Any] = {}
    if rep["form_closure"]:
        cb = closure_bound(g)
        stab["closure_bound"] = cb.bound
        stab["closure_bound_length_scale"] = cb.length_scale
        stab["edge_distances"] = cb.edge_distances.tolist()
        stab["bound"] = float(min(cb.bound, cb.edge_distances.min()))
    if rep["independent"]:
        stab["independence_bound"] = independence_bound(g)
        if N == 7:
            try:
                lm = linearised_margins(g)
                stab["linearised_measures"] = lm.measures.tolist()
                stab["linearised_tolerance"] = lm.min_tolerance
            except MultiArmError as exc:
                rep["notes"].append(f"linearised margins: {exc}")
    rep["stability"] = stab
    return _jsonable(rep), region


def _jsonable(x):
    """Plain Python types for JSON: numpy scalars/arrays converted, non-finite floats -> None."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple | np.ndarray):
        return [_jsonable(v) for v in x]
    if isinstance(x, bool | np.bool_):
        return bool(x)
    if isinstance(x, int | np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        return float(x) if np.isfinite(x) else None
    return x


def format_report(rep: dict[str, Any]) -> str:
    """A readable multi-line text of a report from :func:`analyse`."""
    yes = {True: "yes", False: "no"}
    lines = [f"grasp file: {rep['file']}  ({rep['n_contacts']} contacts)"]
    lines.append(
        f"form closure: {yes[rep['form_closure']]}   rank {rep['rank']}   LP margin "
        f"{rep['margin']:.6g}   Ferrari-Canny epsilon {rep['ferrari_canny']:.6g} "
        f"(moments / {rep['length_scale']:g} m)"
    )
    lines.append(f"first six contacts independent: {yes[rep['independent']]}")
    ind = rep.get("independence", {})
    for msg in ind.get("messages", []):
        lines.append(f"  - {msg}")
    if "region_face" in rep:
        lines.append(
            f"region for one more contact on face {rep['region_face']} "
            f"(given contacts {rep['region_fixed_contacts']}, {rep['region_method']}):"
        )
        if rep["region_empty"]:
            lines.append("  empty: no point of this face completes form closure")
        else:
            lines.append(
                f"  area {rep['region_area']:.6g} m^2, "
                f"{'bounded' if rep['region_bounded'] else 'unbounded on the plane'}; vertices:"
            )
            for v in rep["region_vertices"]:
                lines.append(f"    [{v[0]: .6f}, {v[1]: .6f}, {v[2]: .6f}]")
        if "last_contact_in_region" in rep:
            lines.append(f"  last contact inside it: {yes[rep['last_contact_in_region']]}")
    st = rep.get("stability", {})
    if st:
        lines.append("stability:")
        if "bound" in st:
            lines.append(
                f"  closure kept for contact displacements < {st['bound']:.6g} m "
                f"(wrench bound {st['closure_bound']:.6g} m, nearest face edge "
                f"{min(st['edge_distances']):.6g} m)"
            )
        if "independence_bound" in st:
            lines.append(
                f"  first six stay independent for displacements < {st['independence_bound']:.6g} m"
            )
        if "linearised_tolerance" in st:
            lines.append(
                "  linearised region margins (Example 2.4) tolerate "
                f"~{st['linearised_tolerance']:.6g} m per coordinate"
            )
    for note in rep.get("notes", []):
        lines.append(f"note: {note}")
    if "picture" in rep:
        lines.append(f"picture: {rep['picture']}")
    return "\n".join(lines)


def draw_grasp(
    grasp: Grasp, region: ContactRegion | None, path: str | Path, title: str = ""
) -> Path:
    """Save a 3-D picture of the object, its contacts (with normals) and the region.

    Args:
        grasp: the grasp (needs its polyhedron).
        region: the seventh-contact region to shade on its face, or ``None``.
        path: output image file (PNG).
        title: optional title.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    poly = grasp.polyhedron
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    if poly is not None:
        faces = [poly.vertices[list(f)] for f in poly.faces]
        ax.add_collection3d(Poly3DCollection(faces, facecolor="lightsteelblue", alpha=0.25,
                                             edgecolor="k", linewidth=0.8))  # fmt: skip
        size = float(np.ptp(poly.vertices, axis=0).max())
        lo, hi = poly.vertices.min(axis=0), poly.vertices.max(axis=0)
    else:
        size = float(np.ptp(grasp.points, axis=0).max() or 1.0)
        lo, hi = grasp.points.min(axis=0), grasp.points.max(axis=0)
    if region is not None and not region.empty:
        ax.add_collection3d(Poly3DCollection([region.vertices_3d], facecolor="limegreen",
                                             alpha=0.6, edgecolor="darkgreen"))  # fmt: skip
    P, Nrm = grasp.points, grasp.normals
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], color="crimson", s=30, depthshade=False)
    L = 0.15 * size
    ax.quiver(P[:, 0] - L * Nrm[:, 0], P[:, 1] - L * Nrm[:, 1], P[:, 2] - L * Nrm[:, 2],
              Nrm[:, 0], Nrm[:, 1], Nrm[:, 2], length=L, color="crimson")  # fmt: skip
    for i, p in enumerate(P):
        ax.text(p[0], p[1], p[2], f" {i + 1}", color="crimson")
    c, r = (lo + hi) / 2, 0.6 * size
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    if title:
        ax.set_title(title)
    out = Path(path)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out
