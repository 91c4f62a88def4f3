"""Study files: schema, key paths into the base file, and the list of cases they define.

A study file (YAML) names a base scenario or grasp file and what to vary::

    name: payload_capacity
    base: ../two_ur5_box.yaml        # scenario or grasp file (relative to this file)
    mode: simulate                   # simulate (scenario) | grasp (closure of its contacts)
    set: {simulation.duration: 1.0}  # fixed overrides applied to every case
    parameters:
      - {path: object.mass, grid: [2, 4, 8]}                      # every value
      - {path: controller.kp, uniform: {low: 50, high: 150}}      # seeded random samples
      - {path: arms[0].base.position[2], normal: {sigma: 0.01}}   # mean: the base value
      - {perturb_contacts: {sigma: [0.001, 0.005]}}               # σ [m] of contact points
    samples: 10                      # random draws per grid point (default 1)
    seed: 0
    metrics: [max_constraint_violation, min_contact_force, peak_joint_torque]  # default all

The cases are the Cartesian product of every grid (``perturb_contacts.sigma`` is a grid
too) times ``samples`` draws of the random parameters and perturbations. Every random
value is drawn here, in the driver, from ``numpy.random.default_rng([seed, case index])``,
so a case is a fixed set of overrides ``{key path: value}``: the same on any worker, in a
plain loop, and after a resume.

Key paths use the base file's own keys: ``object.mass``, ``arms[0].base.position``
(a whole vector), ``arms[0].base.position[2]`` (one coordinate), ``controller.margin``,
``contacts[3].point``. A path must exist in the base file. Reading and setting them is
:mod:`multiarm_pin.study.key_paths` (its functions are re-exported here).

Every error is a :class:`~multiarm_pin.exceptions.StudyError` naming the file, the key path
and what was expected.

Twins: ``multiarm_pin.design.spec`` (the same role, a package's input file reader, in another
package, for another format: that module reads design spec files, the object, task, arms and
base region of a design; this one reads study files).
"""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multiarm_pin.app.scenario import did_you_mean
from multiarm_pin.exceptions import MultiArmError, StudyError
from multiarm_pin.study.key_paths import (
    apply_overrides,
    parse_key_path,
    resolve_key_path,
    set_key_path,
)

MODES = ("simulate", "grasp")
"""What a case does: simulate the scenario, or analyse the grasp made by its contacts."""
_TOP_KEYS = ("name", "description", "base", "mode", "set", "parameters", "samples", "seed",
             "metrics")
_DISTRIBUTIONS = ("grid", "uniform", "normal")


# ----------------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class Parameter:
    """One varied quantity of a study.

    Attributes:
        path: key path in the base file (``perturb_contacts.sigma`` for contact perturbations).
        kind: ``grid``, ``uniform``, ``normal`` or ``perturb_contacts``.
        values: grid values (``grid``, and σ values [m] of ``perturb_contacts``).
        low, high: bounds of ``uniform`` (scalars or arrays of the base value's shape).
        mean: mean of ``normal`` (scalar or array; the base value when not given).
        sigma: standard deviation of ``normal`` (>= 0).
        contacts: key paths of the ``point`` of each perturbed contact with its face.
    """

    path: str
    kind: str
    values: tuple = ()
    low: object = None
    high: object = None
    mean: object = None
    sigma: object = None
    contacts: tuple = ()

    @property
    def is_grid(self) -> bool:
        """True when the parameter enumerates values (grid or perturbation σ)."""
        return self.kind in ("grid", "perturb_contacts")


@dataclass(frozen=True)
class Case:
    """One run of a study: fixed overrides of the base file.

    Attributes:
        index: position in the study (0-based).
        case_id: ``case_00042``-style name (folder of its summary).
        key: hash of the base file and the overrides: finished rows with the same key are
            reused by a resume.
        params: scalar value of each varied parameter (the table's parameter columns;
            ``perturb_contacts.sigma`` [m] for perturbations), plus ``sample``.
        overrides: ``{key path: value}`` applied to the base file (JSON values).
    """

    index: int
    case_id: str
    key: str
    params: dict
    overrides: dict


@dataclass(frozen=True)
class StudySpec:
    """A validated study file.

    Attributes:
        file: the study file. name, description: from the file. base_file: absolute path of
        the base file. base_kind: ``scenario`` or ``grasp``. base_data: its parsed content.
        base_text_hash: sha256 of the base file's bytes. mode: one of :data:`MODES`.
        fixed: fixed overrides. parameters: the varied quantities. samples: random draws per
        grid point. seed: RNG seed. metrics: metric names recorded (see
        :mod:`multiarm_pin.study.metrics`).
    """

    file: str
    name: str
    description: str
    base_file: str
    base_kind: str
    base_data: dict
    base_text_hash: str
    mode: str
    fixed: dict
    parameters: tuple[Parameter, ...]
    samples: int
    seed: int
    metrics: tuple[str, ...]
    data: dict = field(default_factory=dict)

    @property
    def varied(self) -> list[str]:
        """Names of the parameter columns of the table, in order."""
        return [p.path for p in self.parameters]

    def cases(self) -> list[Case]:
        """Every case of the study, in order (see the module docstring)."""
        grids = [p for p in self.parameters if p.is_grid]
        randoms = [p for p in self.parameters if not p.is_grid]
        perturb = [p for p in self.parameters if p.kind == "perturb_contacts"]
        n_samples = self.samples
        combos = list(itertools.product(*[range(len(p.values)) for p in grids]))
        out: list[Case] = []
        for combo in combos:
            for s in range(n_samples):
                index = len(out)
                rng = np.random.default_rng([self.seed, index])
                overrides: dict = dict(self.fixed)
                params: dict = {}
                for p, k in zip(grids, combo, strict=True):
                    params[p.path] = _scalar(p.values[k])
                    if p.kind == "grid":
                        overrides[p.path] = _jsonable(p.values[k])
                for p in randoms:
                    value = _draw(p, rng, resolve_key_path(self.base_data, p.path, self.file))
                    overrides[p.path] = _jsonable(value)
                    params[p.path] = _scalar(value)
                for p in perturb:
                    sigma = float(p.values[combo[grids.index(p)]])
                    for point_path, origin_point, tangents in p.contacts:
                        z = rng.standard_normal(2)
                        moved = np.asarray(origin_point) + sigma * (tangents @ z)
                        overrides[point_path] = _jsonable(moved)
                params["sample"] = s
                key = _case_key(self.base_text_hash, self.mode, self.metrics, overrides)
                out.append(Case(index, f"case_{index:05d}", key, params, overrides))
        return out


def _case_key(base_hash: str, mode: str, metrics, overrides: dict) -> str:
    text = json.dumps([base_hash, mode, list(metrics), overrides], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _scalar(v):
    """A table cell for a parameter value: a float, a string, or JSON text of a vector."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        return v if isinstance(v, str) else json.dumps(v, sort_keys=True)
    return float(a) if a.ndim == 0 else json.dumps(a.tolist())


def _jsonable(v):
    a = np.asarray(v)
    if a.dtype.kind in "fiub":
        return a.tolist() if a.ndim else a.item()
    return v


def _draw(p: Parameter, rng: np.random.Generator, base_value):
    shape = np.shape(np.asarray(base_value, dtype=float))
    if p.kind == "uniform":
        return rng.uniform(np.broadcast_to(p.low, shape), np.broadcast_to(p.high, shape))
    mean = np.asarray(base_value, dtype=float) if p.mean is None else np.broadcast_to(
        np.asarray(p.mean, dtype=float), shape)
    return mean + np.asarray(p.sigma, dtype=float) * rng.standard_normal(shape)


# ----------------------------------------------------------------------------- loading
def load_study(path) -> StudySpec:
    """Read and validate a study file (see the module docstring).

    Raises:
        StudyError: unreadable file, bad YAML, unknown keys, a key path missing from the
            base file, a negative σ, an empty grid, ...
    """
    path = Path(path)
    f = str(path)
    if not path.is_file():
        raise StudyError(f, "", "file not found")
    data = _load_yaml(path, f)
    return parse_study(data, f)


def _load_yaml(path: Path, f: str):
    """Strict YAML (:mod:`multiarm_pin.yaml_reader`: duplicate keys, encodings, 1e12 floats)."""
    from multiarm_pin.exceptions import ScenarioError
    from multiarm_pin.yaml_reader import load_yaml_file

    try:
        return load_yaml_file(path)
    except ScenarioError as exc:
        raise StudyError(exc.file, exc.key, exc.message, exc.line, exc.column) from None


def parse_study(data, file: str = "<study>") -> StudySpec:
    """Validate a parsed study mapping (``file`` resolves the relative ``base`` path).

    Raises:
        StudyError: invalid content (names the key path and what was expected).
    """
    f = file
    if not isinstance(data, Mapping):
        raise StudyError(f, "", f"expected a mapping with keys {', '.join(_TOP_KEYS)}")
    for k in data:
        if k not in _TOP_KEYS:
            raise StudyError(f, str(k), f"unknown key{did_you_mean(k, _TOP_KEYS)}; expected "
                             f"keys: {', '.join(_TOP_KEYS)}")
    if "base" not in data:
        raise StudyError(f, "base", "missing required key: the base scenario or grasp file")
    base_rel = data["base"]
    if not isinstance(base_rel, str):
        raise StudyError(f, "base", f"expected a file path, got {base_rel!r}")
    base_file = (Path(f).resolve().parent / base_rel).resolve()
    if not base_file.is_file():
        raise StudyError(f, "base", f"base file {str(base_file)!r} not found")
    base_bytes = base_file.read_bytes()
    try:
        base_data = _load_yaml(base_file, str(base_file))
    except StudyError as exc:
        raise StudyError(f, "base", f"invalid base file: {exc}") from None
    if not isinstance(base_data, Mapping):
        raise StudyError(f, "base", f"{base_file}: expected a scenario or grasp mapping")
    from multiarm_pin.app.grasp_input import is_grasp_file

    base_kind = "grasp" if is_grasp_file(base_data) else "scenario"
    _validate_base(base_data, str(base_file), base_kind, f)
    name = data.get("name", Path(f).stem)
    if not isinstance(name, str) or not name:
        raise StudyError(f, "name", f"expected a non-empty string, got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise StudyError(f, "description", f"expected a string, got {description!r}")
    default_mode = "simulate" if base_kind == "scenario" else "grasp"
    mode = data.get("mode", default_mode)
    if mode not in MODES:
        raise StudyError(f, "mode", f"unknown mode {mode!r}{did_you_mean(str(mode), MODES)}; "
                         f"expected one of {', '.join(MODES)}")
    if base_kind == "grasp" and mode != "grasp":
        raise StudyError(f, "mode", "a grasp file base can only be studied in mode 'grasp'")
    if base_kind == "scenario" and mode == "grasp":  # its grasp, read as `grasp` reads it
        from multiarm_pin.app.grasp_input import grasp_input_from_data

        try:
            grasp_input_from_data(base_data, base_file)
        except MultiArmError as exc:
            raise StudyError(f, "base", f"invalid base file for mode 'grasp': {exc}") from exc
    fixed_raw = data.get("set", {}) or {}
    if not isinstance(fixed_raw, Mapping):
        raise StudyError(f, "set", "expected a mapping {key path: value}")
    fixed = {}
    for p, v in fixed_raw.items():
        resolve_key_path(base_data, str(p), f, f"set.{p}")
        fixed[str(p)] = _jsonable(v)
    samples = data.get("samples", 1)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
        raise StudyError(f, "samples", f"expected a positive integer, got {samples!r}")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise StudyError(f, "seed", f"expected an integer >= 0, got {seed!r}")
    raw_params = data.get("parameters", [])
    if not isinstance(raw_params, list) or not raw_params:
        raise StudyError(f, "parameters", "expected a non-empty list of parameters")
    params = tuple(_parse_parameter(p, i, base_data, base_kind, f)
                   for i, p in enumerate(raw_params))
    paths = [p.path for p in params]
    for i, p in enumerate(paths):
        if paths.index(p) != i:
            raise StudyError(f, f"parameters[{i}]", f"{p!r} is varied twice")
        if p in fixed:
            raise StudyError(f, f"parameters[{i}]", f"{p!r} is also fixed in 'set'")
    from multiarm_pin.study.metrics import metric_names

    arms = base_data.get("arms") if isinstance(base_data, dict) else None
    allowed = metric_names(mode, [str(a["name"]) for a in (arms or [])
                                  if isinstance(a, dict) and "name" in a])
    metrics = data.get("metrics", list(allowed))
    if not isinstance(metrics, list) or not metrics:
        raise StudyError(f, "metrics", f"expected a list of metric names among "
                         f"{', '.join(allowed)}")
    for i, m in enumerate(metrics):
        if m not in allowed:
            raise StudyError(f, f"metrics[{i}]", f"unknown metric {m!r}"
                             f"{did_you_mean(str(m), allowed)} for mode {mode!r}; expected "
                             f"one of {', '.join(allowed)}")
    if not any(p.kind != "grid" for p in params) and samples != 1:
        raise StudyError(f, "samples", "samples > 1 needs a random parameter (uniform, normal "
                         "or perturb_contacts); a grid alone is deterministic")
    h = hashlib.sha256(base_bytes).hexdigest()
    return StudySpec(f, name, description, str(base_file), base_kind, dict(base_data), h, mode,
                     fixed, params, samples, seed, tuple(metrics), dict(data))


def _validate_base(base_data, base_file: str, base_kind: str, f: str) -> None:
    """The base file must be valid by itself (its own error, as a study error on ``base``)."""
    try:
        if base_kind == "grasp":
            from multiarm_pin.grasp.report import grasp_from_data

            grasp_from_data(base_data, base_file)
        else:
            from multiarm_pin.app.scenario import parse_scenario

            parse_scenario(base_data, base_file)
    except MultiArmError as exc:
        raise StudyError(f, "base", f"invalid base file: {exc}") from exc


def _parse_parameter(p, i: int, base, base_kind: str, f: str) -> Parameter:
    key = f"parameters[{i}]"
    if not isinstance(p, Mapping):
        raise StudyError(f, key, "expected a mapping {path, grid|uniform|normal} or "
                         "{perturb_contacts: {sigma: [...]}}")
    if "perturb_contacts" in p:
        if set(p) != {"perturb_contacts"}:
            raise StudyError(f, key, "perturb_contacts takes no other key here")
        return _parse_perturbation(p["perturb_contacts"], f"{key}.perturb_contacts", base,
                                   base_kind, f)
    for k in p:
        if k not in ("path", *_DISTRIBUTIONS):
            raise StudyError(f, f"{key}.{k}", f"unknown key"
                             f"{did_you_mean(str(k), ('path', *_DISTRIBUTIONS))}; expected "
                             "path and one of grid, uniform, normal")
    if "path" not in p:
        raise StudyError(f, f"{key}.path", "missing the key path of the varied value")
    path = p["path"]
    base_value = resolve_key_path(base, path, f, f"{key}.path")
    kinds = [k for k in _DISTRIBUTIONS if k in p]
    if len(kinds) != 1:
        raise StudyError(f, key, f"expected exactly one of grid, uniform, normal, got "
                         f"{kinds or 'none'}")
    kind = kinds[0]
    spec = p[kind]
    k2 = f"{key}.{kind}"
    if kind == "grid":
        if not isinstance(spec, list) or not spec:
            raise StudyError(f, k2, "expected a non-empty list of values")
        if len({json.dumps(v, sort_keys=True) for v in spec}) != len(spec):
            raise StudyError(f, k2, "expected distinct values")
        return Parameter(path, "grid", values=tuple(spec))
    shape = _numeric_shape(base_value, f, f"{key}.path", path)
    if not isinstance(spec, Mapping):
        what = "low, high" if kind == "uniform" else "sigma and optionally mean"
        raise StudyError(f, k2, f"expected a mapping ({what})")
    if kind == "uniform":
        for k in spec:
            if k not in ("low", "high"):
                raise StudyError(f, f"{k2}.{k}", "unknown key; expected low, high")
        low = _numbers(spec.get("low"), shape, f, f"{k2}.low")
        high = _numbers(spec.get("high"), shape, f, f"{k2}.high")
        if np.any(high < low):
            raise StudyError(f, k2, f"expected low <= high, got low {low.tolist()}, high "
                             f"{high.tolist()}")
        return Parameter(path, "uniform", low=low.tolist(), high=high.tolist())
    for k in spec:
        if k not in ("mean", "sigma"):
            raise StudyError(f, f"{k2}.{k}", "unknown key; expected mean, sigma")
    sigma = _numbers(spec.get("sigma"), (), f, f"{k2}.sigma")
    if sigma < 0:
        raise StudyError(f, f"{k2}.sigma", f"expected a standard deviation >= 0, got "
                         f"{float(sigma)}")
    mean = None if spec.get("mean") is None else _numbers(spec["mean"], shape, f,
                                                           f"{k2}.mean").tolist()
    return Parameter(path, "normal", mean=mean, sigma=float(sigma))


def _numeric_shape(value, f: str, key: str, path: str) -> tuple:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise StudyError(f, key, f"{path!r} holds {value!r} in the base file: a random "
                         "parameter needs a number or a list of numbers there") from None
    return a.shape


def _numbers(v, shape, f: str, key: str) -> np.ndarray:
    if v is None:
        raise StudyError(f, key, "missing")
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise StudyError(f, key, f"expected numbers, got {v!r}") from None
    if isinstance(v, bool) or not np.all(np.isfinite(a)):
        raise StudyError(f, key, f"expected finite numbers, got {v!r}")
    try:
        return np.broadcast_to(a, shape).copy() if shape else a.reshape(())
    except ValueError:
        raise StudyError(f, key, f"expected a number or shape {shape}, got shape "
                         f"{a.shape}") from None


def _parse_perturbation(spec, key: str, base, base_kind: str, f: str) -> Parameter:
    if not isinstance(spec, Mapping) or "sigma" not in spec:
        raise StudyError(f, key, "expected {sigma: [σ values, m]} and optionally contacts: "
                         "[indices]")
    for k in spec:
        if k not in ("sigma", "contacts"):
            raise StudyError(f, f"{key}.{k}", "unknown key; expected sigma, contacts")
    sig = spec["sigma"]
    sig_list = sig if isinstance(sig, list) else [sig]
    values = []
    for j, s in enumerate(sig_list):
        if isinstance(s, bool) or not isinstance(s, int | float) or not np.isfinite(s):
            raise StudyError(f, f"{key}.sigma[{j}]", f"expected a length [m], got {s!r}")
        if s < 0:
            raise StudyError(f, f"{key}.sigma[{j}]", f"expected a standard deviation >= 0 "
                             f"[m], got {s}")
        values.append(float(s))
    if len(set(values)) != len(values):
        raise StudyError(f, f"{key}.sigma", "expected distinct values")
    contacts = _contact_points(base, base_kind, f, key)
    which = spec.get("contacts")
    if which is not None:
        if not isinstance(which, list) or not all(
                isinstance(k, int) and not isinstance(k, bool) for k in which):
            raise StudyError(f, f"{key}.contacts", "expected a list of contact indices")
        for k in which:
            if not 0 <= k < len(contacts):
                raise StudyError(f, f"{key}.contacts", f"contact index {k} out of range "
                                 f"0..{len(contacts) - 1}")
        contacts = [contacts[k] for k in which]
    return Parameter("perturb_contacts.sigma", "perturb_contacts", values=tuple(values),
                     contacts=tuple(contacts))


def _contact_points(base, base_kind: str, f: str, key: str):
    """``(point key path, point (3,), tangents (3, 2))`` of every contact of the base file."""
    from multiarm_pin.model.polyhedron import box, from_vertices

    shape = base["object"]["shape"]
    poly = box(shape["size"]) if shape["type"] == "box" else from_vertices(shape["vertices"])
    items = []
    if base_kind == "grasp":
        for i, c in enumerate(base["contacts"]):
            items.append((f"contacts[{i}]", c))
    else:
        for a, arm in enumerate(base["arms"]):
            joint = arm.get("joint", {})
            if joint.get("type") in ("fingertips", "contacts"):  # contacts: deprecated name
                for k, c in enumerate(joint.get("contacts", [])):
                    items.append((f"arms[{a}].joint.contacts[{k}]", c))
    if not items:
        raise StudyError(f, key, "the base file has no contacts to perturb")
    out = []
    for path, c in items:
        if c.get("point") is None:
            raise StudyError(f, key, f"{path} has no point to perturb")
        p = np.asarray(c["point"], dtype=float)
        if "face" in c:
            face = c["face"]
            if isinstance(face, str) and face.lstrip("-").isdigit():
                face = int(face)
            _, R = poly.face_frame(face)
            T = R[:, :2]
        else:  # point + normal: the plane normal to it
            n = np.asarray(c["normal"], dtype=float)
            n = n / np.linalg.norm(n)
            u = np.cross(n, [1.0, 0.0, 0.0])
            if np.linalg.norm(u) < 0.5:
                u = np.cross(n, [0.0, 1.0, 0.0])
            u /= np.linalg.norm(u)
            T = np.column_stack([u, np.cross(n, u)])
        out.append((f"{path}.point", p.tolist(), T))
    return out


__all__ = [
    "MODES",
    "Case",
    "Parameter",
    "StudySpec",
    "apply_overrides",
    "load_study",
    "parse_key_path",
    "parse_study",
    "resolve_key_path",
    "set_key_path",
]
