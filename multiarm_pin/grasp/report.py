"""Grasp files (YAML), the analysis report, and its picture.

One concept at several layers: each layer's ``report.py`` (``grasp``, ``study``, ``feasibility``,
``design``) makes that layer's report of its results.

File format (lengths in metres, points in the object frame)::

    object: {shape: {type: box, size: [2.0, 1.5, 1.0]}}   # or {type: polyhedron, vertices: [...]}
    contacts:
      - {face: +x, point: [1.0, 0.3, 0.2]}                # a face name or index and a point on it
      - {point: [...], normal: [...]}                     # or a point and the inward normal
    seventh_contact: 7                                    # optional, a contact number (from 1)
    seventh_contact_face: +z                              # optional
    length_scale: 1.0                                     # optional, [m], divides moments

The seventh-contact regions do not depend on the order of the contacts. With seven or more
contacts, each contact in turn moves on its face while the others are held fixed, and its
region (where it may lie for form closure) is computed when the others have rank 6 (Eq 2.3
with six fixed independent contacts, checked against Eq 2.4; Eq 2.4 with more). The report
names, for each region, the contacts it holds fixed. ``seventh_contact`` (or ``multiarm-pin
grasp --seventh K``) keeps only contact K's region; ``seventh_contact_face`` keeps the
contacts on that face, or, when none lies on it (always with six contacts), gives the region
of one more contact on it with every contact fixed.

Twins: ``multiarm_pin.feasibility.report``, ``multiarm_pin.design.report`` and
``multiarm_pin.study.report`` (the same role, a package's report of its own results, in four
packages: this one reads grasp files, analyses them, formats the report and draws its picture;
``feasibility.report`` returns the feasibility of a simulated run (limits, collisions) as a
``FeasibilityReport``; ``design.report`` writes a design's results folder (scenarios, pictures,
``report.md``, the best run); ``study.report`` writes a study's ``report.md`` and its plots).
"""

from __future__ import annotations

from collections.abc import Sequence
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
    SeventhContactRegion,
    seventh_contact_regions,
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
        seventh_contact: index (0-based) of the one contact whose region is computed (the
            file's ``seventh_contact`` is its number, from 1), or ``None`` for every contact.
    """

    path: Path
    grasp: Grasp
    seventh_contact_face: str | int | None
    length_scale: float
    seventh_contact: int | None = None


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


_TOP_KEYS = ("object", "contacts", "seventh_contact", "seventh_contact_face", "length_scale",
             "name", "description")


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
    seventh = None
    if "seventh_contact" in d:
        seventh = seventh_number(root.get("seventh_contact"), len(contacts))
    return GraspFile(path, Grasp(tuple(contacts), poly), face, L, seventh)


def seventh_number(r: Reader, n_contacts: int) -> int:
    """The 0-based index of a contact number (from 1) read at ``r``; ScenarioError if invalid."""
    v = r.value
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= n_contacts:
        raise r.error(f"expected a contact number in 1..{n_contacts} (contacts are numbered "
                      f"from 1 in the order of the file), got {describe(v)}")
    return v - 1


def analyse(
    gf: GraspFile, seventh: int | None = None
) -> tuple[dict[str, Any], tuple[SeventhContactRegion, ...]]:
    """Analyse a grasp file: closure, margins, independence, regions, stability.

    Nothing in the report depends on the order of the contacts in the file but the contact
    numbers (1-based, in the file's order, as in the picture). The seventh-contact regions
    are those of :func:`~multiarm_pin.grasp.seventh_contact.seventh_contact_regions`: with
    seven or more contacts, each contact whose removal leaves six independent ones (or the
    one named by ``seventh`` or the file's ``seventh_contact``) moves on its face, the others
    held fixed; the file's ``seventh_contact_face`` picks the contacts on that face (or, when
    none lies on it, one more contact on it).

    Args:
        gf: the grasp file.
        seventh: the moving contact (0-based index), overriding the file's
            ``seventh_contact``; None keeps the file's.

    Returns:
        ``(report, regions)``: a JSON-ready dict with at least ``form_closure`` (bool),
        ``margin`` (float), ``independent`` (bool: some six contacts are independent, i.e.
        the wrenches have rank 6) and ``regions`` (one entry per moving contact: ``contact``
        (its number, None for one more contact), ``fixed_contacts`` (numbers), ``face``,
        ``computed``, ``area`` [m^2], ``vertices`` (list of [x, y, z] in the object frame, in
        order around the region clipped to its face; empty when there is none),
        ``contact_inside``, ``reason``...), and the regions themselves.
    """
    g = gf.grasp
    N = len(g)
    seventh = gf.seventh_contact if seventh is None else seventh
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
    if N == 6:
        ind = check_independence(g)
        rep["independent"] = ind.independent
        rep["independence"] = _independence(ind, tuple(range(6)))
    elif N > 6:
        rep["independent"] = fc.rank == 6
    else:
        rep["independent"] = False
        rep["notes"].append(f"{N} contacts: independence needs six")
    rep["seventh_contact"] = None if seventh is None else int(seventh) + 1
    rep["region_face"] = _face_label(g, gf.seventh_contact_face)
    regions = seventh_contact_regions(g, seventh, gf.seventh_contact_face) if N >= 6 else ()
    rep["regions"] = [_region_entry(g, r) for r in regions]
    if N == 6 and gf.seventh_contact_face is None:
        rep["notes"].append("six contacts: name a face (seventh_contact_face) for the region "
                            "of one more contact")
    for r, e in zip(regions, rep["regions"], strict=True):
        if r.region is not None and r.region.empty:
            rep["notes"].append(f"no point of face {e['face']} completes form closure for "
                                f"{_who(e)} with contacts {_numbers(e['fixed_contacts'])} fixed: "
                                f"{r.reason}")
        if rep["form_closure"] and r.inside is False:  # closure holds at the contact itself
            rep["notes"].append(f"{_who(e)} is not inside its region although the grasp is "
                                "form closure: a numerical boundary case")
    stab: dict[str, Any] = {}
    if rep["form_closure"]:
        cb = closure_bound(g)
        stab["closure_bound"] = cb.bound
        stab["closure_bound_length_scale"] = cb.length_scale
        stab["edge_distances"] = cb.edge_distances.tolist()
        stab["bound"] = float(min(cb.bound, cb.edge_distances.min()))
    if N == 6 and rep["independent"]:
        stab["independence_bound"] = independence_bound(g)
    rep["stability"] = stab
    return _jsonable(rep), regions


def _independence(ind, fixed: tuple[int, ...]) -> dict[str, Any]:
    """The JSON of an independence check of the contacts ``fixed`` (numbered from 1)."""
    out: dict[str, Any] = {
        "contacts": [i + 1 for i in fixed],
        "sigma_min": ind.sigma_min,
        "violated_conditions": [{"name": n, "contacts": [i + 1 for i in c]}
                                for n, c in ind.violated],
        "messages": ind.messages,
    }
    if ind.decomposition is not None:
        out["order"] = [fixed[i] + 1 for i in ind.decomposition.order]
        out["cond_e_A"] = ind.decomposition.cond_e_A
        out["cond_a"] = ind.decomposition.cond_a
    return out


def _region_entry(g: Grasp, r: SeventhContactRegion) -> dict[str, Any]:
    """The JSON of one seventh-contact region (contacts numbered from 1)."""
    e: dict[str, Any] = {
        "contact": r.contact + 1 if r.contact >= 0 else None,
        "contact_face": g.contacts[r.contact].label if r.contact >= 0 else None,
        "fixed_contacts": [i + 1 for i in r.fixed],
        "face": _face_label(g, r.face) if r.face >= 0 else None,
        "fixed_independent": r.independent,
        "fixed_sigma_ratio": r.sigma_ratio,
        "computed": r.region is not None,
        "reason": r.reason,
    }
    if r.region is not None:
        reg = r.region
        e["method"] = ("Eq 2.3 (inverse), checked against Eq 2.4" if r.methods_agree is not None
                       else "Eq 2.4 (generators)")
        e["methods_agree"] = r.methods_agree
        e.update(empty=reg.empty, area=reg.area, bounded=reg.bounded,
                 vertices=reg.vertices_3d.tolist(), contact_inside=r.inside)
    else:
        e.update(empty=True, area=0.0, vertices=[], contact_inside=None)
    if len(r.fixed) == 6 and r.independent:
        e["independence"] = _independence(check_independence(g, r.fixed), r.fixed)
        e["independence_bound"] = independence_bound(g, r.fixed)
        if r.contact >= 0 and len(g) == 7:
            try:
                lm = linearised_margins(g, r.fixed, r.contact)
                e["linearised_measures"] = lm.measures.tolist()
                e["linearised_tolerance"] = lm.min_tolerance
            except MultiArmError as exc:
                e["linearised_note"] = str(exc)
    return e


def _face_label(g: Grasp, face) -> str | None:
    """The name of a face (given by name or index), or None."""
    if face is None or g.polyhedron is None:
        return None
    k = g.polyhedron.face_index(face)
    return g.polyhedron.face_names[k] if g.polyhedron.face_names else f"#{k}"


def _who(e: dict[str, Any]) -> str:
    return f"contact {e['contact']}" if e["contact"] is not None else "one more contact"


def _numbers(numbers) -> str:
    return ", ".join(str(i) for i in numbers)


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
    if rep.get("kind") == "scenario":
        lines = [f"scenario file: {rep['file']}  ({rep['n_contacts']} fingertip contacts: "
                 + ", ".join(f"{i} {n}" for i, n in enumerate(rep["contact_names"], 1)) + ")"]
    else:
        lines = [f"grasp file: {rep['file']}  ({rep['n_contacts']} contacts)"]
    lines.append(
        f"form closure: {yes[rep['form_closure']]}   rank {rep['rank']}   LP margin "
        f"{rep['margin']:.6g}   Ferrari-Canny epsilon {rep['ferrari_canny']:.6g} "
        f"(moments / {rep['length_scale']:g} m)"
    )
    if rep["n_contacts"] == 6:
        lines.append(f"the six contacts independent: {yes[rep['independent']]}")
    elif rep["n_contacts"] > 6:
        lines.append(f"six independent contacts among them (rank 6): {yes[rep['independent']]}")
    ind = rep.get("independence", {})
    for msg in ind.get("messages", []):
        lines.append(f"  - {msg}")
    regions = rep.get("regions", [])
    if regions:
        lines.append("seventh-contact regions (contacts numbered from 1 in the file's order; each "
                     "region: where that contact may lie on the face, the others fixed):")
    for e in regions:
        where = (f"contact {e['contact']} on face {e['face']}" if e["contact"] is not None
                 else f"one more contact on face {e['face']}")
        head = f"  {where}, fixed {_numbers(e['fixed_contacts'])}: "
        if not e["computed"]:
            lines.append(head + f"not computed: {e['reason']}")
            continue
        if e["empty"]:
            lines.append(head + f"empty ({e['method']}): {e['reason']}")
            continue
        inside = ("" if e["contact_inside"] is None
                  else f"; contact {e['contact']} inside it: {yes[e['contact_inside']]}")
        lines.append(head + f"area {e['area']:.6g} m^2, "
                     f"{'bounded' if e['bounded'] else 'unbounded on the plane'} "
                     f"({e['method']}){inside}")
        for msg in e.get("independence", {}).get("messages", []):
            lines.append(f"    - {msg}")
        lines.append("    vertices: " + ", ".join(
            f"[{v[0]:.4f}, {v[1]:.4f}, {v[2]:.4f}]" for v in e["vertices"]))
        if "independence_bound" in e and e["contact"] is not None:  # else: under stability
            lines.append(f"    the fixed six stay independent for displacements < "
                         f"{e['independence_bound']:.6g} m")
        if "linearised_tolerance" in e:
            lines.append("    linearised region margins (Example 2.4) tolerate "
                         f"~{e['linearised_tolerance']:.6g} m per coordinate")
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
                f"  the six stay independent for displacements < {st['independence_bound']:.6g} m"
            )
    for note in rep.get("notes", []):
        lines.append(f"note: {note}")
    if "picture" in rep:
        lines.append(f"picture: {rep['picture']}")
    return "\n".join(lines)


def draw_grasp(
    grasp: Grasp,
    region: ContactRegion | SeventhContactRegion | Sequence | None,
    path: str | Path,
    title: str = "",
) -> Path:
    """Save a 3-D picture of the object, its contacts (with normals) and the regions.

    Args:
        grasp: the grasp (needs its polyhedron).
        region: the seventh-contact region(s) to shade on their faces (a region, the
            :class:`SeventhContactRegion` entries of :func:`analyse`, or ``None``).
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
    items = [] if region is None else [region] if not isinstance(region, Sequence) else region
    for r in items:
        r = r.region if isinstance(r, SeventhContactRegion) else r
        if r is not None and not r.empty:
            ax.add_collection3d(Poly3DCollection([r.vertices_3d], facecolor="limegreen",
                                                 alpha=0.45, edgecolor="darkgreen"))  # fmt: skip
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
