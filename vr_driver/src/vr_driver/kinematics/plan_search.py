"""OMPL in the planner's scaled joint space, steps 3 and 4 of :mod:`vr_driver.kinematics.planner`:
the state space x_i = w_i q_i inside the joint limits with its validity checker and motion-check
resolution (the planner's module text, "Motion-check resolution"), the reseeding of OMPL's random
numbers, a search by one of OMPL's geometric planners to any of some goals, and the simplification
of the path found. Which goals to search for, in which stages, and the check of the result are
the planner's.

    search = OmplSearch((ompl.base, ompl.geometric, ompl.util), weights, lower, upper, max_sweep,
                        is_valid, seed)                          # reseeds OMPL, makes the space
    path = search.solve("RRTConnect", q0, goals, seconds)        # None: none found (search.status)
    joints = search.simplified(path)                             # [rad], start to goal

ROS-free. The OMPL modules are handed in by the planner, which imports them (``kinematics.deps``);
this module imports no optional library. Not thread-safe: OMPL's seed generator is process-wide.
"""
from __future__ import annotations

import functools
import math
import random
import time
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ["OmplSearch", "SIMPLIFY_ROUNDS", "ROPE_SPACING", "SWEEP_VALIDATED", "BatchValidity", "bisection_order",
           "first_invalid"]

#: rounds of shortcutting at most (each tries as many shortcuts as the path has vertices)
SIMPLIFY_ROUNDS = 2
#: the rope shortcut's spacing in the scaled space (the state space's distance: joint 1 alone,
#: 2.09 m/rad, every 55 deg): OMPL's ropeShortcutPath cuts the path into points this far apart
#: and joins each to the farthest one its straight motion reaches. Rounds of random vertex and
#: partial shortcuts alone stopped on detours the rope pulls straight: bench/planning.py, the hood
#: cell's median path 2.47 -> 2.20 s, the example cell's 1.78 -> 1.70 s (bench/README.md,
#: "Planning", round 6); OMPL's default spacing (1.0) shortened them by up to 2 % more for 6-11 %
#: more CPU. None: no rope shortcut
ROPE_SPACING: Optional[float] = 2.0
#: the planners whose motions are checked at the sweep itself (:meth:`OmplSearch._sweep_validator`;
#: they and the simplifier ask OMPL's motion validator only whether a motion is valid, never how
#: far it is). The others -- LBKPIECE1, the plan action's retry planner, asks how far a motion is
#: valid -- keep OMPL's own validator at the resolution :meth:`OmplSearch._space` sets, |dx| <=
#: max_sweep / sqrt(n) in the scaled space, so their checked states lie no farther apart by the
#: sweep bound either (sum_i |dx_i| <= sqrt(n) |dx|), at up to sqrt(n) times the checks; and the
#: planner checks every motion of the simplified path at the sweep bound itself, the result's
#: chords too (test_planner.py: test_a_retry_planners_motions_are_checked_at_the_sweep_bound_or_finer)
SWEEP_VALIDATED = ("RRTConnect",)


class BatchValidity:
    """A validity of one configuration, ``is_valid(q) -> bool`` (calling it), with the same test
    of a batch: ``first_invalid(qs)`` the index of the first row of ``qs`` (n x dof) it refuses,
    or None -- a motion's states checked in one call (:func:`first_invalid`)."""

    def __init__(self, one: Callable[[Sequence[float]], bool], batch: Callable[[Any], Optional[int]]) -> None:
        self._one = one
        self.first_invalid = batch

    def __call__(self, q: Sequence[float]) -> bool:
        return self._one(q)


def first_invalid(is_valid: Callable[[Sequence[float]], bool], qs: Sequence[Sequence[float]]) -> Optional[int]:
    """The index of the first row of ``qs`` (n x dof) that ``is_valid`` refuses, or None: in
    one call where it has a batch test (``first_invalid``: a :class:`BatchValidity`), else row by row."""
    batch = getattr(is_valid, "first_invalid", None)
    if batch is not None:
        return batch(qs)
    for i, q in enumerate(qs):
        if not is_valid(tuple(float(v) for v in q)):
            return i
    return None


def bisection_order(n: int) -> Tuple[int, ...]:
    """1 .. n-1 in the order a bisection visits them (the middle first, then the middles of the
    halves, ...): a motion into an obstacle is refused after a few checks, wherever it enters.
    (One level of the bisection at a time, its spans left to right, in numpy.)"""
    out = []
    lo, hi = np.array([0]), np.array([n])
    while len(lo):
        keep = hi - lo >= 2
        lo, hi = lo[keep], hi[keep]
        mid = (lo + hi) // 2
        out.append(mid)
        lo, hi = np.stack((lo, mid), axis=1).ravel(), np.stack((mid, hi), axis=1).ravel()
    return tuple(np.concatenate(out).tolist())


class SweepZone:
    """The configurations within a sweep bound (sum_i w_i |q_i - e_i|, ``weights`` w) of any of
    ``ends`` (the planner's escape zone around a plan's start and goals): :meth:`near`."""

    def __init__(self, ends: Sequence[Sequence[float]], weights: Sequence[float]) -> None:
        self.ends = tuple(tuple(e) for e in ends)
        self._rows = np.array(self.ends, dtype=float) if self.ends else np.zeros((0, 0))
        self._weights = np.array(weights, dtype=float)

    def near(self, q: Sequence[float], bound: float, sweep: Callable[[Sequence[float], Sequence[float]], float]) -> bool:
        """Whether ``sweep(q, e) <= bound`` for an end e: the sweeps in numpy, and where one lies
        within 1e-9 of the bound (numpy's sum may round otherwise), ``sweep``'s own sums decide."""
        if not self.ends:
            return False
        sweeps = np.abs(self._rows - np.asarray(q, dtype=float)) @ self._weights
        if np.min(np.abs(sweeps - bound)) < 1e-9:
            return any(sweep(q, e) <= bound for e in self.ends)
        return bool(np.min(sweeps) <= bound)


@functools.lru_cache(maxsize=4096)
def motion_fractions(n: int) -> np.ndarray:
    """The fractions of a motion of ``n`` steps its states are checked at, in order: the end (1)
    first, then k / n for k in :func:`bisection_order` (read-only; kept per n)."""
    out = np.concatenate(([1.0], np.array(bisection_order(n), dtype=float) / n))
    out.flags.writeable = False
    return out


class OmplSearch:
    """One plan's OMPL: made with OMPL's modules ``ompl`` (base, geometric, util), the joints'
    ``weights`` [m/rad] (``planner.joint_weights``), their ``lower`` and ``upper`` limits [rad],
    ``max_sweep`` [m] (no point of the arm moves farther between two checked states) and
    ``is_valid(q)`` (joints [rad]) -- it reseeds OMPL's seed generator with ``seed`` (None: a random
    one) before anything draws a seed from it, then makes the space, so that one seed and one
    problem give one path (as long as the search finishes within its time)."""

    def __init__(self, ompl: Tuple[Any, Any, Any], weights: Sequence[float], lower: Sequence[float],
                 upper: Sequence[float], max_sweep: float, is_valid: Callable[[Sequence[float]], bool],
                 seed: Optional[int], sweep_motions: bool = False) -> None:
        self._ob, self._og, ou = ompl
        self.weights = tuple(weights)
        self.dof = len(self.weights)
        #: the last search's outcome in OMPL's words (its planner status)
        self.status = ""
        self._found: Any = None
        #: whether motions are checked at the sweep itself (``sweep_motions``: the planner is one of
        #: SWEEP_VALIDATED and this OMPL takes a validator written in Python), and how many motions
        #: and states that validator checked at most
        self.sweep_motions = bool(sweep_motions)
        self.counts = {"motions": 0, "states": 0}
        # OMPL logs an error when it has drawn seeds before, but reseeds all the same
        previous = ou.getLogLevel()
        ou.setLogLevel(ou.LOG_NONE)
        try:
            ou.RNG.setSeed(int(seed) if seed is not None else random.SystemRandom().randrange(1, 2 ** 31))
        finally:
            ou.setLogLevel(previous)
        self.si = self._space(lower, upper, max_sweep, is_valid)

    def _space(self, lower: Sequence[float], upper: Sequence[float], max_sweep: float,
               is_valid: Callable[[Sequence[float]], bool]) -> Any:
        """OMPL's space information: the scaled joint box, ``is_valid`` on the joints, the
        motion-check resolution of ``max_sweep``."""
        ob = self._ob
        space = ob.RealVectorStateSpace(self.dof)
        bounds = ob.RealVectorBounds(self.dof)
        for i, (w, lo, hi) in enumerate(zip(self.weights, lower, upper)):
            bounds.setLow(i, w * lo)
            bounds.setHigh(i, w * hi)
        space.setBounds(bounds)
        si = ob.SpaceInformation(space)
        weights, dof = self.weights, self.dof

        def valid(state) -> bool:
            return bool(is_valid(tuple(state[i] / weights[i] for i in range(dof))))

        si.setStateValidityChecker(valid)
        # the longest segment checked in one piece: |dx| <= max_sweep / sqrt(n) bounds the sweep
        # sum_i w_i |dq_i| by max_sweep (the planner's module text)
        si.setStateValidityCheckingResolution(max_sweep / math.sqrt(dof) / space.getMaximumExtent())
        if self.sweep_motions:
            self.sweep_motions = self._sweep_validator(si, max_sweep, is_valid)
        si.setup()
        return si

    def _sweep_validator(self, si: Any, max_sweep: float, is_valid: Callable[[Sequence[float]], bool]) -> bool:
        """OMPL's motion validator replaced by one that checks a motion at the sweep itself: in the
        scaled space a motion's sweep bound sum_i w_i |dq_i| is the sum of its coordinates' moves,
        so ceil(that / ``max_sweep``) segments keep every point of the arm within ``max_sweep``
        between two checks (as the planner's own ``motion_valid``) -- the bound OMPL's resolution
        keeps through |dx| <= max_sweep / sqrt(n), with up to sqrt(n) times as many checks (a
        motion of one joint: 2.4 x). The end first, then the inner states in bisection order, as
        one batch (``is_valid``'s ``first_invalid`` where it has one: :func:`first_invalid`), the
        first refusal ending it. False (OMPL's own stays) where this OMPL cannot take a validator
        written in Python."""
        weights, dof = self.weights, self.dof
        w = np.array(weights)
        counts = self.counts

        class SweepMotions(self._ob.MotionValidator):
            def checkMotion(self, s1: Any, s2: Any, *last: Any) -> bool:
                if last:                  # the form that reports how far a motion is valid: not asked
                    raise NotImplementedError("the sweep validator answers checkMotion(s1, s2) only")
                counts["motions"] += 1
                a = np.array([s1[i] for i in range(dof)])
                d = np.array([s2[i] for i in range(dof)]) - a
                n = int(math.ceil(float(np.abs(d).sum()) / max_sweep))
                order = motion_fractions(n)
                counts["states"] += len(order)
                # the end first, then the inner states in bisection order: one batch, the first
                # refusal ends it
                return first_invalid(is_valid, (a + order[:, None] * d) / w) is None

        try:
            self._validator = SweepMotions(si)
            si.setMotionValidator(self._validator)
        except (AttributeError, TypeError):
            return False
        return True

    def _state(self, q: Sequence[float]) -> Any:
        s = self.si.allocState()
        for i, (w, v) in enumerate(zip(self.weights, q)):
            s[i] = w * v
        return s

    def solve(self, planner: str, q0: Sequence[float], goals: Sequence[Sequence[float]], seconds: float,
              since: Optional[float] = None) -> Any:
        """A search by OMPL's geometric planner ``planner`` (e.g. "RRTConnect") from the joints
        ``q0`` to any of ``goals`` within ``seconds`` (at least 1 ms), counted from ``since`` (a
        ``time.perf_counter()`` reading) when given, else from the search's start: OMPL's path
        (exact solutions only), or None; ``status`` says how it ended."""
        ob, si = self._ob, self.si
        pdef = ob.ProblemDefinition(si)
        pdef.addStartState(self._state(q0))
        goal = ob.GoalStates(si)
        for g in goals:
            goal.addState(self._state(g))
        pdef.setGoal(goal)
        search = getattr(self._og, planner)(si)
        search.setProblemDefinition(pdef)
        search.setup()
        left = seconds - (time.perf_counter() - since) if since is not None else seconds
        status = search.solve(max(left, 1e-3))
        self.status = status.asString()
        if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION or not pdef.hasExactSolution():
            return None
        self._found = (search, pdef)          # the path is theirs: kept alive as long as this search
        return pdef.getSolutionPath()

    def path_of(self, joints: Sequence[Sequence[float]]) -> Any:
        """An OMPL path through ``joints`` [rad] (a route found elsewhere: the roadmap's), for
        :meth:`simplified`."""
        path = self._og.PathGeometric(self.si)
        for q in joints:
            path.append(self._state(q))
        self._found = (path,)
        return path

    def simplified(self, path: Any) -> List[Tuple[float, ...]]:
        """``path`` (of :meth:`solve`) simplified, as joints [rad]: OMPL's simplification steps with
        step counts, not a time limit (a seed gives one path): rounds of vertex reduction (random
        shortcuts between vertices), in the first round the rope shortcut (the path cut into
        points ``ROPE_SPACING`` apart, each joined to the farthest it reaches straight; again in
        the second round it shortened the paths by 1 % for 4-7 % more CPU, checking the path it
        had pulled straight once more), partial shortcuts (a subset of the joints at a time) and
        collapsing close vertices, until a round changes nothing (at most ``SIMPLIFY_ROUNDS``),
        then B-spline smoothing of the corners. Each step keeps the path valid (it checks its
        motions as the search does: the sweep validator where the planner has it)."""
        simplifier = self._og.PathSimplifier(self.si)
        for round_ in range(SIMPLIFY_ROUNDS):
            changed = simplifier.reduceVertices(path, 0, 0)
            if not round_ and ROPE_SPACING:
                changed = simplifier.ropeShortcutPath(path, ROPE_SPACING) or changed
            changed = simplifier.partialShortcutPath(path, 0, 0) or changed
            changed = simplifier.collapseCloseVertices(path) or changed
            if not changed:
                break
        simplifier.smoothBSpline(path, 3)
        return [tuple(s[i] / self.weights[i] for i in range(self.dof)) for s in path.getStates()]
