"""Exception hierarchy of multiarm_pin.

Every error raised on purpose by the package derives from :class:`MultiArmError`, so a
caller can catch them all at once. Exceptions carry the data a user needs to fix the
input (valid names, the shape that was expected, the gap that was measured).
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence

import numpy as np


class MultiArmError(Exception):
    """Root of every error raised on purpose by multiarm_pin."""


class InputError(MultiArmError, ValueError):
    """An argument has the wrong shape, type or value (e.g. a non-unit quaternion)."""


class RobotNotFoundError(MultiArmError, KeyError):
    """A robot name is not known.

    Attributes:
        name: the name that was asked for.
        available: the names that would have worked.
    """

    def __init__(self, name: str, available: Sequence[str]):
        self.name = name
        self.available = sorted(available)
        close = difflib.get_close_matches(name, self.available, n=1) if isinstance(name, str) \
            else []
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        super().__init__(
            f"unknown robot {name!r}{hint}; available robots: {', '.join(self.available)}")

    def __str__(self) -> str:  # KeyError would otherwise quote the message
        return str(self.args[0])


class URDFError(MultiArmError):
    """A URDF file cannot be read or is not a valid robot description.

    Attributes:
        path: the file.
    """

    def __init__(self, path: str, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


class FrameNotFoundError(MultiArmError, KeyError):
    """A frame name does not exist in a model.

    Attributes:
        frame: the missing frame name.
        available: the frame names the model has.
        source: where the model came from (URDF path or robot name).
    """

    def __init__(self, frame: str, available: Sequence[str], source: str = ""):
        self.frame = frame
        self.available = list(available)
        self.source = source
        where = f" in {source}" if source else ""
        super().__init__(
            f"frame {frame!r} not found{where}; frames available: {', '.join(self.available)}"
        )

    def __str__(self) -> str:
        return str(self.args[0])


class SingularityError(MultiArmError, ArithmeticError):
    """A quantity that needs an invertible matrix was asked for at a singularity.

    Attributes:
        what: the matrix that is singular (e.g. ``"J M^-1 J^T"``).
        condition: its condition number (``inf`` when exactly singular).
    """

    def __init__(self, what: str, condition: float, hint: str = ""):
        self.what = what
        self.condition = float(condition)
        msg = f"{what} is singular or badly conditioned (condition number {condition:.3g})"
        if hint:
            msg += f": {hint}"
        super().__init__(msg)


class GraspError(MultiArmError, ValueError):
    """A grasp or contact definition is invalid (point off its face, bad face index...)."""


class ConstraintError(MultiArmError, ValueError):
    """A joint or contact definition is invalid or violated beyond tolerance."""


class InitialGapError(ConstraintError):
    """An initial state leaves a contact open (or penetrating) beyond the tolerance.

    Attributes:
        arm: index of the arm whose joint is violated, or None (a support, or a joint alone).
        support: index of the penetrated support, or None (a joint).
        contact: the contact's index in its joint, or the point's index in its support.
        gap: the contact's gap φ [m] (negative: penetration).
        tol: the tolerance it exceeds [m].
    """

    def __init__(self, message: str, *, arm: int | None = None, support: int | None = None,
                 contact: int = 0, gap: float = 0.0, tol: float = 0.0):
        super().__init__(message)
        self.arm, self.support, self.contact = arm, support, contact
        self.gap, self.tol = float(gap), float(tol)


class DynamicsError(MultiArmError, ArithmeticError):
    """The equations of motion have no solution, or the state is invalid (NaN, inconsistent)."""


class RunStoppedError(MultiArmError):
    """A run ended at the first violation a monitor of its ``stop`` policies found.

    Raised by :func:`~multiarm_pin.sim.simulation.simulate` (``monitors=``) as soon as the
    stretch of samples holding the violation has been recorded; its ``partial_result``
    (:func:`~multiarm_pin.sim.simulation.partial_result`) ends at that sample.

    Attributes:
        monitor: the name of the monitor that stopped it (``"limits.collision"``...).
        sample: the index of the violating sample (the last one kept).
        t: its time [s].
    """

    def __init__(self, message: str, monitor: str, sample: int, t: float):
        self.monitor, self.sample, self.t = monitor, int(sample), float(t)
        super().__init__(message)


class ScenarioError(MultiArmError, ValueError):
    """A scenario file is invalid.

    Attributes:
        file: the scenario file.
        key: the key path, e.g. ``"arms[1].joint.type"``.
        line, column: 1-based position in the file (a YAML syntax error), or None; the
            message then starts ``file:line:column:``.
    """

    def __init__(self, file: str, key: str, message: str, line: int | None = None,
                 column: int | None = None):
        self.file = str(file)
        self.key = key
        self.message = message
        self.line, self.column = line, column
        where = self.file if line is None else f"{self.file}:{line}:{column}"
        super().__init__(f"{where}: {key}: {message}" if key else f"{where}: {message}")


class OutputError(MultiArmError, OSError):
    """The results folder cannot be used (a file, another run's results, not writable...)."""


class ResultsNotMovedError(OutputError):
    """A run's results were written but could not be moved into the results folder.

    Attributes:
        kept: the folder where they were written and are kept.
    """

    def __init__(self, message: str, kept):
        self.kept = kept
        super().__init__(message)


class RunFailedError(MultiArmError):
    """A run failed after its simulation had started; what it simulated was written.

    Attributes:
        t_end: the last simulated time [s] kept in the partial results.
        out_dir: the results folder holding the partial run (None if nothing was written).
        reason: the message of the error that stopped the simulation.
    """

    def __init__(self, message: str, t_end: float | None, out_dir=None, reason: str = ""):
        self.t_end = t_end
        self.out_dir = out_dir
        self.reason = reason or message
        super().__init__(message)


class RunInterrupted(KeyboardInterrupt):  # noqa: N818 (a KeyboardInterrupt, not an error)
    """A run was interrupted (Ctrl-C or SIGTERM); what it simulated was written.

    Attributes:
        t_end: the last simulated time [s] kept (None if the simulation had not started).
        out_dir: the results folder holding the partial run (None if nothing was written).
        signal_name: ``"SIGINT"`` or ``"SIGTERM"``.
    """

    def __init__(self, message: str, t_end: float | None = None, out_dir=None,
                 signal_name: str = "SIGINT"):
        self.t_end = t_end
        self.out_dir = out_dir
        self.signal_name = signal_name
        super().__init__(message)


class JointNotFoundError(MultiArmError, KeyError):
    """Joint names (e.g. ``locked_joints``) that a model does not have.

    Attributes:
        joints: the missing names.
        available: the model's joint names.
        source: where the model came from.
    """

    def __init__(self, joints: Sequence[str], available: Sequence[str], source: str = ""):
        self.joints = list(joints)
        self.available = list(available)
        self.source = source
        where = f" in {source}" if source else ""
        super().__init__(f"joints {self.joints} not found{where}; joints: "
                         f"{', '.join(self.available)}")

    def __str__(self) -> str:
        return str(self.args[0])


class UnsupportedJointError(MultiArmError, ValueError):
    """A model has a joint type that the compiled rigid-body pass does not support.

    Attributes:
        joint: name of the (first) unsupported joint.
        joint_type: its Pinocchio type (``shortname()``, e.g. ``"JointModelSpherical"``).
        joints: names of every unsupported joint of the model.
    """

    def __init__(self, joint: str, joint_type: str, joints: Sequence[str] = ()):
        self.joint = joint
        self.joint_type = joint_type
        self.joints = list(joints) or [joint]
        others = f" (unsupported joints: {', '.join(self.joints)})" if len(self.joints) > 1 \
            else ""
        super().__init__(
            f"joint {joint!r} is a {joint_type}, which the compiled rigid-body pass does not "
            "support (revolute, prismatic and continuous joints about x, y, z or any axis "
            f"only){others}: use Pinocchio's path for this model")


class UnsupportedSolverError(InputError):
    """A forward-dynamics solver was named for rows it cannot serve (it is never replaced).

    Attributes:
        solver: the solver's name.
        rows: labels of the rows it cannot serve (``"<arm>:<contact>"``, ``"<support>[j]"``).
        serving: the solvers that serve them.
    """

    def __init__(self, solver: str, rows: Sequence[str], serving: Sequence[str]):
        self.solver = solver
        self.rows = list(rows)
        self.serving = list(serving)
        shown = ", ".join(self.rows[:6]) + (f" and {len(self.rows) - 6} more"
                                            if len(self.rows) > 6 else "")
        super().__init__(
            f"solver {solver!r} cannot serve the unilateral rows of this system ({shown}): it "
            "holds every row as an equality, where a unilateral row may push only and "
            f"separate; name one of {', '.join(self.serving)}")

    def __reduce__(self):
        return type(self), (self.solver, self.rows, self.serving)


class UnreachableError(MultiArmError, ValueError):
    """Inverse kinematics found no configuration meeting the targets (out of reach).

    Attributes:
        residual: the norm of the primary residual left at the best configuration found
            [m for points/planes; mixed m and rad for poses].
        q: (nq,) that best configuration.
        details: a per-target description of what is left.
    """

    def __init__(self, what: str, residual: float, q: np.ndarray, details: str = ""):
        self.residual = float(residual)
        self.q = np.asarray(q, float).copy()
        self.details = details
        msg = (
            f"{what}: out of reach, inverse kinematics left a residual of {self.residual:.3g} "
            "(tolerance met nowhere from the seed and its perturbations)"
        )
        if details:
            msg += f"; {details}"
        super().__init__(msg)


class StudyError(ScenarioError):
    """A study file (``multiarm-pin sweep``), or the way it is run, is invalid.

    Attributes:
        file: the study file (or the results folder).
        key: the key path, e.g. ``"parameters[1].normal.sigma"``, or the option.
    """


class DesignError(ScenarioError):
    """A design spec file (``multiarm-pin design``) is invalid.

    Attributes:
        file: the spec file.
        key: the key path, e.g. ``"bases.region.x"``.
    """


class DesignImpossibleError(MultiArmError):
    """No candidate of a design search met every condition (``multiarm-pin design``: exit 1).

    Attributes:
        condition: the condition that the candidates which got furthest failed (``reach``,
            ``path``, ``collision``, ``torque``, ``closure``).
        best: the best value of that condition any candidate reached (its unit in the
            message).
        message: the sentence for people, naming the condition and the best value.
    """

    def __init__(self, condition: str, best: float, message: str):
        self.condition, self.best, self.message = condition, float(best), message
        super().__init__(message)
