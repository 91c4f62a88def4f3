"""``phased_pd``: ``object_pd`` through phases with their own motions, contact sets and supports.

A pick-up from a table (thesis ch. 5, future work: "pick up the object by first tilting it")
is a sequence of phases, each starting where the previous one's reference ended:

- ``tilt``: the object turns by ``angle`` [rad] about a world axis through a pivot point
  (a bottom edge on the table), minimum-jerk over ``duration``;
- ``move``: the object translates by ``displacement`` [m] (world), minimum-jerk;
- ``hold``: the reference stays.

Each phase also says which support rows must keep pressing (``press``: indices of the
support rows, in the order of the system's support labels; the others are planned with no
force, so they separate when the motion lifts them), which arms are released (``release``:
their contacts get no planned force, their tips follow their offsets away), and where each
arm's held points are relative to their grasp places (``offsets``: ``{arm: [dx, dy, dz]}``
in the object frame [m], reached minimum-jerk over the phase's ``duration``; an arm that
starts apart (``joint.approach``) starts at its approach offset).

The force distribution knows the supports
(:func:`~multiarm_pin.dynamics.force_distribution.distribute_with_supports`): the pressing
rows push with at least ``support_margin`` and the object's desired acceleration keeps them
on their plane, so no arm contact is asked to pull and the pivot keeps pressing.

Compiled path: on an evaluation of the compiled path (:meth:`MultiArmSystem.blocks`) the
torques come from :func:`multiarm_pin._compiled.phased.phased_torques`, on the phases packed
as arrays here (:meth:`PhasedPD.phase_arrays`); whenever it reports a case it cannot decide
as :meth:`PhasedPD.reference` does (the margins cannot be kept, a rank-deficient arm, NaN),
the reference decides. The compiled contact loop runs the same kernel inside its steps
(:class:`~multiarm_pin.sim.contact_loop.ContactLoop`; the registry entry's kernel
``phased_pd``) and hands such steps back to the stepper.

Twins: ``multiarm_pin._compiled.phased`` (the same concept, the ``phased_pd`` controller, at the
compiled layer: its ``phased_torques`` computes the torques of :class:`PhasedPD`'s compiled
path, whose oracle is :meth:`PhasedPD.reference`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin._compiled import layout
from multiarm_pin._compiled.controller_kernels import PD_OK, planned_torques
from multiarm_pin._compiled.phased import phased_torques, supported_distribution
from multiarm_pin.dynamics.blocks import expand_rows, restrict_rows, select_rows
from multiarm_pin.dynamics.force_distribution import distribute_with_supports
from multiarm_pin.dynamics.inverse_dynamics import InverseDynamicsResult, inverse_dynamics
from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.sim.controllers.object_pd import ObjectPD, ObjectPDPlan
from multiarm_pin.sim.trajectories import PoseSample, minimum_jerk, pose_error
from multiarm_pin.system import Evaluation, MultiArmSystem, SystemState

PRESSING_GAP = 1e-6
"""[m] A support row planned to press is planned only while its gap is below this (the
stepper's ``SEPARATION_GAP``): a row that is off its plane has nothing to press on."""

PHASE_KINDS = ("tilt", "move", "hold")

PHASE_CODES = {"hold": layout.PHASE_HOLD, "tilt": layout.PHASE_TILT, "move": layout.PHASE_MOVE}
"""The compiled kernel's code of each phase kind (``PH_KIND`` of the phase table)."""


def current_phase(starts, t):
    """Index of the phase current at ``t`` [s] (a scalar, or (T,) at each time of ``t``).

    The last phase started at or before ``t``, 0 before the first start (``starts``: the
    phases' start times [s], increasing, as :func:`parse_phases` makes them).
    """
    return np.maximum(np.searchsorted(np.asarray(starts, float), t, side="right") - 1, 0)


@dataclass(frozen=True)
class Phase:
    """One phase of :class:`PhasedPD` (see the module).

    Attributes:
        name: label.
        kind: ``"tilt"``, ``"move"`` or ``"hold"``.
        t: start time [s].
        duration: duration of its motion and of its offsets' changes [s] (> 0).
        pivot: (3,) world point on the tilt axis [m] (tilt).
        axis: (3,) unit world axis of the tilt (tilt).
        angle: tilt angle [rad] (right hand about ``axis``).
        displacement: (3,) world translation [m] (move).
        press: support row indices that must keep pressing; None: every row.
        release: arm names whose contacts get no planned force.
        offsets: arm name -> (3,) object-frame offset of its held points [m]; arms not named
            keep the previous phase's.
        margin: least push [N] of the arms' engaged contacts in this phase (None: the
            controller's ``margin``).
        loose: labels (``"<arm>:tip[k]"``) of contacts planned with no least push in this
            phase (they may rest without force: e.g. a gripper's tip on a side face whose
            opposite face no contact touches yet).
    """

    name: str
    kind: str
    t: float
    duration: float
    pivot: np.ndarray
    axis: np.ndarray
    angle: float
    displacement: np.ndarray
    press: tuple[int, ...] | None
    release: tuple[str, ...]
    offsets: dict
    margin: float | None = None
    loose: tuple[str, ...] = ()


def _vector(d: dict, key: str, where: str, default=None) -> np.ndarray:
    v = d.get(key, default)
    a = np.asarray(v, dtype=float) if v is not None else None
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{where}.{key}: expected 3 finite numbers, got {v!r}")
    return a


def parse_phases(phases, arm_names: list[str], n_support_rows: int,
                 contact_labels: tuple[str, ...] = ()) -> list[Phase]:
    """:class:`Phase` list from plain mappings (a scenario's ``controller.phases``).

    Raises:
        InputError: naming the phase and key, with what was expected.
    """
    if not isinstance(phases, list | tuple) or not phases:
        raise InputError(f"phased_pd phases: expected a non-empty list, got {phases!r}")
    out: list[Phase] = []
    for k, d in enumerate(phases):
        where = f"phased_pd phases[{k}]"
        if not isinstance(d, dict):
            raise InputError(f"{where}: expected a mapping, got {d!r}")
        known = {"name", "kind", "t", "duration", "pivot", "axis", "angle", "displacement",
                 "press", "release", "offsets", "margin", "loose"}
        bad = sorted(set(d) - known)
        if bad:
            raise InputError(f"{where}: unknown keys {bad}; accepted: {sorted(known)}")
        kind = d.get("kind", "hold")
        if kind not in PHASE_KINDS:
            raise InputError(f"{where}.kind: expected one of {PHASE_KINDS}, got {kind!r}")
        t = float(d.get("t", 0.0 if not out else np.nan))
        duration = float(d.get("duration", 1.0))
        if not (np.isfinite(t) and t >= 0.0) or (out and t < out[-1].t + out[-1].duration - 1e-9):
            raise InputError(f"{where}.t: expected a start time >= 0 [s] after the previous "
                             f"phase's end, got {d.get('t')!r}")
        if not (np.isfinite(duration) and duration > 0.0):
            raise InputError(f"{where}.duration: expected a time > 0 [s], got {duration!r}")
        pivot = axis = np.zeros(3)
        angle = 0.0
        disp = np.zeros(3)
        if kind == "tilt":
            pivot = _vector(d, "pivot", where)
            axis = _vector(d, "axis", where)
            if np.linalg.norm(axis) < 1e-9:
                raise InputError(f"{where}.axis: expected a nonzero vector")
            axis = axis / np.linalg.norm(axis)
            angle = float(d.get("angle", np.nan))
            if not np.isfinite(angle):
                raise InputError(f"{where}.angle: expected an angle [rad], got {d.get('angle')!r}")
        elif kind == "move":
            disp = _vector(d, "displacement", where)
        press = d.get("press")
        if press is not None:
            press = tuple(int(i) for i in press)
            if any(i < 0 or i >= n_support_rows for i in press):
                raise InputError(f"{where}.press: expected support row indices in "
                                 f"0..{n_support_rows - 1}, got {list(press)}")
        release = tuple(d.get("release", ()))
        offsets = {}
        for name, v in dict(d.get("offsets", {})).items():
            if name not in arm_names:
                raise InputError(f"{where}.offsets: unknown arm {name!r}; arms: {arm_names}")
            offsets[name] = _vector({"v": v}, "v", f"{where}.offsets.{name}")
        for name in release:
            if name not in arm_names:
                raise InputError(f"{where}.release: unknown arm {name!r}; arms: {arm_names}")
        margin = d.get("margin")
        if margin is not None:
            margin = float(margin)
            if not (np.isfinite(margin) and margin >= 0.0):
                raise InputError(f"{where}.margin: expected a force >= 0 [N], got {margin!r}")
        loose = tuple(str(x) for x in d.get("loose", ()))
        for label in loose:
            if label not in contact_labels:
                raise InputError(f"{where}.loose: unknown contact {label!r}; contacts: "
                                 f"{list(contact_labels)}")
        out.append(Phase(str(d.get("name", f"phase{k}")), kind, t, duration, pivot, axis,
                         angle, disp, press, release, offsets, margin, loose))
    return out


class PhasedPD(ObjectPD):
    """``object_pd`` through :class:`Phase` s, with the supports in its force distribution.

    Args:
        system: the system.
        phases: the phases (mappings, see :func:`parse_phases`); None: one ``hold`` phase
            (the first call's pose, every support row pressing).
        support_margin: least push [N] of every support row planned to press.
        kp, kd, margin, null_kp, null_kd, hold_kp, hold_kd: as :class:`ObjectPD`.

    The reference of phase k is its motion applied to the reference pose at the end of
    phase k - 1 (the object's pose at the first call for the first); between phases it
    holds. Torques: the desired acceleration ``a_d`` (PD on the reference), the force
    distribution with the supports on the engaged rows (touching and not released), the
    held points' tasks at their offset places, and the inverse dynamics with the planned
    support forces acting on the object
    (:func:`~multiarm_pin.dynamics.force_distribution.distribute_with_supports`).
    """

    name = "phased_pd"

    def __init__(self, system: MultiArmSystem, phases=None, support_margin: float = 1.0,
                 kp=100.0, kd=20.0, margin: float = 1.0, null_kp: float = 25.0,
                 null_kd: float = 10.0, hold_kp: float = 100.0, hold_kd: float = 20.0):
        super().__init__(system, kp=kp, kd=kd, margin=margin, null_kp=null_kp,
                         null_kd=null_kd, hold_kp=hold_kp, hold_kd=hold_kd)
        if not (np.isfinite(support_margin) and support_margin >= 0):
            raise InputError(f"phased_pd support_margin: expected a force >= 0 [N], got "
                             f"{support_margin!r}")
        self.support_margin = float(support_margin)
        self.arm_names = [a.name for a in system.arms]
        # arm rows by label: "<arm>:<contact>" -> (arm, row)
        self.rows_by_label = {lab: (b, r) for b, r, lab in system.contact_labels
                              if b < system.n_arms}
        self.phases = parse_phases([{"kind": "hold"}] if phases is None else phases,
                                   self.arm_names, system.supports.n_rows,
                                   tuple(self.rows_by_label))
        self._starts: list[tuple[np.ndarray, np.ndarray]] | None = None
        self._grasp_points: np.ndarray | None = None
        self._offset_start = np.zeros((system.n_arms, 3))
        self.last_support_mu = np.zeros(system.supports.n_rows)
        self._phase_arrays: tuple | None = None
        self._phased_inputs: tuple | None = None  # (ObjectPD's inputs, kernel_inputs())

    # ------------------------------------------------------------------ reference
    def phase_index(self, t: float) -> int:
        """Index of the phase at ``t``: the last one started (0 before the first)."""
        return int(current_phase([p.t for p in self.phases], t))

    def _phase_pose(self, p, position, rotation, s, ds, dds):
        """Pose, twist and acceleration of phase ``p`` at profile ``(s, ṡ, s̈)`` from a start."""
        if p.kind == "tilt":
            Rk = pin.exp3(p.axis * (p.angle * s))
            r0 = position - p.pivot
            r = Rk @ r0
            w = p.axis * (p.angle * ds)
            alpha = p.axis * (p.angle * dds)
            v = np.cross(w, r)
            a = np.cross(alpha, r) + np.cross(w, v)
            return p.pivot + r, Rk @ rotation, np.concatenate([v, w]), np.concatenate([a, alpha])
        if p.kind == "move":
            return (position + s * p.displacement, rotation,
                    np.concatenate([ds * p.displacement, np.zeros(3)]),
                    np.concatenate([dds * p.displacement, np.zeros(3)]))
        return position, rotation, np.zeros(6), np.zeros(6)

    def reference_pose(self, t: float) -> PoseSample:
        """The reference pose, twist and acceleration at ``t`` (after the first call)."""
        k = self.phase_index(t)
        p = self.phases[k]
        pos, rot = self._starts[k]
        if t < p.t:  # before the first phase: hold
            s, ds, dds = 0.0, 0.0, 0.0
        else:
            s, ds1, dds1 = minimum_jerk((t - p.t) / p.duration)
            ds, dds = ds1 / p.duration, dds1 / p.duration ** 2
            if t > p.t + p.duration:
                ds = dds = 0.0
        x, R, tw, acc = self._phase_pose(p, pos, rot, s, ds, dds)
        return PoseSample(x, pin.Quaternion(R).coeffs().copy(), R, tw, acc)

    def _fix_starts(self, o) -> None:
        """The phases' start poses from the object's pose ``o`` at the first call (once)."""
        if self._starts is None:
            self._starts = []
            pos, rot = np.array(o.position, dtype=float), np.array(o.rotation, dtype=float)
            for p in self.phases:
                self._starts.append((pos, rot))
                pos, rot = self._phase_pose(p, pos, rot, 1.0, 0.0, 0.0)[:2]

    def desired_acceleration(self, t: float, state: SystemState) -> np.ndarray:
        """(6,) ``a_d = a_ref + K_d (v_ref - v_o) + K_p e`` on the phases' reference."""
        o = state.obj
        self._fix_starts(o)
        ref = self.reference_pose(t)
        e = pose_error(ref.position, ref.rotation, o.position, o.rotation)
        return ref.acceleration + self.kd * (ref.twist - o.twist) + self.kp * e

    def offsets(self, t: float) -> np.ndarray:
        """(n, 3) object-frame offsets [m] of each arm's held points at ``t``."""
        now = self._offset_start.copy()
        for p in self.phases:
            if t < p.t:
                break
            s = minimum_jerk((t - p.t) / p.duration)[0]
            prev = now.copy()
            for name, v in p.offsets.items():
                i = self.arm_names.index(name)
                now[i] = prev[i] + s * (v - prev[i])
        return now

    # ------------------------------------------------------------------ torques
    def _init_hold(self, state: SystemState, evaluation: Evaluation) -> None:
        """Held points at the grasp places: an arm that starts apart starts at its offset."""
        super()._init_hold(state, evaluation)
        o = state.obj
        tools = evaluation.arms.tools
        for i, joint in enumerate(self.system.joints):
            if not joint.starts_apart:
                continue
            # the tool's offset from the grasp placement the joint was built at
            grasp = joint.tool_in_object
            tool_in_object = (o.position, o.rotation)
            p_t = tool_in_object[1].T @ (tools.position[i] - tool_in_object[0])
            self._offset_start[i] = p_t - grasp.translation
        self._grasp_points = self.hold_points_in_object - self._offset_start[:, None, :]

    def phase_arrays(self) -> tuple:
        """The phases as the compiled kernel reads them (after the first call fixed the starts).

        Returns:
            ``(phases (P, PHASE_SIZE), press (P, K) bool, release (P, n) bool, named (P, n)
            bool, offsets (P, n, 3) [m], margins (P, n, m) [N])``: the phase table
            (:data:`~multiarm_pin._compiled.layout.PHASE_FIELDS`), the support rows each
            phase keeps pressing, the arms it releases, the arms whose offsets it sets and
            those offsets (object frame), and each arm row's least push in it (0 on its
            ``loose`` rows); see :func:`~multiarm_pin._compiled.phased.phased_torques`.
        """
        if self._phase_arrays is not None:
            return self._phase_arrays
        s = self.system
        P, K, n = len(self.phases), s.supports.n_rows, s.n_arms
        table = np.zeros((P, layout.PHASE_SIZE))
        press = np.zeros((P, K), dtype=bool)
        release = np.zeros((P, n), dtype=bool)
        named = np.zeros((P, n), dtype=bool)
        offs = np.zeros((P, n, 3))
        margins = np.zeros((P, *s.unilateral.shape))
        for k, p in enumerate(self.phases):
            row = table[k]
            row[layout.PH_T], row[layout.PH_DURATION] = p.t, p.duration
            row[layout.PH_KIND] = PHASE_CODES[p.kind]
            row[layout.PH_PIVOT:layout.PH_PIVOT + 3] = p.pivot
            row[layout.PH_AXIS:layout.PH_AXIS + 3] = p.axis
            row[layout.PH_ANGLE] = p.angle
            row[layout.PH_DISPLACEMENT:layout.PH_DISPLACEMENT + 3] = p.displacement
            pos, rot = self._starts[k]
            row[layout.PH_START_POSITION:layout.PH_START_POSITION + 3] = pos
            row[layout.PH_START_ROTATION:layout.PH_START_ROTATION + 9] = np.ravel(rot)
            row[layout.PH_SUPPORT_MARGIN] = self.support_margin
            press[k, list(range(K)) if p.press is None else list(p.press)] = True
            for name in p.release:
                release[k, self.arm_names.index(name)] = True
            for name, v in p.offsets.items():
                i = self.arm_names.index(name)
                named[k, i] = True
                offs[k, i] = v
            margins[k] = self.margin if p.margin is None else p.margin
            for label in p.loose:
                margins[k][self.rows_by_label[label]] = 0.0
        arrays = tuple(np.ascontiguousarray(a) for a in
                       (table, press, release, named, offs, margins))
        for a in arrays:  # fixed once: read only (one kernel type for every caller)
            a.setflags(write=False)
        self._phase_arrays = arrays
        return arrays

    @property
    def offset_start(self) -> np.ndarray:
        """(n, 3) object-frame offsets [m] of the held points before the first phase.

        Read only; nonzero for the arms that start apart.
        """
        view = self._offset_start.view()
        view.setflags(write=False)
        return view

    def prepare(self, state: SystemState, evaluation: Evaluation) -> None:
        """:meth:`ObjectPD.prepare`, and the phases' start poses from the object's pose."""
        super().prepare(state, evaluation)
        self._fix_starts(state.obj)

    def kernel_inputs(self) -> tuple | None:
        """:meth:`ObjectPD.kernel_inputs` with the held points' grasp places (offsets not added).

        The compiled contact loop's inputs of this controller, with :meth:`phase_arrays` and
        :attr:`offset_start`; None before :meth:`prepare`.
        """
        base = super().kernel_inputs()
        if base is None or self._starts is None:
            return None
        kept = self._phased_inputs
        if kept is None or kept[0] is not base:
            kept = self._phased_inputs = (base, (*base[:4], self._grasp_points, *base[5:]))
        return kept[1]

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) torques [N m]: the compiled kernel's on a compiled evaluation, else the reference.

        Both give the same torques (to round-off); the reference decides whenever the kernel
        reports a case it cannot (see the module).
        """
        out = self.compiled_torques(t, state, evaluation)
        return self.reference(t, state, evaluation) if out is None else out

    def compiled_torques(self, t: float, state: SystemState, evaluation: Evaluation
                         ) -> np.ndarray | None:
        """(nv,) torques [N m] by :func:`~multiarm_pin._compiled.phased.phased_torques`.

        Sets :attr:`last` (an :class:`~multiarm_pin.sim.controllers.object_pd.ObjectPDPlan`
        whose ``a_o`` is the planned object acceleration), :attr:`last_support_mu`,
        :attr:`last_point_acceleration`, :attr:`margin_kept` and :attr:`holding` as
        :meth:`reference` does (not :attr:`hold_points_in_object`: the kernel adds the
        offsets itself).

        Returns:
            The torques, or None when the evaluation is not of the compiled path or the
            kernel reported a case the reference must decide.
        """
        buffer = getattr(evaluation, "buffer", None) if self.compiled else None
        if buffer is None:
            return None
        s = self.system
        self.prepare(state, evaluation)
        o = state.obj
        self._fix_starts(o)
        phases, press, release, named, offs, margins = self.phase_arrays()
        path = s.compiled
        active = getattr(evaluation, "active", None)
        active = (np.ascontiguousarray(evaluation.blocks.constraint_mask) if active is None
                  else np.ascontiguousarray(active, dtype=bool))
        st = s.support_terms(state)
        err = pin.difference(s.arm_set.model, state.q, self.q_ref)
        z = s.pad(self.null_kp * err - self.null_kd * state.v)
        kshape, mshape = self._shapes
        tau, qdd = np.empty(kshape), np.empty(kshape)
        mu = np.empty(mshape)
        lam = np.empty(s.supports.n_rows)
        a_pts = np.zeros(self.hold_points_in_tool.shape)
        a_d, a_o = np.empty(6), np.empty(6)
        obj = layout.object_state_vector(o.position, o.quaternion, o.twist)
        status, kept = phased_torques(
            float(t), buffer, path.dims, path.N, path.nv_arm, self._unilateral, active, obj,
            np.ascontiguousarray(st.G_object, dtype=float), np.ascontiguousarray(st.kappa),
            np.ascontiguousarray(st.phi), phases, press, release, named, offs, margins,
            self.offset_start, self._pd_gains, z, self.hold_points_in_tool,
            self._grasp_points, self._hold_n, self._gains, tau, mu, lam, qdd, a_pts, a_d, a_o,
            supported_distribution, planned_torques)
        if status != PD_OK:
            return None
        self.last_point_acceleration = a_pts
        self.last = ObjectPDPlan(tau, mu, qdd, a_o)
        self.last_support_mu = lam
        self.margin_kept = bool(kept)
        self.holding = False
        return s.unpad(tau)

    def reference(self, t: float, state: SystemState, evaluation: Evaluation) -> np.ndarray:
        """(nv,) torques [N m] of the current phase (see the class)."""
        s = self.system
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        if self.hold_mask is None:
            self._init_hold(state, evaluation)
        phase = self.phases[self.phase_index(t)]
        off = self.offsets(t)
        self.hold_points_in_object = self._grasp_points + np.where(
            self.hold_mask[:, :, None], off[:, None, :], 0.0)
        b = evaluation.blocks
        active = getattr(evaluation, "active", None)
        engaged = np.array(b.constraint_mask if active is None else active, dtype=bool)
        for name in phase.release:
            engaged[self.arm_names.index(name)] = False
        index = None
        unilateral = s.unilateral
        if not np.all(engaged[b.constraint_mask]):
            b, index = restrict_rows(b, engaged)
            unilateral = select_rows(s.unilateral, index)
        a_d = self.desired_acceleration(t, state)
        st = s.support_terms(state)
        press = np.zeros(s.supports.n_rows, dtype=bool)
        press[list(range(s.supports.n_rows)) if phase.press is None else list(phase.press)] = True
        press &= st.phi <= PRESSING_GAP
        sm = np.where(press, self.support_margin, np.nan)
        margin = np.full(s.unilateral.shape, self.margin if phase.margin is None
                         else phase.margin)
        for label in phase.loose:
            margin[self.rows_by_label[label]] = 0.0
        if index is not None:  # the rows kept, in the restricted blocks' order
            margin = select_rows(margin, index)
        try:
            dist = distribute_with_supports(b, a_d, unilateral, margin, st.G_object,
                                            st.kappa, sm)
            self.margin_kept = True
        except DynamicsError:
            # no forces keep the margins: pushing forces (margins 0) that make the wrench
            # closest to the desired one; the rest is left to the motion (an impact's
            # aftermath that no pushing contact can correct, until the grasp can)
            dist = distribute_with_supports(b, a_d, unilateral, 0.0, st.G_object, st.kappa,
                                            np.where(press, 0.0, np.nan), best_effort=True)
            self.margin_kept = False
        self.last_support_mu = dist.support_mu
        qdd_desired = self.joint_accelerations(state, evaluation, dist.a_o)
        fd = dist.forces
        # the supports act on the object like an external wrench: h_o + Σ λ_k G_kᵀ, which
        # the distribution made equal to M_o a_o - W_o μ (to round-off); written as the
        # latter, the arms' wrench is not a difference of weight-sized terms (it vanishes
        # when the supports carry the object)
        on_object = b.replaced(h_o=b.M_o @ dist.a_o - b.stacked_W_o() @ fd.mu_flat)
        try:
            last = inverse_dynamics(on_object, dist.a_o, qdd_desired, fd.mu_I, fd.basis)
        except DynamicsError as exc:
            return self._hold_still(t, state, evaluation.blocks,
                                    f"no inverse dynamics on the engaged contacts ({exc})")
        if index is not None:
            last = InverseDynamicsResult(last.tau, expand_rows(last.mu, index), last.qdd,
                                         last.a_o, last.mu_I, last.basis)
        self.last = last
        self.holding = False
        return s.unpad(last.tau)


__all__ = ["PHASE_CODES", "PHASE_KINDS", "Phase", "PhasedPD", "current_phase", "parse_phases"]
