"""The inverse kinematics of one chain (:class:`IkSolver`), on PyKDL and the closed-form solver of
:mod:`vr_driver.kinematics.analytic`; :class:`~vr_driver.kinematics.solver.Kinematics` validates
the target and the seed, owns the time budget and delegates here. ROS-free.

Strategy (``Kinematics.ik``):

1. Validate the target (finite, a rotation) and the seed (finite, right length; clamped into the
   limits, because KDL's NR_JL returns a seed outside the limits unchanged).
2. When the chain has the structure of a six-axis industrial arm with a spherical wrist (6 revolute
   joints; J2 parallel to J3 and perpendicular to J1; the axes of J4, J5, J6 meet in one point),
   an analytic solver built from the chain's zero-pose screw axes (generic, any such URDF) computes
   all 8 branches (shoulder front/back x elbow up/down x wrist flip). The reach check is part of it
   and costs a few microseconds. Each joint is then moved by +-2 pi towards the seed where the limits
   allow it (the wrist joints span more than 2 pi), out-of-limit branches are dropped, and the
   branch nearest the seed wins. The result is checked with KDL's FK (1e-6 m, 1e-6 rad) and, if it
   misses, polished by KDL NR_JL.
3. Otherwise (any other chain), KDL ``ChainIkSolverPos_NR_JL`` and then ``ChainIkSolverPos_LMA``
   (which converges more often but ignores the limits, so its joints are moved by full turns into
   the limits and re-checked) from the seed, then from random seeds (``random.Random``, seedable)
   until the time budget is spent, after a cheap reach check (distance to the target against the
   sum of the chain's link lengths). One solver run may overrun the budget (~1 ms at most).

Errors (vr_driver.errors): ``UnreachableError`` (outside the reach, with the distances),
``IkTimeoutError`` (numeric search exhausted), ``JointLimitError`` (reachable only outside the
limits, naming the joint), ``PoseError`` (NaN, inf, not a rigid transform).
"""
from __future__ import annotations

import itertools
import math
import random
import time
from dataclasses import dataclass
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np
import PyKDL as kdl
from panasonic_vr006l_support.model import Joint

from .. import validate
from ..errors import IkTimeoutError, JointLimitError, ModelError, PoseError, UnreachableError
from ..poses import check_transform, wrap_angle
from .analytic import TWO_PI, AnalyticSolver, applies, cross, dot, turn
from .limits import JointLimits

#: a rotation (row-major 9-tuple) and a position (3-tuple, m): a target as the solvers take it
Target = Tuple[Tuple[float, ...], Tuple[float, ...]]


@dataclass(frozen=True)
class IkSettings:
    """IK settings. ``timeout`` [s] is the whole budget of one IK call (MoveIt's
    ``kinematics_solver_timeout``). ``attempts`` (``kinematics_solver_attempts``) is read and kept:
    MoveIt repeats a failed search that many times; our numeric path instead restarts from random
    seeds until the one budget is spent, which covers the same need without multiplying the time.
    Tolerances: FK(IK(p)) must match p within ``position_tolerance`` [m] and
    ``orientation_tolerance`` [rad]."""

    timeout: float = 0.005
    attempts: int = 3
    position_tolerance: float = 1e-6
    orientation_tolerance: float = 1e-6
    nr_max_iterations: int = 100
    nr_eps: float = 1e-9

    def __post_init__(self) -> None:
        validate.number(self.timeout, lambda _: ModelError("IK timeout must be a positive number of seconds, got %r"
                                                           % (self.timeout,)), 0.0, lo_open=True, text=False)
        if int(self.attempts) < 1:
            raise ModelError("IK attempts must be >= 1, got %r" % self.attempts)


def jnt_array(dof: int, values: Sequence[float], clip: bool = False) -> "kdl.JntArray":
    """A ``PyKDL.JntArray`` of ``dof`` joints holding ``values``; ``clip``: infinite values (the
    limits of continuous joints) as large finite ones."""
    q = kdl.JntArray(dof)
    if clip:
        for i, v in enumerate(values):
            q[i] = max(-1e10, min(1e10, v))
    else:
        for i, v in enumerate(values):
            q[i] = v
    return q


def rotation_and_position(target: Any) -> Target:
    """(rotation, position) of an IK target: a ``PyKDL.Frame`` or a 4x4 rigid transform (a float
    array that is one is taken without copying; anything else through ``poses.check_transform``).
    PoseError for NaN, inf or a matrix that is not a rigid transform."""
    if isinstance(target, kdl.Frame):
        m, v = target.M, target.p
        r = (m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2])
        p = (v[0], v[1], v[2])
        if not all(math.isfinite(x) for x in r + p):
            raise PoseError("target frame contains NaN or inf")
        return r, p
    if isinstance(target, np.ndarray) and target.shape == (4, 4) and target.dtype == float:
        rows = target.tolist()
        flat = rows[0] + rows[1] + rows[2]
        if all(math.isfinite(x) for x in flat) and rows[3] == [0.0, 0.0, 0.0, 1.0]:
            r = (flat[0], flat[1], flat[2], flat[4], flat[5], flat[6], flat[8], flat[9], flat[10])
            det_ok = abs(dot(cross(r[0:3], r[3:6]), r[6:9]) - 1.0) < 1e-6
            if det_ok and abs(dot(r[0:3], r[3:6])) < 1e-6 and abs(dot(r[0:3], r[0:3]) - 1.0) < 1e-6 \
                    and abs(dot(r[3:6], r[3:6]) - 1.0) < 1e-6:
                return r, (flat[3], flat[7], flat[11])
    t = check_transform(target, "IK target")
    flat = t[:3, :3].reshape(-1).tolist()
    return tuple(flat), tuple(t[:3, 3].tolist())


class IkSolver:
    """The IK search of one chain (the module's strategy): the analytic branches when the chain has
    the shape (:attr:`analytic`; :attr:`analytic_reason` says why not), else KDL NR_JL and LMA with
    random restarts; every answer within the position ``limits`` and checked with KDL's FK against
    the ``settings``' tolerances. Targets are (rotation, position) pairs
    (:func:`rotation_and_position`), seeds validated joint tuples. It holds KDL solvers of its own:
    use it in one thread."""

    def __init__(self, chain_joints: Sequence[Joint], chain: "kdl.Chain", limits: JointLimits,
                 settings: IkSettings, analytic: bool = True) -> None:
        self.limits = limits
        self.settings = settings
        self.dof = len(limits.names)
        self._fk = kdl.ChainFkSolverPos_recursive(chain)
        self._q_min = jnt_array(self.dof, limits.lower, clip=True)
        self._q_max = jnt_array(self.dof, limits.upper, clip=True)
        self._vel = kdl.ChainIkSolverVel_pinv(chain)
        self._nr_jl = kdl.ChainIkSolverPos_NR_JL(chain, self._q_min, self._q_max, self._fk, self._vel,
                                                 settings.nr_max_iterations, settings.nr_eps)
        self._lma = kdl.ChainIkSolverPos_LMA(chain, 1e-10, 500, 1e-15)
        # zero-pose screw axes (root frame) and reach bound
        axes, points, types, t = [], [], [], np.eye(4)
        reach = 0.0
        for j in chain_joints:
            o = j.origin
            reach += float(np.linalg.norm(o[:3, 3]))
            t = t @ o
            if j.movable:
                axes.append(tuple(t[:3, :3] @ np.array(j.axis)))
                points.append(tuple(t[:3, 3]))
                types.append(j.type)
        #: [m] the sum of the chain's link lengths: no target farther from the first joint is reachable
        self.reach_bound = reach
        self._first_point = points[0]
        ok, why = applies(axes, points, types)
        #: why the chain has no analytic solver ("" when it has the shape)
        self.analytic_reason = why
        #: the closed-form solver (None: the chain has not the shape, or ``analytic=False``)
        self.analytic: Optional[AnalyticSolver] = AnalyticSolver(axes, points, t) if (ok and analytic) else None

    def nearest(self, r, p, seed: Tuple[float, ...], deadline: float, budget: float,
                rng: Optional[random.Random] = None, numeric: bool = False) -> Tuple[float, ...]:
        """The solution nearest ``seed``: the analytic one unless there is none or ``numeric``, else
        KDL's search until ``deadline`` (``time.perf_counter()``; ``budget`` [s] for the message),
        restarting from joints drawn with ``rng`` (default: a fresh ``random.Random()``, made only
        here: seeding one costs ~20 us)."""
        if self.analytic is not None and not numeric:
            return self._analytic_nearest(r, p, seed)
        return self._numeric(r, p, seed, deadline, rng or random.Random(), budget * 1e3)

    def solutions(self, r, p, seed: Tuple[float, ...]) -> List[Tuple[float, ...]]:
        """Every solution within the limits from the analytic solver (``Kinematics.ik_solutions``):
        each geometric branch and each full turn of a revolute joint that fits its limits, nearest
        to ``seed`` first. Raises as :meth:`nearest` when there is none."""
        lower, upper = self.limits.lower, self.limits.upper
        candidates, _, _, _ = self.analytic.solve(r, p, seed, lower, upper)
        found = []
        for _, q in candidates:
            if not self._ok(q, r, p):
                q = self._nr_polish(q, r, p)
                if q is None:
                    continue
            found.append(q)
        if not found:                          # the errors (and the polish) of the one-solution path
            found.append(self._analytic_nearest(r, p, seed))
        out: List[Tuple[float, ...]] = []
        for q in found:
            turns = []
            for v, lo, hi, rev in zip(q, lower, upper, self.limits.revolute):
                if not rev:
                    turns.append((v,))
                    continue
                k_lo, k_hi = math.ceil((lo - 1e-9 - v) / TWO_PI), math.floor((hi + 1e-9 - v) / TWO_PI)
                turns.append(tuple(min(max(v + k * TWO_PI, lo), hi) for k in range(k_lo, k_hi + 1)) or (v,))
            for variant in itertools.product(*turns):
                if all(max(abs(a - b) for a, b in zip(variant, other)) > 1e-9 for other in out):
                    out.append(variant)
        out.sort(key=lambda q: sum((a - b) ** 2 for a, b in zip(q, seed)))
        return out

    def _verify(self, q, r, p) -> Tuple[float, float]:
        """(position error [m], rotation error [rad]) of FK(q) against (r, p), with KDL's FK."""
        f = kdl.Frame()
        self._fk.JntToCart(jnt_array(self.dof, q), f)
        m, v = f.M, f.p
        dp = math.sqrt((v[0] - p[0]) ** 2 + (v[1] - p[1]) ** 2 + (v[2] - p[2]) ** 2)
        # rotation angle of R_fk^T R_target from its trace
        tr = (m[0, 0] * r[0] + m[1, 0] * r[3] + m[2, 0] * r[6] + m[0, 1] * r[1] + m[1, 1] * r[4]
              + m[2, 1] * r[7] + m[0, 2] * r[2] + m[1, 2] * r[5] + m[2, 2] * r[8])
        c = (tr - 1.0) / 2.0
        if c > 1.0 - 1e-10:
            # acos loses precision near 0: use the skew part instead
            s = [m[0, 0], m[0, 1], m[0, 2], m[1, 0], m[1, 1], m[1, 2], m[2, 0], m[2, 1], m[2, 2]]
            # R_fk^T R_target, skew part
            def e(i, j):
                return s[i] * r[j] + s[i + 3] * r[j + 3] + s[i + 6] * r[j + 6]
            da = 0.5 * math.sqrt((e(2, 1) - e(1, 2)) ** 2 + (e(0, 2) - e(2, 0)) ** 2 + (e(1, 0) - e(0, 1)) ** 2)
        else:
            da = math.acos(max(-1.0, c))
        return dp, da

    def _ok(self, q, r, p) -> bool:
        dp, da = self._verify(q, r, p)
        return dp <= self.settings.position_tolerance and da <= self.settings.orientation_tolerance

    def _analytic_nearest(self, r, p, seed) -> Tuple[float, ...]:
        lower, upper = self.limits.lower, self.limits.upper
        names = self.limits.names
        # the nearest candidate alone first (the arm branches farther than it are not solved: the
        # same first candidate in about half the time); when it does not pass, all of them
        candidates = self.analytic.solve(r, p, seed, lower, upper, nearest=True)[0]
        if candidates and self._ok(candidates[0][1], r, p):
            return candidates[0][1]
        candidates, n_raw, rejected, reason = self.analytic.solve(r, p, seed, lower, upper)
        if not n_raw:
            raise UnreachableError("pose unreachable: " + (reason or "no arm configuration reaches it"))
        if not candidates:
            i, v = rejected[0]
            v = wrap_angle(v) if self.limits.revolute[i] else v
            bad = sorted({names[j] for j, _ in rejected})
            raise JointLimitError(
                "pose reachable only outside the joint limits: all %d arm/wrist configurations violate "
                "%s (e.g. %s = %.4f rad, limits [%.4f, %.4f])"
                % (n_raw, ", ".join(bad), names[i], v, lower[i], upper[i]))
        for _, q in candidates:
            if self._ok(q, r, p):
                return q
        # numerical trouble (e.g. at a singular boundary): polish the nearest with KDL
        q = self._nr_polish(candidates[0][1], r, p)
        if q is not None:
            return q
        raise UnreachableError("pose unreachable: the analytic solution misses the pose by more than the "
                               "tolerance and KDL could not polish it")

    def _nr_polish(self, q0, r, p) -> Optional[Tuple[float, ...]]:
        target = kdl.Frame(kdl.Rotation(*r), kdl.Vector(*p))
        out = kdl.JntArray(self.dof)
        if self._nr_jl.CartToJnt(jnt_array(self.dof, q0), target, out) < 0:
            return None
        q = tuple(out[i] for i in range(self.dof))
        if self.limits.violations(q) or not self._ok(q, r, p):
            return None
        return q

    def _nearest_turns(self, q, seed) -> Tuple[float, ...]:
        """Each revolute joint moved by multiples of 2 pi towards the seed, staying within limits."""
        out = []
        for v, s, lo, hi, rev in zip(q, seed, self.limits.lower, self.limits.upper, self.limits.revolute):
            if rev:
                k = round((s - v) / TWO_PI)
                for kk in (k, k - 1, k + 1):
                    c = v + kk * TWO_PI
                    if lo <= c <= hi and abs(c - s) < abs(v - s):
                        v = c
            out.append(v)
        return tuple(out)

    def _into_limits(self, q, seed) -> Optional[Tuple[float, ...]]:
        out = []
        for v, s, lo, hi, rev in zip(q, seed, self.limits.lower, self.limits.upper, self.limits.revolute):
            if rev:
                v = turn(v, s, lo, hi)
                if v is None:
                    return None
            elif not lo <= v <= hi:
                return None
            out.append(v)
        return tuple(out)

    def _numeric(self, r, p, seed, deadline, rng, budget_ms) -> Tuple[float, ...]:
        dist = math.sqrt(sum((p[i] - self._first_point[i]) ** 2 for i in range(3)))
        if dist > self.reach_bound:
            raise UnreachableError("pose unreachable: %.4f m from the first joint, beyond the chain's "
                                   "total length %.4f m" % (dist, self.reach_bound))
        target = kdl.Frame(kdl.Rotation(*r), kdl.Vector(*p))
        out = kdl.JntArray(self.dof)
        q_init = self.limits.clamp(seed)          # NR_JL would return an out-of-limit seed unchanged
        tries = 0
        while True:
            tries += 1
            if self._nr_jl.CartToJnt(jnt_array(self.dof, q_init), target, out) >= 0:
                q = tuple(out[i] for i in range(self.dof))
                if not self.limits.violations(q) and self._ok(q, r, p):
                    return self._nearest_turns(q, seed)
            # LMA converges far more often but ignores the limits: take each joint's full turn
            # nearest the seed that fits (prismatic joints must fit as they are)
            if self._lma.CartToJnt(jnt_array(self.dof, q_init), target, out) >= 0:
                q = self._into_limits(tuple(out[i] for i in range(self.dof)), seed)
                if q is not None and self._ok(q, r, p):
                    return q
            if time.perf_counter() >= deadline:
                raise IkTimeoutError("pose unreachable: no IK solution in %d tries within the %.2f ms budget"
                                     % (tries, budget_ms))
            q_init = self.limits.random_joints(rng)
