"""Result plots of a run (matplotlib, Agg backend: PNG files, no display needed).

Every function takes plain arrays (as stored in ``trajectory.npz``) and writes one PNG.
Units: time [s], positions [m], orientation as a rotation vector [rad], forces [N],
gaps [m].
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

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


EVENT_STYLE = {"separation": ("tab:red", "--"), "touchdown": ("tab:green", ":")}
"""Colour and line style of the vertical lines marking contact events."""


def _mark_events(ax, events) -> None:
    for te, kind in {(float(te), str(kind)) for te, kind in events}:
        color, style = EVENT_STYLE.get(kind, ("k", "-."))
        ax.axvline(te, color=color, ls=style, lw=0.8, alpha=0.7)


def plot_contact_forces(path, t, mu: Mapping[str, np.ndarray], title: str = "",
                        events=()) -> Path:
    """Contact multipliers (forces, positive = pushing) of each arm or support against time.

    Args:
        path: PNG file.
        t: (T,) times [s].
        mu: arm or support name -> (T, N_A) multipliers [N].
        title: figure title.
        events: ``[(t, kind), ...]`` contact events (``separation`` red dashed,
            ``touchdown`` green dotted vertical lines).
    """
    t = _times(t)
    if not mu:
        raise InputError("plot_contact_forces: no arms given")
    n = len(mu)
    fig, axes = plt.subplots(n, 1, figsize=(7, 2.2 + 1.8 * n), sharex=True, squeeze=False)
    for ax, (name, m) in zip(axes[:, 0], mu.items(), strict=True):
        m = as_array(m, (len(t), None), f"mu_{name} (T, N)")
        for k in range(m.shape[1]):
            ax.plot(t, m[:, k], lw=1.0, label=f"{k}")
        ax.axhline(0.0, color="k", lw=0.6)
        _mark_events(ax, events)
        ax.set_ylabel(f"{name}: μ [N]")
        ax.grid(alpha=0.3)
        if 0 < m.shape[1] <= 8:
            ax.legend(loc="upper right", fontsize=7, ncol=m.shape[1], title="contact",
                      title_fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(title or "contact forces (positive = pushing)")
    return _save(fig, path)


def plot_contact_states(path, t, active, labels, events=(), title: str = "") -> Path:
    """Each contact's state against time: a bar where it touches, a gap where it is separated.

    Args:
        path: PNG file.
        t: (T,) times [s].
        active: (T, K) bool, True where contact k touches (active set, or bilateral).
        labels: (K,) contact names (``arm:contact`` or ``support[j]``).
        events: ``[(t, kind, k), ...]`` events with the contact index, drawn as markers
            (red x: separation, green o: touchdown).
        title: figure title.
    """
    t = _times(t)
    act = np.asarray(active, dtype=bool)
    if act.ndim != 2 or act.shape[0] != len(t) or act.shape[1] != len(labels):
        raise InputError(f"plot_contact_states: active must be (T, K) = ({len(t)}, "
                         f"{len(labels)}), got {act.shape}")
    K = act.shape[1]
    fig, ax = plt.subplots(figsize=(7, 1.6 + 0.28 * max(K, 1)))
    for k in range(K):
        y = np.where(act[:, k], k, np.nan)
        ax.plot(t, y, lw=5, solid_capstyle="butt", color="tab:blue")
    for te, kind, k in events:
        color = EVENT_STYLE.get(str(kind), ("k", "-"))[0]
        ax.plot([te], [k], "x" if kind == "separation" else "o", color=color, ms=6,
                mfc="none")
    ax.set_yticks(range(K))
    ax.set_yticklabels([str(x) for x in labels], fontsize=7)
    ax.set_ylim(-0.7, K - 0.3)
    ax.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
    ax.set_xlabel("time [s]")
    ax.grid(alpha=0.3, axis="x")
    ax.set_title(title or "contacts: touching (bar), separated (gap); x separation, o touchdown")
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


def write_plots(out_dir, trajectory: Mapping[str, np.ndarray], arm_names, title: str = "",
                support_names=()) -> list[Path]:
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

    Returns:
        The PNG files written: ``object_pose.png``, ``contact_forces.png``,
        ``constraint_violation.png``, and ``contact_states.png`` when the run has contact
        events or supports.
    """
    out = Path(out_dir)
    pre = f"{title}: " if title else ""
    t = trajectory["t"]
    names = [*arm_names, *support_names]
    ev_t = np.asarray(trajectory.get("event_t", np.zeros(0)), dtype=float)
    ev_kind = np.asarray(trajectory.get("event_kind", np.zeros(0, dtype=str)))
    ev_k = np.asarray(trajectory.get("event_contact", np.zeros(0, dtype=int)))
    events = list(zip(ev_t.tolist(), ev_kind.tolist(), strict=True))
    extra = []
    from multiarm_pin.app.run_results import plot_names  # the one list of a run's files

    if "contact_states.png" in plot_names(trajectory, support_names):
        extra.append(plot_contact_states(
            out / "contact_states.png", t, trajectory["contact_active"],
            trajectory["contact_labels"],
            list(zip(ev_t.tolist(), ev_kind.tolist(), ev_k.tolist(), strict=True)),
            pre + "contacts touching (bars); x separation, o touchdown"))
    return extra + [
        plot_object_pose(out / "object_pose.png", t, trajectory["object_position"],
                         trajectory["object_quaternion"], pre + "object pose"),
        plot_contact_forces(out / "contact_forces.png", t,
                            {a: trajectory[f"mu_{a}"] for a in names},
                            pre + "contact forces (positive = pushing)", events),
        plot_constraint_violation(out / "constraint_violation.png", t,
                                  trajectory["constraint_violation"],
                                  pre + "constraint violation"),
    ]


__all__ = [
    "EVENT_STYLE",
    "plot_constraint_violation",
    "plot_contact_states",
    "plot_contact_forces",
    "plot_object_pose",
    "rotation_vectors",
    "write_plots",
]
