"""Result plots of a run (matplotlib, Agg backend: PNG files, no display needed).

Every function takes plain arrays (as stored in ``trajectory.npz``) and writes one PNG.
Units: time [s], positions [m], orientation as a rotation vector [rad], forces [N],
gaps [m].
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

from multiarm_pin.app.replay_phases import phase_table  # noqa: E402
from multiarm_pin.exceptions import InputError  # noqa: E402
from multiarm_pin.spatial import as_array, quaternion_to_rotation  # noqa: E402

DPI = 110


def rotation_vectors(quaternions: np.ndarray) -> np.ndarray:
    """(T, 3) rotation vectors ``log3(R)`` [rad] of (T, 4) quaternions ``[x, y, z, w]``.

    Consecutive vectors are kept continuous (no jump of 2π at |θ| = π) by choosing, at each
    sample, the equivalent vector nearest to the previous one.
    """
    quats = as_array(quaternions, (None, 4), "quaternions (T, 4) [x, y, z, w]")
    out = np.zeros((len(quats), 3))
    for k, q in enumerate(quats):
        r = pin.log3(quaternion_to_rotation(q / np.linalg.norm(q)))
        if k > 0:
            theta = np.linalg.norm(r)
            if theta > 1e-9:
                axis = r / theta
                alt = r - 2 * np.pi * axis
                if np.linalg.norm(alt - out[k - 1]) < np.linalg.norm(r - out[k - 1]):
                    r = alt
        out[k] = r
    return out


def _save(fig, path) -> Path:
    path = Path(path)
    if not path.parent.is_dir():
        plt.close(fig)
        raise InputError(f"plot: folder {path.parent} does not exist")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _times(t) -> np.ndarray:
    t = as_array(t, (None,), "t (T,) [s]")
    if len(t) < 1:
        raise InputError("t: needs at least one sample")
    return t


def plot_object_pose(path, t, position, quaternion, title: str = "") -> Path:
    """Object COM position and orientation (rotation vector) against time.

    Args:
        path: PNG file to write.
        t: (T,) times [s].
        position: (T, 3) COM in the world [m].
        quaternion: (T, 4) orientation ``[x, y, z, w]``.
        title: figure title.

    Returns:
        The path written.
    """
    t = _times(t)
    p = as_array(position, (len(t), 3), "object position (T, 3)")
    r = rotation_vectors(as_array(quaternion, (len(t), 4), "object quaternion (T, 4)"))
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    for k, lab in enumerate("xyz"):
        a1.plot(t, p[:, k], label=lab)
        a2.plot(t, r[:, k], label=f"θ{lab}")
    a1.set_ylabel("COM position [m]")
    a2.set_ylabel("rotation vector [rad]")
    a2.set_xlabel("time [s]")
    a1.legend(loc="best")
    a2.legend(loc="best")
    a1.grid(alpha=0.3)
    a2.grid(alpha=0.3)
    a1.set_title(title or "object pose")
    return _save(fig, path)


EVENT_STYLE = {"separation": ("tab:red", "--"), "touchdown": ("tab:green", ":"),
               "off_edge": ("tab:orange", "-.")}
"""Colour and line style of the vertical lines marking contact events."""


def _mark_events(ax, events) -> None:
    for te, kind in {(float(te), str(kind)) for te, kind in events}:
        color, style = EVENT_STYLE.get(kind, ("k", "-."))
        ax.axvline(te, color=color, ls=style, lw=0.8, alpha=0.7)


def plot_contact_forces(path, t, mu: Mapping[str, np.ndarray], title: str = "",
                        events=(), labels: Mapping[str, Sequence[str]] | None = None) -> Path:
    """Contact multipliers (forces, positive = pushing) of each arm or support against time.

    Args:
        path: PNG file.
        t: (T,) times [s].
        mu: arm or support name -> (T, N_A) multipliers [N].
        title: figure title.
        events: ``[(t, kind), ...]`` contact events (``separation`` red dashed,
            ``touchdown`` green dotted, ``off_edge`` orange dash-dotted vertical lines).
        labels: optional name -> (N_A,) contact names for the legend (the events' and
            warnings' ``"<arm>:<contact>"`` / ``"<support>[point]"``); row indices otherwise.
    """
    t = _times(t)
    if not mu:
        raise InputError("plot_contact_forces: no arms given")
    labels = labels or {}
    n = len(mu)
    fig, axes = plt.subplots(n, 1, figsize=(7, 2.2 + 1.8 * n), sharex=True, squeeze=False)
    for ax, (name, m) in zip(axes[:, 0], mu.items(), strict=True):
        m = as_array(m, (len(t), None), f"mu_{name} (T, N)")
        names = list(labels.get(name, ()))
        if len(names) != m.shape[1]:
            names = [str(k) for k in range(m.shape[1])]
        for k in range(m.shape[1]):
            ax.plot(t, m[:, k], lw=1.0, label=names[k])
        ax.axhline(0.0, color="k", lw=0.6)
        _mark_events(ax, events)
        ax.set_ylabel(f"{name}: μ [N]")
        ax.grid(alpha=0.3)
        if 0 < m.shape[1] <= 8:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
                      title="contact", title_fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(title or "contact forces (positive = pushing)")
    return _save(fig, path)


PHASE_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown",
                "tab:pink", "tab:olive", "tab:cyan")
"""Colours of the phases' bands in ``contact_states.png``, in turn."""


def plot_contact_states(path, t, active, labels, events=(), title: str = "",
                        phases=()) -> Path:
    """Each contact's state against time: a bar where it touches, a gap where it is separated.

    Args:
        path: PNG file.
        t: (T,) times [s].
        active: (T, K) bool, True where contact k touches (active set, or bilateral).
        labels: (K,) contact names (``arm:contact`` or ``support[j]``).
        events: ``[(t, kind, k), ...]`` events with the contact index, drawn as markers
            (red x: separation, green o: touchdown, orange x: off the edge of a support).
        title: figure title.
        phases: the task's phases (:class:`~multiarm_pin.app.replay_phases.ReplayPhase`,
            a ``phased_pd`` run's): a band per phase behind the bars (darker while its
            motion runs), named above the plot.
    """
    t = _times(t)
    act = np.asarray(active, dtype=bool)
    if act.ndim != 2 or act.shape[0] != len(t) or act.shape[1] != len(labels):
        raise InputError(f"plot_contact_states: active must be (T, K) = ({len(t)}, "
                         f"{len(labels)}), got {act.shape}")
    K = act.shape[1]
    fig, ax = plt.subplots(figsize=(7, 1.6 + 0.28 * max(K, 1) + (0.3 if phases else 0.0)))
    for i, p in enumerate(phase_table(phases, float(t[-1]))):
        color = PHASE_COLORS[i % len(PHASE_COLORS)]
        ax.axvspan(p["t"], p["end"], color=color, alpha=0.08, lw=0)
        if p["motion_end"] > p["t"]:
            ax.axvspan(p["t"], p["motion_end"], color=color, alpha=0.12, lw=0)
        ax.text(0.5 * (p["t"] + p["end"]), 1.0, p["name"], transform=ax.get_xaxis_transform(),
                ha="center", va="bottom", fontsize=6, color=color, clip_on=False)
    for k in range(K):
        y = np.where(act[:, k], k, np.nan)
        ax.plot(t, y, lw=5, solid_capstyle="butt", color="tab:blue")
    for te, kind, k in events:
        color = EVENT_STYLE.get(str(kind), ("k", "-"))[0]
        ax.plot([te], [k], "o" if kind == "touchdown" else "x", color=color, ms=6,
                mfc="none")
    ax.set_yticks(range(K))
    ax.set_yticklabels([str(x) for x in labels], fontsize=7)
    ax.set_ylim(-0.7, K - 0.3)
    ax.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3, axis="x")
    ax.set_title(title or "contacts: touching (bar), separated (gap); "
                 "x separation or off edge, o touchdown", pad=14 if phases else 6)
    return _save(fig, path)


def plot_constraint_violation(path, t, violation, title: str = "") -> Path:
    """``max |φ|`` over all contacts against time, log scale.

    Args:
        path: PNG file.
        t: (T,) times [s].
        violation: (T,) [m].
        title: figure title.
    """
    t = _times(t)
    v = as_array(violation, (len(t),), "constraint violation (T,)")
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.semilogy(t, np.maximum(np.abs(v), 1e-16))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("max |φ| [m]")
    ax.grid(alpha=0.3, which="both")
    ax.set_title(title or "constraint violation")
    return _save(fig, path)


def plot_arm_wrenches(path, t, wrench: Mapping[str, np.ndarray], title: str = "",
                      events=()) -> Path:
    """Each arm's wrench on the object against time: force and moment at the COM, world axes.

    Args:
        path: PNG file.
        t: (T,) times [s].
        wrench: arm name -> (T, 6) ``[f; m]`` [N, N m], the moment about the object's COM.
        title: figure title.
        events: ``[(t, kind), ...]`` contact events, drawn as vertical lines.
    """
    t = _times(t)
    if not wrench:
        raise InputError("plot_arm_wrenches: no arms given")
    n = len(wrench)
    fig, axes = plt.subplots(n, 2, figsize=(10, 2.2 + 1.8 * n), sharex=True, squeeze=False)
    for row, (name, w) in zip(axes, wrench.items(), strict=True):
        w = as_array(w, (len(t), 6), f"arm_wrench {name} (T, 6)")
        for ax, part, unit in ((row[0], slice(0, 3), "f [N]"), (row[1], slice(3, 6), "m [N m]")):
            for axis, k in zip("xyz", range(part.start, part.stop), strict=True):
                ax.plot(t, w[:, k], lw=1.0, label=axis)
            ax.axhline(0.0, color="k", lw=0.6)
            _mark_events(ax, events)
            ax.set_ylabel(f"{name}: {unit}")
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=7, ncol=3)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(title or "each arm's wrench on the object (world axes, at the COM)")
    return _save(fig, path)


def plot_torque_ratios(path, t, tau: Mapping[str, np.ndarray],
                       limits: Mapping[str, np.ndarray], joint_names=None,
                       title: str = "") -> Path:
    """Each joint's ``|τ| / τ_max`` against time, with the limit (1) drawn and excess marked.

    Args:
        path: PNG file.
        t: (T,) times [s].
        tau: arm name -> (T, nv) joint torques [N m].
        limits: arm name -> (nv,) effort limits [N m] (``inf`` or 0: none, not drawn).
        joint_names: optional arm name -> joint names (legend).
        title: figure title.
    """
    t = _times(t)
    if not tau:
        raise InputError("plot_torque_ratios: no arms given")
    n = len(tau)
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.2 + 1.8 * n), sharex=True, squeeze=False)
    for ax, (name, tq) in zip(axes[:, 0], tau.items(), strict=True):
        tq = as_array(tq, (len(t), None), f"tau_{name} (T, nv)")
        lim = np.asarray(limits[name], dtype=float).reshape(-1)
        names = list((joint_names or {}).get(name, [])) or [str(j) for j in range(tq.shape[1])]
        for j in range(tq.shape[1]):
            if not (np.isfinite(lim[j]) and lim[j] > 0):
                continue
            ratio = np.abs(tq[:, j]) / lim[j]
            (line,) = ax.plot(t, ratio, lw=1.0, label=names[j])
            over = ratio > 1.0
            if over.any():
                ax.plot(t[over], ratio[over], "x", ms=3, color=line.get_color())
        ax.axhline(1.0, color="tab:red", lw=1.0, ls="--", label="limit")
        ax.set_ylabel(f"{name}: |τ| / τ_max")
        ax.set_ylim(0.0, max(1.1, 1.05 * ax.get_ylim()[1]))
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(title or "joint torques against their URDF effort limits (x: over)")
    return _save(fig, path)


def write_plots(out_dir, trajectory: Mapping[str, np.ndarray], arm_names, title: str = "",
                support_names=(), phases=()) -> list[Path]:
    """All standard plots of a run from its ``trajectory.npz`` arrays.

    Args:
        out_dir: existing folder.
        trajectory: mapping with ``t``, ``object_position``, ``object_quaternion``,
            ``constraint_violation`` and ``mu_<name>`` for each arm and support; optionally
            ``contact_active``, ``contact_labels``, ``event_t``, ``event_kind``,
            ``event_contact`` (contact events).
        arm_names: the arms' names.
        title: scenario name, prefixed to the titles.
        support_names: the supports' names.
        phases: a ``phased_pd`` run's phases
            (:func:`~multiarm_pin.app.replay_phases.replay_phases`): bands in
            ``contact_states.png``.

    With ``arm_wrench`` (T, n_arms, 6) it also writes ``arm_wrenches.png``, each arm's wrench
    on the object; then ``contact_forces.png`` shows only the arms with unilateral rows
    (fingertips) and the supports, whose multipliers are forces at named points (a weld's six
    rows are not: its wrench says what it does), and is left out when there are none. With
    ``tau_<arm>`` and ``tau_limit_<arm>`` (nv,) for every arm it writes ``joint_torques.png``,
    the torques as ratios of their limits.

    Returns:
        The PNG files written: ``object_pose.png``, ``contact_forces.png``,
        ``constraint_violation.png``, ``contact_states.png`` when the run has contact
        events or supports, ``arm_wrenches.png`` and ``joint_torques.png``.
    """
    out = Path(out_dir)
    pre = f"{title}: " if title else ""
    t = trajectory["t"]
    ev_t = np.asarray(trajectory.get("event_t", np.zeros(0)), dtype=float)
    ev_kind = np.asarray(trajectory.get("event_kind", np.zeros(0, dtype=str)))
    ev_k = np.asarray(trajectory.get("event_contact", np.zeros(0, dtype=int)))
    events = list(zip(ev_t.tolist(), ev_kind.tolist(), strict=True))
    from multiarm_pin.app.run_results import force_names, plot_names  # one list of files

    wanted = plot_names(trajectory, support_names, arm_names)
    written = []
    if "contact_states.png" in wanted:
        written.append(plot_contact_states(
            out / "contact_states.png", t, trajectory["contact_active"],
            trajectory["contact_labels"],
            list(zip(ev_t.tolist(), ev_kind.tolist(), ev_k.tolist(), strict=True)),
            pre + "contacts touching (bars); x separation or off edge, o touchdown", phases))
    if "arm_wrenches.png" in wanted:
        w = np.asarray(trajectory["arm_wrench"])
        written.append(plot_arm_wrenches(
            out / "arm_wrenches.png", t, {a: w[:, i] for i, a in enumerate(arm_names)},
            pre + "each arm's wrench on the object (world axes, at the COM)", events))
    if "joint_torques.png" in wanted:
        written.append(plot_torque_ratios(
            out / "joint_torques.png", t, {a: trajectory[f"tau_{a}"] for a in arm_names},
            {a: trajectory[f"tau_limit_{a}"] for a in arm_names},
            {a: trajectory[f"joint_names_{a}"] for a in arm_names
             if f"joint_names_{a}" in trajectory},
            title=pre + "joint torques / URDF effort limits (x: over the limit)"))
    written.append(plot_object_pose(out / "object_pose.png", t, trajectory["object_position"],
                                    trajectory["object_quaternion"], pre + "object pose"))
    if "contact_forces.png" in wanted:
        forces = force_names(trajectory, arm_names, support_names)
        every = [str(x) for x in np.asarray(trajectory.get("contact_labels", []), dtype=str)]
        legend = {a: [x for x in every if x.startswith((f"{a}:", f"{a}["))] for a in forces}
        written.append(plot_contact_forces(out / "contact_forces.png", t,
                                           {a: trajectory[f"mu_{a}"] for a in forces},
                                           pre + "contact forces (positive = pushing)", events,
                                           legend))
    written.append(plot_constraint_violation(out / "constraint_violation.png", t,
                                             trajectory["constraint_violation"],
                                             pre + "constraint violation"))
    return written


__all__ = [
    "EVENT_STYLE",
    "plot_arm_wrenches",
    "plot_torque_ratios",
    "plot_constraint_violation",
    "plot_contact_states",
    "plot_contact_forces",
    "plot_object_pose",
    "rotation_vectors",
    "write_plots",
]
