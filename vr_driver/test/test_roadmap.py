"""kinematics.roadmap: the paths of earlier plans as a hint for the next ones -- a route of them is
returned only when every motion of it passed the motion check it is given, a blocked edge is
dropped, another cell's key drops everything; and the planner and the plan action use it."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from vr_driver.kinematics import deps
from vr_driver.kinematics.roadmap import Roadmap

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")


def _wall_free(a, b, wall):
    """A 2-D motion clear of the vertical wall x in [-0.1, 0.1], y < ``wall``, sampled densely."""
    f = np.linspace(0.0, 1.0, 200)[:, None]
    p = (1 - f) * np.asarray(a) + f * np.asarray(b)
    return not np.any((np.abs(p[:, 0]) <= 0.1) & (p[:, 1] < wall))


def test_a_route_is_only_motions_the_check_passed_now_and_a_blocked_edge_is_dropped():
    """Random paths around a wall, then random queries: every route returned is free motion by
    motion by the check given (brute force); the wall raised afterwards blocks old edges, which the
    routes then go around or give up on -- never through."""
    rng = np.random.default_rng(2)
    roadmap = Roadmap((1.0, 1.0))
    for _ in range(30):      # paths over the wall's top (y > 0.5): left, top, right
        a, b = (-rng.uniform(0.3, 1.0), rng.uniform(-1, 1)), (rng.uniform(0.3, 1.0), rng.uniform(-1, 1))
        top = rng.uniform(0.6, 1.0)
        roadmap.add([a, (a[0], top), (b[0], top), b])
    for wall, n_routes in ((0.5, 10), (0.8, 0)):
        calls = []

        def free(a, b):
            calls.append((a, b))
            return _wall_free(a, b, wall)
        routes = 0
        for _ in range(40):
            q0, goal = (-rng.uniform(0.3, 1.0), rng.uniform(-1, 0.4)), (rng.uniform(0.3, 1.0), rng.uniform(-1, 0.4))
            route = roadmap.route(q0, goal, free)
            if route is None:
                continue
            routes += 1
            assert route[0] == q0 and route[-1] == goal
            assert all(_wall_free(a, b, wall) for a, b in zip(route, route[1:]))
            assert all(any(np.allclose(a, c) and np.allclose(b, d) for c, d in calls) for a, b in zip(route, route[1:]))
        assert routes >= n_routes
    assert roadmap.counts["blocked"] > 0


def test_another_cell_drops_the_roadmap():
    roadmap = Roadmap((1.0, 1.0))
    roadmap.keep(("cell A", 0.01))
    roadmap.add([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)])
    roadmap.keep(("cell A", 0.01))
    assert len(roadmap) == 3
    roadmap.keep(("cell A", 0.02))          # another padding
    assert len(roadmap) == 0 and roadmap.counts["dropped"] == 1
    assert roadmap.route((0.0, 0.0), (1.0, 1.0), lambda a, b: True) is None


_MISSING = deps.missing_dependencies(("ompl", "toppra", "pinocchio", "coal"))


@pytest.mark.skipif(bool(_MISSING), reason="; ".join(r for _, r in _MISSING))
def test_the_planner_takes_a_route_of_its_earlier_plan_and_checks_the_result(kin):
    """Around the pillar twice: the second plan is the first one's route (no search), simplified,
    timed and checked as any plan; its samples and chords are free of the true shapes."""
    from vr_driver.kinematics.collision import CollisionChecker
    from vr_driver.kinematics.planner import Planner, joint_weights
    from vr_driver.kinematics.scene import load_scene
    checker = CollisionChecker.default(scene=load_scene(CELL), padding=0.01)
    exact = CollisionChecker.default(scene=load_scene(CELL), padding=0.0)
    roadmap = Roadmap(joint_weights(kin))
    home = tuple(kin.named_states["home"])
    start, goal = (-0.3,) + home[1:], (1.3,) + home[1:]
    first = Planner(kin, checker, seed=5, roadmap=roadmap).plan(start, goal)
    assert "roadmap" not in first.timings and len(first.path) > 2 and len(roadmap) >= 3
    near = tuple(v + 0.02 for v in start)
    second = Planner(kin, checker, seed=6, roadmap=roadmap).plan(near, goal)
    assert second.timings.get("roadmap") == 1.0 and roadmap.counts["routes"] == 1
    positions = second.positions
    for a, b in zip(positions, positions[1:]):
        n = max(1, int(math.ceil(max(abs(x - y) for x, y in zip(a, b)) / math.radians(0.5))))
        assert not any(exact.in_collision([x + (y - x) * k / n for x, y in zip(a, b)]) for k in range(n + 1))
