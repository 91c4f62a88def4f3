"""Contact events of a simulation: the active set of unilateral rows, separations, touchdowns.

Integration scheme (event-driven; see docs/ARCHITECTURE.md, "Unilateral contacts"):

- Between events the smooth integrator (``rk4`` or ``semi_implicit``) runs with the *active
  set* fixed during a step. Every evaluation solves the mixed LCP of part S
  (:func:`multiarm_pin.dynamics.unilateral.solve_unilateral`) on the active rows: bilateral
  rows ``φ̈ = 0``, active unilateral rows ``0 <= μ ⟂ φ̈ >= 0`` (with Baumgarte terms, which
  therefore act on active rows only); inactive rows have ``μ = 0``.
- **Separation**: an active unilateral row that pushes at a step's start (``μ > 0``) and
  at its end has ``μ = 0`` and lifts (``φ̈ > SEPARATION_ACCELERATION``) separated inside
  the step. Its time is where the multiplier ``μ_k(t)`` of the current active set reaches
  zero and the row starts to lift (the sign of ``-φ̈_k`` of force-free lifting rows, else
  of the rows' total force), located by the Illinois method on ``θ ∈ [0, 1]`` of the step,
  re-integrating from the step's start with step ``θ h`` and the active set unchanged,
  to a bracket shorter than ``SEPARATION_TIME_TOLERANCE``; the step is split there (a
  touchdown located before it is handled first), the row leaves the active set (event
  ``"separation"`` at that time) and the step is finished with the new active set. In
  addition, at the start of every step (and after every impact or separation), an active
  unilateral row whose solution has ``μ = 0`` and ``φ̈ > SEPARATION_ACCELERATION``, or
  whose gap exceeds ``SEPARATION_GAP`` or gap rate ``SEPARATION_SPEED``, leaves the active
  set at that time (rows that let go at t = 0, after an impact, or whose multiplier was
  already 0 at the step's start).
- **Touchdown**: after every step, an inactive unilateral row whose gap fell below
  ``-GAP_TOLERANCE`` has touched down inside the step (only rows that started the step
  above ``-LOST_GAP``: gaps are distances to the contact surface extended to infinity, so
  a separated fingertip that goes round an edge of its face gets a negative gap without
  touching anything; such a row is ignored until its gap is back above ``-LOST_GAP``).
  A row that starts the step inside or just below the band and closes is hit at once. The time is
  located by the Illinois (modified regula falsi) method on ``θ ∈ [0, 1]`` of the step,
  re-integrating from the step's start with step ``θ h``, until the smallest such gap lies
  in ``[-GAP_TOLERANCE, 0]`` (or the bracket is below ``TIME_TOLERANCE``). There the impact
  law of part S
  (:func:`~multiarm_pin.dynamics.unilateral.solve_impact`, ``0 <= P ⟂ φ̇⁺ + e φ̇⁻ >= 0`` on
  the active and touching unilateral rows, ``φ̇⁺ = 0`` on bilateral rows) changes the
  velocities; a touching row that leaves with ``φ̇⁺ > REBOUND_SPEED`` rebounds and stays
  inactive, the others join the active set (event ``"touchdown"``); an active row that the
  impact makes leave separates. Impacts slower than ``RESTING_SPEED`` are plastic
  (``e = 0``), and a row that would leave slower than ``RESTING_SPEED`` is *captured*: the
  impact is solved again with it held at ``φ̇⁺ = 0`` (as a bilateral row, so its impulse may
  be slightly negative, of order ``m RESTING_SPEED``). So a bouncing body, or fingertips
  knocking each other off through the object, come to rest after finitely many events
  instead of an infinite (Zeno) sequence, and no active row ever has ``φ̇ > 0`` (the
  acceleration-level complementarity, with its Baumgarte terms, is only right for rows at
  ``φ ≈ 0``, ``φ̇ ≈ 0``). The step is then finished from the event time with the new
  active set.

- **Off the edge**: a support with an ``extent`` is a rectangle of its plane
  (:class:`~multiarm_pin.constraints.Support`). An active row of such a support whose
  point's in-plane position leaves the rectangle (its edge margin, positive inside,
  :meth:`~multiarm_pin.constraints.SupportSet.edge_margins`, reaches 0) while it touches
  is no longer supported: the time is the root of the smallest edge margin of those rows
  on ``θ ∈ [0, 1]`` of the step (the same re-integration, active set unchanged), located by
  the Illinois method to a bracket shorter than ``EDGE_TIME_TOLERANCE`` (the bracket's
  upper end, just past the edge); the step is split there (a separation or a touchdown
  located before it is handled first), the row leaves the active set (event
  ``"off_edge"``) and the step is finished with the new active set. An active row found
  outside at a step's start leaves the same way at that time. A row outside its rectangle
  never touches down: rows are watched for a touchdown only when inside at the step's
  start or end, and a touchdown located where the row is outside is none (the step is only
  split there). A row that goes below the plane (by more than ``GAP_TOLERANCE``) while
  outside (it fell past the edge) is *fallen*: not watched, nor counted as a penetration,
  until it is above the plane again (by more than ``GAP_TOLERANCE``); a point that comes
  back over the rectangle while above the plane touches down as usual.

The scheme is exact at events up to the stated tolerances and keeps the smooth integrator's
order between them; velocity-level time stepping (Moreau-Jean) would be more robust for many
simultaneous impacts but is first order everywhere. The sampling grid stays ``k dt``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

GAP_TOLERANCE = 1e-9
"""[m] A row touches down when its gap falls below ``-GAP_TOLERANCE``; located to within it."""

LOST_GAP = 1e-4
"""[m] A separated row whose gap is below ``-LOST_GAP`` at a step's start is not watched for
touchdowns (its tip is behind the infinite plane of its face, off the face: it touches
nothing). Real penetrations stay far smaller (Baumgarte-corrected drift, ~1e-9 m here)."""

TIME_TOLERANCE = 1e-13
"""[s] Touchdown location stops when the bracket is shorter than this."""

LIFT_ACCELERATION = 1e-8
"""[m/s²] While a separation is located, a force-free row whose ``φ̈`` exceeds this has
let go (far above round-off, ~1e-14 here; a lift this slow moves less than 1e-14 m in a
millisecond)."""

SEPARATION_TIME_TOLERANCE = 1e-10
"""[s] Separation location stops when the bracket is shorter than this: a recorded
separation time is at most this late (the bracket's upper end, where ``μ = 0``)."""

EDGE_TIME_TOLERANCE = 1e-10
"""[s] Off-edge location stops when the bracket is shorter than this: a recorded ``off_edge``
time is at most this late (the bracket's upper end, where the point is outside)."""

SEPARATION_ACCELERATION = 1e-3
"""[m/s²] An active unilateral row with ``μ = 0`` separates when ``φ̈`` exceeds this.

Below it the row stays in the active set, where the complementarity problem still lets it
lift (``φ̈ >= 0`` with ``μ = 0``); a lift that small stays below ``GAP_TOLERANCE`` over a
millisecond step, so leaving the active set for it would only make touchdown chatter."""

SEPARATION_GAP = 1e-6
"""[m] An active unilateral row whose gap exceeds this separates, whatever its ``μ``."""

SEPARATION_SPEED = 1e-4
"""[m/s] An active unilateral row opening faster than this separates, whatever its ``μ``.

The acceleration-level complementarity (with its Baumgarte terms ``-2αφ̇ - β²φ``) is right
only for rows at ``φ ≈ 0``, ``φ̇ ≈ 0``: for an opening row it would push to keep the
row from closing again faster than the Baumgarte rates (a cushion). Such a row leaves the
active set; if it closes again, that is a touchdown with its impact."""

REBOUND_SPEED = 1e-6
"""[m/s] Speed above round-off: a row leaves after an impact when ``φ̇⁺ > REBOUND_SPEED``, a
touching row closes (its impact is applied at once) when ``φ̇ < -REBOUND_SPEED``."""

RESTING_SPEED = 1e-3
"""[m/s] Impacts with a closing speed below this are plastic (``e = 0``), and rows that an
impact would send off slower than this are held (``φ̇⁺ = 0``): no micro-bounces."""

MAX_EVENTS_PER_STEP = 50
"""Touchdowns handled within one step before the simulation gives up (DynamicsError)."""


EVENT_KINDS = ("separation", "touchdown", "off_edge")
"""The kinds of :class:`ContactEvent`."""


@dataclass(frozen=True)
class ContactEvent:
    """A unilateral contact separating, touching down or losing its support off an edge.

    Attributes:
        t: time [s].
        kind: ``"separation"``, ``"touchdown"`` (``rebound`` True: it left again at once)
            or ``"off_edge"`` (a support row whose point left its support's rectangle).
        block: block index (an arm, or ``n_arms`` for the supports); row: row in the block.
        label: ``"<arm>:<contact>"`` or ``"<support>[point]"``.
        body: the arm's or the support's name.
        phi_dot: gap rate [m/s] before the event (``φ̇⁻`` at a touchdown).
        phi_dot_after: gap rate [m/s] after it (``φ̇⁺`` at a touchdown).
        impulse: contact impulse ``P`` [N s] of the impact (0 for a separation by force
            and off the edge).
        rebound: True if the row left again at once after its impact (restitution).
    """

    t: float
    kind: str
    block: int
    row: int
    label: str
    body: str
    phi_dot: float = 0.0
    phi_dot_after: float = 0.0
    impulse: float = 0.0
    rebound: bool = False

    def as_dict(self) -> dict:
        """Plain JSON-ready mapping."""
        return {k: (float(v) if isinstance(v, float) else v) for k, v in asdict(self).items()}


__all__ = [
    "EDGE_TIME_TOLERANCE",
    "EVENT_KINDS",
    "GAP_TOLERANCE",
    "LIFT_ACCELERATION",
    "LOST_GAP",
    "MAX_EVENTS_PER_STEP",
    "REBOUND_SPEED",
    "RESTING_SPEED",
    "SEPARATION_ACCELERATION",
    "SEPARATION_GAP",
    "SEPARATION_SPEED",
    "SEPARATION_TIME_TOLERANCE",
    "TIME_TOLERANCE",
    "ContactEvent",
]
