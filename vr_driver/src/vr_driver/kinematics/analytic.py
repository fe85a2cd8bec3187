"""The closed-form IK of a six-axis industrial arm with a spherical wrist (6 revolute joints; J2
parallel to J3 and perpendicular to J1; the axes of J4, J5, J6 meet in one point), built from the
chain's zero-pose screw axes (generic: any URDF of that shape). :func:`applies` tells whether a
chain has that shape (and why not); :class:`AnalyticSolver` computes all 8 branches of a pose
(shoulder front/back x elbow up/down x wrist flip), the reach check included, in tens of
microseconds. Pure Python on floats; :mod:`vr_driver.kinematics.ik` chooses among the branches."""
from __future__ import annotations

import math
from typing import Tuple

import numpy as np

TWO_PI = 2.0 * math.pi
_GEOM_EPS = 1e-9           # tolerance of the structure detection (m, or unit-vector components)

# ====================================================================== small pure-Python 3-D helpers
# The analytic solver runs in tens of microseconds only with plain floats (numpy calls cost ~1 us each).

def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def _rotate(axis, angle, v):
    """Rodrigues: v rotated about the unit ``axis`` by ``angle``."""
    c, s = math.cos(angle), math.sin(angle)
    kx, ky, kz = axis
    cx, cy, cz = ky * v[2] - kz * v[1], kz * v[0] - kx * v[2], kx * v[1] - ky * v[0]
    d = (kx * v[0] + ky * v[1] + kz * v[2]) * (1.0 - c)
    return (v[0] * c + cx * s + kx * d, v[1] * c + cy * s + ky * d, v[2] * c + cz * s + kz * d)


def _mv(a, v):
    return (a[0] * v[0] + a[1] * v[1] + a[2] * v[2], a[3] * v[0] + a[4] * v[1] + a[5] * v[2],
            a[6] * v[0] + a[7] * v[1] + a[8] * v[2])


def _angle_about(axis, frm, to):
    """The angle that rotates ``frm`` onto ``to`` about ``axis`` (both projected onto the plane
    normal to the axis); None when ``frm`` is (nearly) parallel to the axis."""
    d = axis[0] * frm[0] + axis[1] * frm[1] + axis[2] * frm[2]
    fp = (frm[0] - axis[0] * d, frm[1] - axis[1] * d, frm[2] - axis[2] * d)    # (the same operations, inlined:
    if _norm(fp) < 1e-9:                                                        # it runs 12 times an IK)
        return None
    return math.atan2(dot(axis, cross(fp, to)), dot(fp, to))


# ================================================================================ the analytic solver

class AnalyticSolver:
    """Closed-form IK of a 6R arm with J2 || J3 _|_ J1 and a spherical wrist, from the zero-pose screw
    axes of the chain (product of exponentials: T(q) = e^[a1]q1 ... e^[a6]q6 M)."""

    def __init__(self, axes, points, tip_zero: np.ndarray):
        a = [tuple(float(c) for c in ax) for ax in axes]
        p = [tuple(float(c) for c in pt) for pt in points]
        self.a = a
        # the wrist centre: where the axes of J4 and J5 meet
        self.w0 = _closest_point(p[3], a[3], p[4], a[4])
        self.s23 = 1.0 if dot(a[1], a[2]) > 0 else -1.0
        self.p1 = p[0]
        self.a1xa2 = cross(a[0], a[1])
        self.d1 = dot(a[1], _sub(self.w0, p[0]))
        # plane of the arm (normal a2): basis e1, e2 with e1 x e2 = a2
        e1 = a[0]
        e2 = cross(a[1], e1)
        self.e1, self.e2 = e1, e2
        c2 = (dot(e1, p[1]), dot(e2, p[1]))
        c3 = (dot(e1, p[2]), dot(e2, p[2]))
        w0 = (dot(e1, self.w0), dot(e2, self.w0))
        self.c2, self.c3, self.w0p = c2, c3, w0
        self.l2 = math.hypot(c3[0] - c2[0], c3[1] - c2[1])
        self.r3 = math.hypot(w0[0] - c3[0], w0[1] - c3[1])
        self.phi2 = math.atan2(c2[1] - c3[1], c2[0] - c3[0])
        self.phiw = math.atan2(w0[1] - c3[1], w0[0] - c3[0])
        # tip (M) at zero: rotation and the wrist centre seen from the tip
        mr = tip_zero[:3, :3]
        self.w_in_tip = tuple(float(v) for v in (mr.T @ (np.array(self.w0) - tip_zero[:3, 3])))
        # wrist: subproblem-2 constants (rotate a6 by J4 then J5)
        a4, a5, a6 = a[3], a[4], a[5]
        self.c45 = dot(a4, a5)
        self.n45 = _norm(cross(a4, a5)) ** 2
        self.a4xa5 = cross(a4, a5)
        self.beta_num = dot(a5, a6)
        # a unit vector normal to a6 (for q6)
        helper = (1.0, 0.0, 0.0) if abs(a6[0]) < 0.9 else (0.0, 1.0, 0.0)
        v = cross(a6, helper)
        n = _norm(v)
        self.v6 = (v[0] / n, v[1] / n, v[2] / n)
        self.m_a6 = tuple(float(c) for c in mr.T @ np.array(a6))
        self.m_v6 = tuple(float(c) for c in mr.T @ np.array(self.v6))
        self.reach_min = abs(self.l2 - self.r3)
        self.reach_max = self.l2 + self.r3

    def solve(self, r, p, seed, lower, upper, nearest=False):
        """All branches for the tip rotation ``r`` (row-major 9-tuple) and position ``p``, each joint
        moved by +-2 pi towards ``seed`` within [lower, upper].

        Returns (candidates sorted by squared distance to the seed as (distance, q), number of
        geometric branches, [(joint index, value) that broke a limit], reason when none exists).

        ``nearest``: the arm branches (joint_1..3) within the limits nearest the seed first, and
        none whose arm alone is farther from the seed than a candidate found already (each of its
        wrist's would be farther still): the first candidate is the one of all branches, later
        ones may be missing, and the counts, limits and reasons are those of the branches solved
        (a caller that needs more than the first candidate solves again without it).
        """
        a = self.a
        a1, a2, a4, a5, a6 = a[0], a[1], a[3], a[4], a[5]
        wt = self.w_in_tip
        w = (p[0] + r[0] * wt[0] + r[1] * wt[1] + r[2] * wt[2],
             p[1] + r[3] * wt[0] + r[4] * wt[1] + r[5] * wt[2],
             p[2] + r[6] * wt[0] + r[7] * wt[1] + r[8] * wt[2])
        ta = _mv(r, self.m_a6)               # R_target M_R^T a6: where the J6 axis must point
        tv = _mv(r, self.m_v6)               # ... and a vector normal to it (for q6)
        p1 = self.p1
        u = (w[0] - p1[0], w[1] - p1[1], w[2] - p1[2])
        aa = dot(a2, u)
        bb = dot(self.a1xa2, u)
        rr = math.hypot(aa, bb)
        d = self.d1
        if rr < 1e-9:
            if abs(d) > 1e-9:
                return [], 0, [], "the wrist centre is on the joint_1 axis but the arm is offset sideways"
            q1s = (seed[0], seed[0] + math.pi)                  # shoulder singularity: keep the seed's q1
        else:
            if abs(d) > rr:
                return [], 0, [], ("the wrist centre is %.4f m from the joint_1 axis, closer than the "
                                   "arm's lateral offset %.4f m" % (rr, abs(d)))
            phi = math.atan2(bb, aa)
            delta = math.acos(d / rr)
            q1s = (phi + delta, phi - delta) if delta > 1e-12 else (phi,)
        e1, e2, c2, c3 = self.e1, self.e2, self.c2, self.c3
        l2, r3, phiw, s23 = self.l2, self.r3, self.phiw, self.s23
        q3_base = self.phi2 - phiw
        c45, n45, a4xa5, bnum = self.c45, self.n45, self.a4xa5, self.beta_num
        den = c45 * c45 - 1.0
        v6 = self.v6
        cands = []
        rejected = []
        n_raw = 0
        reason = ""
        miss = math.inf
        s0, s1, s2, s3, s4, s5 = seed
        # the arm branches in order: (arm distance to the seed, q2, q3, joints 1..3, the wrist's
        # targets), or (None, joint index, value) where a joint of the arm breaks its limits
        arms = []
        for q1 in q1s:
            x = _rotate(a1, -q1, u)
            xp0 = e1[0] * x[0] + e1[1] * x[1] + e1[2] * x[2] + dot(e1, p1) - c2[0]
            xp1 = e2[0] * x[0] + e2[1] * x[1] + e2[2] * x[2] + dot(e2, p1) - c2[1]
            dist2 = xp0 * xp0 + xp1 * xp1
            cos_psi = (l2 * l2 + r3 * r3 - dist2) / (2.0 * l2 * r3)
            if cos_psi > 1.0 + 1e-12 or cos_psi < -1.0 - 1e-12:
                # the branch that misses by least says why (J1 turned back is often far off)
                if abs(cos_psi) - 1.0 < miss:
                    miss = abs(cos_psi) - 1.0
                    dist = math.sqrt(dist2)
                    off = dist - self.reach_max if cos_psi < 0.0 else self.reach_min - dist
                    reason = ("the wrist centre is %.4f m from the shoulder (joint_2 axis), %.2f mm %s; the arm "
                              "reaches %.4f ... %.4f m" % (dist, off * 1000.0, "beyond its reach" if cos_psi < 0.0
                                                           else "too close", self.reach_min, self.reach_max))
                continue
            psi = math.acos(max(-1.0, min(1.0, cos_psi)))
            j1 = turn(q1, s0, lower[0], upper[0])
            ta1 = _rotate(a1, -q1, ta)
            tv1 = _rotate(a1, -q1, tv)
            ang_x = math.atan2(xp1, xp0)
            for q3 in ((q3_base + psi, q3_base - psi) if psi > 1e-12 else (q3_base,)):
                ang = phiw + q3
                q2 = ang_x - math.atan2(c3[1] + r3 * math.sin(ang) - c2[1], c3[0] + r3 * math.cos(ang) - c2[0])
                n_raw += 2
                if j1 is None:
                    arms.append((None, 0, q1))
                    continue
                j2 = turn(q2, s1, lower[1], upper[1])
                if j2 is None:
                    arms.append((None, 1, q2))
                    continue
                j3 = turn(q3, s2, lower[2], upper[2])
                if j3 is None:
                    arms.append((None, 2, q3))
                    continue
                arms.append(((j1 - s0) ** 2 + (j2 - s1) ** 2 + (j3 - s2) ** 2, q2, q3, j1, j2, j3, ta1, tv1))
        if nearest:
            arms = sorted((arm for arm in arms if arm[0] is not None), key=lambda arm: arm[0])
        closest = math.inf          # (nearest: the smallest distance of a candidate so far)
        for arm in arms:
            if arm[0] is None:
                rejected.append(arm[1:])
                continue
            arm_d, q2, q3, j1, j2, j3, ta1, tv1 = arm
            if nearest and arm_d > closest:
                break
            # wrist: R4 R5 R6 = rw; first put a6 onto t (Paden-Kahan subproblem 2), then q6
            q23 = -(q2 + s23 * q3)
            t = _rotate(a2, q23, ta1)
            vt = _rotate(a2, q23, tv1)
            a4t = dot(a4, t)
            alpha = (c45 * bnum - a4t) / den
            beta = (c45 * a4t - bnum) / den
            g2 = (1.0 - alpha * alpha - beta * beta - 2.0 * alpha * beta * c45) / n45
            if g2 < -1e-9:
                n_raw -= 2
                reason = reason or "the wrist cannot reach the orientation"
                continue
            g = math.sqrt(g2) if g2 > 0.0 else 0.0
            for gamma in ((g, -g) if g > 1e-9 else (0.0,)):
                z = (alpha * a4[0] + beta * a5[0] + gamma * a4xa5[0],
                     alpha * a4[1] + beta * a5[1] + gamma * a4xa5[1],
                     alpha * a4[2] + beta * a5[2] + gamma * a4xa5[2])
                q4 = _angle_about(a4, z, t)
                singular = q4 is None
                if singular:                                 # wrist singularity: keep the seed's q4
                    q4 = s3
                    z = _rotate(a4, -q4, t)
                q5 = _angle_about(a5, a6, z)
                if q5 is None:
                    continue
                v = _rotate(a5, -q5, _rotate(a4, -q4, vt))
                q6 = _angle_about(a6, v6, v)
                j4 = turn(q4, s3, lower[3], upper[3])
                j5 = turn(q5, s4, lower[4], upper[4])
                j6 = turn(q6, s5, lower[5], upper[5])
                if j4 is None or j5 is None or j6 is None:
                    bad = 3 if j4 is None else 4 if j5 is None else 5
                    rejected.append((bad, (q4, q5, q6)[bad - 3]))
                else:
                    cands.append((arm_d + (j4 - s3) ** 2 + (j5 - s4) ** 2 + (j6 - s5) ** 2,
                                  (j1, j2, j3, j4, j5, j6)))
                    closest = min(closest, cands[-1][0])
                if singular:
                    break
        cands.sort()
        return cands, n_raw, rejected, reason


def turn(v, s, lo, hi):
    """``v`` plus the multiple of 2 pi nearest ``s`` that lies within [lo, hi] (None if none)."""
    k = round((s - v) / TWO_PI)
    c = v + k * TWO_PI
    if lo - 1e-9 <= c <= hi + 1e-9:
        return hi if c > hi else lo if c < lo else c
    best = None
    for c2 in (c - TWO_PI, c + TWO_PI):
        if lo - 1e-9 <= c2 <= hi + 1e-9 and (best is None or abs(c2 - s) < abs(best - s)):
            best = hi if c2 > hi else lo if c2 < lo else c2
    return best


# ============================================================================ the structure detection

def _closest_point(p1, a1, p2, a2):
    """The midpoint of the common normal of two lines (point, unit direction)."""
    w = _sub(p1, p2)
    b = dot(a1, a2)
    den = 1.0 - b * b
    if den < 1e-12:
        return p1
    d, e = dot(a1, w), dot(a2, w)
    s = (b * e - d) / den
    t = (e - b * d) / den
    x1 = (p1[0] + s * a1[0], p1[1] + s * a1[1], p1[2] + s * a1[2])
    x2 = (p2[0] + t * a2[0], p2[1] + t * a2[1], p2[2] + t * a2[2])
    return ((x1[0] + x2[0]) / 2, (x1[1] + x2[1]) / 2, (x1[2] + x2[2]) / 2)


def _line_distance(point, p, a):
    v = _sub(point, p)
    return _norm(cross(v, a))


def applies(axes, points, types) -> Tuple[bool, str]:
    """Whether :class:`AnalyticSolver` applies to a chain with these zero-pose joint ``axes``
    (unit vectors), ``points`` on them and joint ``types``, and why not ("" when it does)."""
    if len(axes) != 6 or any(t not in ("revolute", "continuous") for t in types):
        return False, "the chain is not six revolute joints"
    a, p = axes, points
    if abs(dot(a[0], a[1])) > _GEOM_EPS:
        return False, "joint 2 is not perpendicular to joint 1"
    if _norm(cross(a[1], a[2])) > _GEOM_EPS:
        return False, "joint 3 is not parallel to joint 2"
    if _norm(cross(a[3], a[4])) < 1e-6 or _norm(cross(a[4], a[5])) < 1e-6:
        return False, "wrist axes 4/5 or 5/6 are parallel"
    w0 = _closest_point(p[3], a[3], p[4], a[4])
    if _line_distance(w0, p[3], a[3]) > _GEOM_EPS or _line_distance(w0, p[4], a[4]) > _GEOM_EPS:
        return False, "wrist axes 4 and 5 do not intersect"
    if _line_distance(w0, p[5], a[5]) > _GEOM_EPS:
        return False, "wrist axis 6 does not pass through the wrist centre"
    if _line_distance(p[2], p[1], a[1]) < 1e-6:
        return False, "joint 2 and joint 3 axes coincide"
    return True, ""
