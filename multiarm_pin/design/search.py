"""The design search: random candidates, then local refinement around the best, in parallel.

Round 0 draws ``search.candidates`` random candidates (:func:`~.candidates.sample_candidate`).
Each of the ``search.refine`` rounds after it draws half as many candidates: half of them
neighbours (:func:`~.candidates.perturb`, steps halved each round, on the parents' IK branches)
of the :data:`PARENTS` best candidates so far whose bases differ (:data:`PARENT_DISTANCE`; the
best designs by the objective, or, while no candidate met every condition, those that got
furthest: the latest condition, the best value there); the other half recombinations
(:func:`~.candidates.recombine`) of arms that reached their grasps in any candidate so far
(with one arm, fresh random candidates). Then a branch round tries every other IK branch
of each arm of the best designs (:func:`_branch_round`: not only the branches their random
seeds fell into; at most ``search.candidates`` candidates, whole designs). After them,
``search.polish`` rounds of a quarter as many candidates refine the Pareto front
(:func:`_polish`: its best designs by the objective and those beside its widest gaps; other
IK branches of the arm with the worst torque, bases toward or away from their grasps, one
or all together, welds turned about their faces, small steps). A
design found twice is ranked once (:func:`_distinct`). Candidates are assessed
(:func:`~.assessment.assess`) in parallel on Dask (a ``LocalCluster`` of ``workers``
processes or the scheduler at ``scheduler``, as ``multiarm-pin sweep``), or in this process
when ``workers`` is 1.

Determinism: a candidate depends only on the spec's seed, its index and its parent
(:func:`~.candidates.candidate_rng`); an assessment only on its candidate; parents and designs
are chosen by a total order (:func:`~.scoring.rank_key`). So the same spec and seed give the
same designs on any number of workers, whatever order they finish in.

An impossible spec (no candidate met every condition) raises
:class:`~multiarm_pin.exceptions.DesignImpossibleError` naming the condition the furthest
candidates failed and the best value any of them reached there.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from multiarm_pin.design.assessment import CONDITIONS, Assessment, DesignProblem, assess
from multiarm_pin.design.candidates import (
    BRANCHES,
    approach,
    arm_pool,
    branch_of,
    n_branches,
    perturb,
    recombine,
    reseed,
    sample_candidate,
    slide,
    turn,
)
from multiarm_pin.design.scoring import (
    SCORES,
    crowding_distance,
    objective,
    pareto_front,
    rank_key,
)
from multiarm_pin.exceptions import DesignImpossibleError

PARENTS = 4
"""Candidates refined in each refinement round."""

POLISH_MIN = 8
"""Fewest candidates of a polishing round (each of a quarter of ``search.candidates``)."""

APPROACH_STEP = 0.05
"""Largest horizontal step [m] of a polishing round's base toward its grasp."""

TURN_STEP = 0.5
"""Largest turn [rad] of a polishing round's weld about its face normal."""

SLIDE_STEP = 0.03
"""Largest step [m] along each axis of its face of a polishing round's weld point."""

MOVES = 8
"""Recipes per parent of a polishing round (:func:`_polish`)."""

PARENT_DISTANCE = 0.15
"""The parents of a round differ pairwise by this much [m] in some arm's base position."""

LOWER_IS_BETTER = {"reach": True, "path": True, "collision": False, "torque": True,
                   "closure": False}
"""Per condition, whether a smaller value is nearer to meeting it."""


@dataclass
class Design:
    """One returned design.

    Attributes:
        rank: 1 for the best.
        index: its candidate's index.
        objective: the weighted objective (:func:`~.scoring.objective`).
        scores: the :data:`~.scoring.SCORES` values (None where they do not apply).
        pareto: on the Pareto front of every design found.
        scenario: the scenario mapping (``multiarm-pin run`` reads it as YAML).
        assessment: the :class:`~.assessment.Assessment`.
    """

    rank: int
    index: int
    objective: float
    scores: dict
    pareto: bool
    scenario: dict
    assessment: Assessment


@dataclass
class DesignResult:
    """What :func:`run_design` found.

    Attributes:
        spec: the :class:`~.spec.DesignSpec`.
        designs: the top designs, best first.
        pareto: every design of the Pareto front (ranked as ``designs``).
        evaluated: candidates assessed (named as the ``evaluated`` key of ``design.json``).
        feasible: candidates that met every condition.
        failures: per condition, how many candidates failed it first.
        wall_time: seconds of the search.
        workers: the worker count (1: this process).
    """

    spec: object
    designs: list
    pareto: list
    evaluated: int
    feasible: int
    failures: dict = field(default_factory=dict)
    wall_time: float = 0.0
    workers: int = 1


def _progress_key(e: Assessment, weights: dict) -> tuple:
    """Total order of assessments: furthest condition first, then nearest to meeting it."""
    if e.ok:
        return (0, *rank_key(objective(e.scores, weights), e.index))
    v = e.value if e.value is not None and np.isfinite(e.value) else np.inf
    v = v if LOWER_IS_BETTER[e.condition] else -v
    return (len(CONDITIONS) - e.stage, round(float(v), 12), e.index)


def make_and_assess(problem: DesignProblem, recipe: tuple) -> Assessment:
    """Make a candidate from its recipe and assess it (one task of the search).

    Recipes: ``("sample", index)`` (:func:`~.candidates.sample_candidate`), ``("perturb",
    parent, q0s, index, scale)`` (:func:`~.candidates.perturb`), ``("reseed", parent, q0s,
    index, arm[, branch])`` (:func:`~.candidates.reseed`), ``("approach", parent, q0s, index, arm,
    step)`` (:func:`~.candidates.approach`), ``("turn", parent, q0s, index, arm, step)``
    (:func:`~.candidates.turn`), ``("slide", parent, q0s, index, arm, step)``
    (:func:`~.candidates.slide`), ``("ready", candidate)``.
    Making the candidate in the task spreads the fingertip grips' fits over the workers too.
    """
    kind = recipe[0]
    if kind == "sample":
        cand = sample_candidate(problem, recipe[1])
    elif kind == "perturb":
        cand = perturb(problem, *recipe[1:])
    elif kind == "reseed":
        cand = reseed(problem, *recipe[1:])
    elif kind == "approach":
        cand = approach(problem, *recipe[1:])
    elif kind == "turn":
        cand = turn(problem, *recipe[1:])
    elif kind == "slide":
        cand = slide(problem, *recipe[1:])
    else:
        cand = recipe[1]
    return assess(problem, cand)


class _Loop:
    def map(self, problem, recipes):
        return [make_and_assess(problem, r) for r in recipes]

    def close(self):
        pass


class _Dask:
    def __init__(self, workers: int, scheduler: str | None, client=None):
        from multiarm_pin.study.execution import connect, local_cluster

        self.cluster = self.own_client = None
        if client is None:
            if scheduler is not None:
                client = self.own_client = connect(scheduler)
            else:
                from distributed import Client

                self.cluster = local_cluster(workers)
                client = self.own_client = Client(self.cluster)
        self.client = client
        self.problem = None

    def map(self, problem, recipes):
        # scattered once and held for the whole search: scattering it again gives the same
        # key, which releasing the first future would take from the tasks using the second
        if self.problem is None:
            self.problem = self.client.scatter(problem, broadcast=True)
        futures = self.client.map(make_and_assess, [self.problem] * len(recipes), recipes,
                                  pure=False)
        return self.client.gather(futures)

    def close(self):
        import contextlib

        for c in (self.own_client, self.cluster):
            if c is not None:
                with contextlib.suppress(Exception):
                    c.close()


def run_design(spec, workers: int = 1, scheduler: str | None = None, client=None,
               seed: int | None = None, progress=None) -> DesignResult:
    """Search a design spec (module docstring) and rank what it found.

    Args:
        spec: a :class:`~.spec.DesignSpec` or a spec file path.
        workers: assess on a local Dask cluster of this many processes (1: in this
            process, no Dask).
        scheduler: address of an existing Dask scheduler instead.
        client: a ``distributed.Client`` to use (not closed here).
        seed: overrides ``search.seed``.
        progress: called with a line of text after each round, or None.

    Returns:
        :class:`DesignResult`.

    Raises:
        DesignImpossibleError: no candidate met every condition.
        DesignError: an invalid spec file.
    """
    from multiarm_pin.design.spec import load_design

    if not hasattr(spec, "arms"):
        spec = load_design(spec)
    if seed is not None:
        spec = replace(spec, search=replace(spec.search, seed=int(seed)))
    t0 = time.perf_counter()
    problem = DesignProblem(spec)
    blocked = _unclosable(problem)
    if blocked is not None:
        raise blocked
    s = spec.search
    def key(e):
        return _progress_key(e, spec.weights)

    runner = _Dask(workers, scheduler, client) if (client is not None or scheduler is not None
                                                   or workers > 1) else _Loop()
    try:
        assessments = runner.map(problem, [("sample", i) for i in range(s.candidates)])
        nxt = s.candidates
        per_round = max(s.candidates // 2, 1)
        for r in range(1, s.refine + 1):
            if progress is not None:
                progress(_round_line(r - 1, assessments))
            parents = _parents(sorted(assessments, key=key))
            cands = []
            for j in range(per_round // 2):
                p = parents[j % len(parents)]
                q0 = p.q0 if p.q0 is not None else [a.q_seed for a in p.candidate.arms]
                cands.append(("perturb", p.candidate, q0, nxt + j, 0.5 ** r))
            pool = arm_pool(problem, assessments)
            for j in range(per_round // 2, per_round):
                c = recombine(problem, pool, nxt + j) if len(spec.arms) > 1 else None
                cands.append(("ready", c) if c is not None else ("sample", nxt + j))
            nxt += per_round
            new = runner.map(problem, cands)
            assessments += new
        cands = _branch_round(problem, sorted(assessments, key=key), nxt, s.candidates)
        nxt += len(cands)
        assessments += runner.map(problem, cands)
        for r in range(1, s.polish + 1):
            if progress is not None:
                progress(_round_line(s.refine + r - 1, assessments))
            cands = _polish(sorted(assessments, key=key), max(s.candidates // 4, POLISH_MIN), nxt,
                            0.5 ** (s.refine + r))
            nxt += len(cands)
            assessments += runner.map(problem, cands)
    finally:
        runner.close()
    if progress is not None:
        progress(_round_line(s.refine + s.polish, assessments))
    ok = _distinct(sorted((e for e in assessments if e.ok), key=key))
    failures = {c: sum(1 for e in assessments if e.condition == c) for c in CONDITIONS}
    if not ok:
        raise _impossible(problem, assessments)
    designs = [Design(k + 1, e.index, objective(e.scores, spec.weights), _all_scores(e), False,
                      e.scenario, e) for k, e in enumerate(ok)]
    front = set(pareto_front([d.scores for d in designs]))
    for k, d in enumerate(designs):
        d.pareto = k in front
    return DesignResult(spec, designs[:spec.top], [d for d in designs if d.pareto],
                        len(assessments), sum(1 for e in assessments if e.ok), failures,
                        time.perf_counter() - t0,
                        1 if isinstance(runner, _Loop) else max(workers, 1))


def _parents(ranked: list) -> list:
    """A round's parents: the best candidates, and the design best on each score.

    The :data:`PARENTS` best of the ranking (:func:`_diverse`), then for each score the design
    best on it, so that every trade-off of the Pareto front is refined too.
    """
    out = _diverse(ranked, PARENTS)
    ok = [e for e in ranked if e.ok]
    for name, score in SCORES.items():
        have = [e for e in ok if e.scores.get(name) is not None]
        if not have:
            continue
        sign = -1.0 if score.higher_is_better else 1.0
        best = min(have, key=lambda e: (sign * e.scores[name], e.index))
        if all(best.index != o.index for o in out):
            out.append(best)
    return out


def _polish(ranked: list, n: int, first: int, scale: float) -> list:
    """A polishing round's ``n`` recipes: neighbours of designs of the Pareto front.

    Up to ``n // MOVES`` designs of the front: a third of them its best by the objective,
    the others those of the largest crowding distance (:func:`~.scoring.crowding_distance`:
    the ends of the front and the designs beside its widest gaps, where the objective's
    ranking sends no parent). Each gets, in turn (:data:`MOVES` recipes), a re-seed of the
    arm with the worst torque ratio (another IK branch of the same bases and grasps:
    :func:`~.candidates.reseed`), that arm's base moved toward its grasp
    (:func:`~.candidates.approach`, up to :data:`APPROACH_STEP`), the base of the arm with
    the smallest manipulability moved away from its grasp, every base moved toward and,
    in another recipe, away from its grasp together (along the trade-off of torque and
    manipulability), the worst-torque arm's weld turned about its face normal
    (:func:`~.candidates.turn`, up to :data:`TURN_STEP`: the torques change, the
    manipulability not), its weld point moved on its face (:func:`~.candidates.slide`, up
    to :data:`SLIDE_STEP`; a rigid fingertip grip has neither: another re-seed and another
    step toward its grasp instead), and a small step of its bases and grasps
    (:func:`~.candidates.perturb` at ``scale``). A
    neighbour better on one score and no worse on the others displaces its parent from the
    front, so that the front moves outward where the random rounds left it; candidates
    indexed from ``first``.
    """
    ok = _distinct([e for e in ranked if e.ok])
    if not ok:
        return []
    front = [ok[i] for i in pareto_front([_all_scores(e) for e in ok])]
    m = max(min(len(front), n // MOVES), 1)
    top = (m + 2) // 3
    crowd = crowding_distance([_all_scores(e) for e in front])
    spread = sorted(range(top, len(front)), key=lambda i: (-crowd[i], i))[:m - top]
    parents = front[:top] + [front[i] for i in sorted(spread)]
    out = []
    for j in range(n):
        k, move = divmod(j, MOVES)
        p = parents[k % len(parents)]
        a = p.torque_arm
        if move == 0:
            out.append(("reseed", p.candidate, p.q0, first + j, a))
        elif move == 1:
            out.append(("approach", p.candidate, p.q0, first + j, a, APPROACH_STEP))
        elif move == 2:
            out.append(("approach", p.candidate, p.q0, first + j, p.manipulability_arm,
                        -APPROACH_STEP))
        elif move in (3, 4):
            out.append(("approach", p.candidate, p.q0, first + j, None,
                        APPROACH_STEP if move == 3 else -APPROACH_STEP))
        elif move in (5, 6) and len(p.candidate.arms[a].points) > 1:  # a rigid grip
            out.append(("reseed", p.candidate, p.q0, first + j, a) if move == 5 else
                       ("approach", p.candidate, p.q0, first + j, a, APPROACH_STEP))
        elif move == 5:
            out.append(("turn", p.candidate, p.q0, first + j, a, TURN_STEP))
        elif move == 6:
            out.append(("slide", p.candidate, p.q0, first + j, a, SLIDE_STEP))
        else:
            out.append(("perturb", p.candidate, p.q0, first + j, scale))
    return out


def _branch_round(problem, ranked: list, first: int, limit: int | None = None) -> list:
    """Every other IK branch of every arm of the best designs: the branch round's recipes.

    For each parent (:func:`_parents`: the :data:`PARENTS` best designs whose bases differ
    and the design best on each score; while none met every condition, the furthest
    candidates whose start pose was found), each arm with :data:`~.candidates.BRANCHES` and
    each branch other than the one its start
    configuration is on (:func:`~.candidates.branch_of`): the design with that arm seeded on
    that branch (:func:`~.candidates.reseed`; the other arms keep their configurations).
    Seeds that converge to a configuration already found give the same design, which the
    ranking keeps once (:func:`_distinct`). Candidates indexed from ``first``. With ``limit``
    (the search passes ``search.candidates``), the parents after the first whose recipes
    would bring the round beyond ``limit`` are left out (each parent's branches whole).
    """
    ok = [e for e in ranked if e.ok]
    out = []
    for p in (_parents(ranked) if ok else _diverse([e for e in ranked if e.q0 is not None],
                                                   PARENTS)):
        mine = []
        for i, a in enumerate(p.candidate.arms):
            if n_branches(problem, i) == 1:
                continue
            target = problem.object_placement.act(a.points.mean(axis=0))
            own = branch_of(problem, i, a.base, target, p.q0[i])
            mine += [(i, b) for b in range(BRANCHES) if b != own]
        if out and limit is not None and len(out) + len(mine) > limit:
            break
        out += [("reseed", p.candidate, p.q0, first + len(out) + k, i, b)
                for k, (i, b) in enumerate(mine)]
    return out


def _distinct(ranked: list) -> list:
    """The assessments of a ranking without repeats (the same design found twice).

    A design whose bases, grasps and start configurations equal (to 1e-6 m or rad) those of
    one ranked before it is left out.
    """
    seen, out = set(), []
    for e in ranked:
        key = tuple(np.round(np.concatenate(
            [np.concatenate([a.base, np.ravel(a.points), [a.roll], q])
             for a, q in zip(e.candidate.arms, e.q0, strict=True)]), 6).tolist())
        if key not in seen:
            seen.add(key)
            out.append(e)
    return out


def _diverse(ranked: list, n: int) -> list:
    """The first ``n`` assessments of a ranking whose bases differ by :data:`PARENT_DISTANCE`.

    Two candidates differ when some arm's base is at least that far from its place in the
    other (positions [m]); the ranking's first is always kept.
    """
    out = []
    for e in ranked:
        if len(out) == n:
            break
        if all(max(float(np.linalg.norm(a.base[:3] - b.base[:3]))
                   for a, b in zip(e.candidate.arms, o.candidate.arms, strict=True))
               >= PARENT_DISTANCE for o in out):
            out.append(e)
    return out


def _all_scores(e: Assessment) -> dict:
    return {n: e.scores.get(n) for n in SCORES}


def _round_line(r: int, assessments: list) -> str:
    ok = sum(1 for e in assessments if e.ok)
    return f"round {r}: {len(assessments)} candidates evaluated, {ok} met every condition"


def _impossible(problem, assessments: list) -> DesignImpossibleError:
    """The error of a search that found nothing: the furthest condition and its best value."""
    best = min(assessments, key=lambda e: _progress_key(e, problem.spec.weights))
    c, v, detail = best.condition, best.value, best.detail
    spec = problem.spec
    n = len(assessments)
    if c == "reach" and not np.isfinite(v):
        msg = f"no candidate could be built: {detail}"
    elif c == "reach":
        msg = (f"no base in the region reaches the object with every arm within its joint "
               f"limits (each contact inside its face by {spec.search.face_margin:g} m): "
               f"closest {v:.3g} m (IK residual of {detail})")
    elif c == "closure":
        msg = (f"the fingertip contacts are never form closure: best LP margin {v:.3g} "
               f"(needs > 0)")
        msg += _closure_hint(problem)
    elif c == "path":
        msg = (f"no candidate follows the task on one continuous IK branch within joint "
               f"limits: best {v:.3g} ({detail})")
    elif c == "collision":
        msg = (f"no candidate keeps the clearance margin {spec.search.clearance:g} m along "
               f"the task: best {v * 1e3:.3g} mm ({detail})")
    else:
        msg = f"static torque at {detail} {v:.3g}x its limit at best"
    return DesignImpossibleError(c, v, f"{spec.file}: no design found in {n} candidates: "
                                       f"{msg}")


def _unclosable(problem) -> DesignImpossibleError | None:
    """Fingertips only, and the faces they may touch cannot push the object every way.

    Frictionless contacts push along the inward normals of the faces they touch; if those
    normals do not positively span R³ (the LP of :func:`~multiarm_pin.grasp.form_closure.lp_margin`
    on them has no positive margin), no placement of the tips is form closure.
    """
    from multiarm_pin.grasp.form_closure import lp_margin

    if any(s.gripper == "weld" for s in problem.spec.arms):
        return None
    touchable = [f for f in range(problem.poly.n_faces) if not problem.covered(f)]
    N = -problem.poly.normals[touchable].T  # (3, F) inward normals
    eps = lp_margin(N)[0] if touchable else float("nan")
    if np.isfinite(eps) and eps > 1e-9 and np.linalg.matrix_rank(N) == 3:
        return None
    eps = eps if np.isfinite(eps) else 0.0
    return DesignImpossibleError(
        "closure", eps, f"{problem.spec.file}: no design possible: the fingertip contacts can "
        f"never be form closure (LP margin of the touchable faces' normals {eps:.3g}, needs > 0)"
        + _closure_hint(problem))


def _closure_hint(problem) -> str:
    """Why fingertips may never close: a face they cannot touch because it rests on a table."""
    poly = problem.poly
    for f, _, _ in problem.rects:
        if problem.covered(f):
            name = poly.face_names[f] if poly.face_names else str(f)
            sp = next(s.name for s in problem.spec.supports)
            return (f"; the {name} face rests on {sp!r}, which covers it whole, and fingertips "
                    "cannot push up: form closure needs a contact on it")
    return ""


__all__ = ["PARENTS", "Design", "DesignResult", "make_and_assess", "run_design"]
