"""vr_driver.kinematics.collision on the VR-006L model and the example cell: the joint vector maps to
the same arm as kinematics.solver, known contacts with the table, the pillar and the arm itself are
found and named, SRDF pairs are left out, padding moves the verdict at a known distance, check_path
stops at the first colliding sample, bad input is refused. Skipped (with the reason) where pinocchio
or coal are not installed (Python < 3.10, or scripts/setup not run); the MissingDependency message
itself is tested everywhere."""
from __future__ import annotations

import math
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from vr_driver.errors import ModelError, PoseError
from vr_driver.kinematics.deps import missing_dependencies
from vr_driver.kinematics.scene import Scene, SceneObject, load_scene

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SRC = os.path.join(REPO, "vr_driver", "src")
EXAMPLE = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")
SRDF = os.path.join(REPO, "panasonic_vr006l_moveit_config", "config", "panasonic_vr006l.srdf")
HOME = np.array([0.0, 0.645469, -0.280043, 0.0, 0.419972, 0.0])      # the SRDF's home
LINKS = ["base_link"] + ["link_%d" % i for i in range(1, 7)]

_MISSING = missing_dependencies(("pinocchio", "coal"))
needs_libs = pytest.mark.skipif(bool(_MISSING), reason="; ".join(r for _, r in _MISSING))


def test_a_missing_library_is_a_clear_error_naming_the_package_and_setup():
    """With coal blocked, building a checker raises MissingDependency (an ImportError too) naming coal
    -- not pinocchio, which fails only because it imports coal -- and scripts/setup; importing the
    module itself still works. (Where pinocchio is absent anyway, it is the one named.)"""
    missing = missing_dependencies(("pinocchio",))
    expected = missing[0][0] if missing else "coal"
    script = (
        "import sys\n"
        "sys.modules['coal'] = None\n"
        "sys.path.insert(0, %r)\n"
        "from vr_driver.kinematics.collision import CollisionChecker\n"
        "from vr_driver.errors import MissingDependency\n"
        "try:\n"
        "    CollisionChecker.from_urdf('<robot name=\"r\"/>')\n"
        "except MissingDependency as exc:\n"
        "    assert isinstance(exc, ImportError)\n"
        "    print(exc.package)\n"
        "    print(exc)\n" % SRC)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    package, text = proc.stdout.split("\n", 1)
    assert package == expected
    assert "Python package %s " % expected in text and "scripts/setup" in text, text


@pytest.fixture(scope="module")
def urdf():
    from panasonic_vr006l_support.description import render_urdf
    return render_urdf()


@pytest.fixture(scope="module")
def srdf():
    with open(SRDF) as f:
        return f.read()


@pytest.fixture(scope="module")
def cell():
    return load_scene(EXAMPLE)


@pytest.fixture()
def checker(urdf, srdf, cell):
    from vr_driver.kinematics.collision import CollisionChecker
    return CollisionChecker.from_urdf(urdf, srdf, scene=cell)


def interpolate(a, b, n=40):
    return [np.asarray(a) + (np.asarray(b) - np.asarray(a)) * t for t in np.linspace(0.0, 1.0, n)]


@needs_libs
def test_every_link_of_the_arm_has_collision_geometry(urdf, checker):
    root = ET.fromstring(urdf)
    for name in LINKS:
        link = root.find("link[@name='%s']" % name)
        assert link is not None and link.findall("collision"), name
    checked = {a for a, _, _ in checker.checked_pairs()} | {b for _, b, _ in checker.checked_pairs()}
    assert checked == set(LINKS) | {"table", "pillar", "shelf"}


@needs_libs
def test_the_joint_vector_is_the_solvers(checker, kin):
    """tool0 from pinocchio's model with q in checker.joint_names order equals kinematics.solver's FK
    (KDL, the controller's angles): same joint order, same zero offsets."""
    import pinocchio as pin

    assert checker.joint_names == kin.joint_names
    tool0 = checker.model.getFrameId("tool0")
    rng = np.random.default_rng(7)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    for _ in range(20):
        q = lo + rng.random(6) * (hi - lo)
        pin.framesForwardKinematics(checker.model, checker.data, checker._config(q))
        np.testing.assert_allclose(checker.data.oMf[tool0].homogeneous, kin.fk(q), atol=1e-9)


@needs_libs
def test_frame_point_and_point_here_are_the_kinematics_of_the_verdict(checker, kin):
    """frame_point: a point of tool0 at q as KDL's FK puts it; point_here: the same point at the q
    of the last in_collision (free and colliding configurations alike), through an outer frame;
    an unknown frame is refused, and so is point_here before any verdict."""
    rng = np.random.default_rng(3)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    point = np.array([0.01, -0.02, 0.1])
    outer = np.eye(4)
    outer[:3, 3] = (0.5, -0.25, 1.0)
    with pytest.raises(ModelError, match="no in_collision"):
        checker.copy().point_here(checker.point_probe("tool0", point))
    probe = checker.point_probe("tool0", point, outer)
    verdicts = []
    for _ in range(60):
        q = lo + rng.random(6) * (hi - lo)
        tip = kin.fk(q)
        np.testing.assert_allclose(checker.frame_point(q, "tool0", point), tip[:3, :3] @ point + tip[:3, 3],
                                   atol=1e-9)
        verdicts.append(checker.in_collision(q))
        np.testing.assert_allclose(checker.point_here(probe), tip[:3, :3] @ point + tip[:3, 3] + outer[:3, 3],
                                   atol=1e-9)
    assert any(verdicts) and not all(verdicts)
    with pytest.raises(ModelError, match="no frame 'tool9'"):
        checker.frame_point(q, "tool9")
    with pytest.raises(ModelError, match="no frame 'tool9'"):
        checker.point_probe("tool9")


@needs_libs
def test_the_broad_phase_verdicts_are_every_pairs_and_follow_the_padding_and_the_scene(checker, kin):
    """The verdicts (in_collision, first_collision, check_path: the broad phase) against every
    pair's narrow phase over random configurations, many of them within the padding of something
    (brute force; each on a new geometry data: coal's narrow phase on a data that checked other
    configurations before missed link_4 in link_6 by up to 46 mm at some of these); a new padding
    or scene drops the broad phase built for the old one."""
    import pinocchio as pin

    def narrow(q):
        data = checker.geom_model.createData()
        for req in data.collisionRequests:
            req.security_margin = checker.padding
        return bool(pin.computeCollisions(checker.model, checker.data, checker.geom_model, data,
                                          checker._config(q), False))

    rng = np.random.default_rng(11)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    qs = lo + rng.random((400, 6)) * (hi - lo)
    for padding in (0.0, 0.03):
        checker.set_padding(padding)
        truth = [narrow(q) for q in qs]
        assert [checker.in_collision(q) for q in qs] == truth
        assert [bool(checker.contacts(q)) for q in qs] == truth          # the words name them all
        assert 0 < sum(truth) < len(truth)
        near = sum(1 for q, hit in zip(qs, truth) if hit and checker.min_distance(q) >= 0.0)
        assert padding == 0.0 or near > 10            # verdicts inside the padding were compared
        for k in range(0, 400, 40):
            first = next((i for i in range(k, k + 40) if truth[i]), None)
            assert checker.first_collision(qs[k:k + 40]) == (None if first is None else first - k)
            found = checker.check_path(qs[k:k + 40])
            assert (found and found[0]) == (None if first is None else first - k)
    assert checker.first_collision(np.zeros((0, 6))) is None
    with pytest.raises(PoseError):
        checker.first_collision([(0.0,) * 5 + (math.nan,)])
    free = next(q for q, hit in zip(qs, truth) if not hit and checker.min_distance(q) < 0.05)
    checker.set_padding(0.0)
    assert not checker.in_collision(free)
    checker.set_padding(0.06)
    assert checker.in_collision(free)
    checker.set_padding(0.0)
    tcp = kin.fk(free)[:3, 3]
    checker.set_scene(Scene([SceneObject("block", "box", (0.1, 0.1, 0.1), tuple(tcp))]))
    assert checker.in_collision(free) and checker.first_collision([HOME, free]) == 1
    checker.set_scene(Scene())
    assert not checker.in_collision(free)
    # a copy shares the models built, not its padding, scene or verdicts
    copy = checker.copy()
    copy.set_padding(0.06)
    assert copy.in_collision(free) and not checker.in_collision(free)
    copy.set_padding(0.0)
    copy.set_scene(Scene([SceneObject("block", "box", (0.1, 0.1, 0.1), tuple(tcp))]))
    assert copy.in_collision(free) and not checker.in_collision(free) and not checker.scene.names()


@needs_libs
@pytest.mark.parametrize("cell_file", [EXAMPLE, os.path.join(REPO, "bench", "cells", "hood_post.yaml")])
def test_distances_are_a_fresh_datas_whatever_was_asked_before(urdf, srdf, kin, cell_file):
    """min_distance and nearest against every pair's distance on a new geometry data (brute force)
    over random configurations of both cells, asked in an order that mixes them: the same numbers
    exactly. On the checker's one data, reused from call to call, coal's narrow phase kept what it
    found at the configurations before: depths 1 to 3 um apart at 5 to 8 of 3 000 (the scene guard
    compares depths to 1 um)."""
    import pinocchio as pin

    from vr_driver.kinematics.collision import CollisionChecker
    checker = CollisionChecker.from_urdf(urdf, srdf, scene=load_scene(cell_file))

    def brute(q):
        data = checker.geom_model.createData()
        for req in data.distanceRequests:
            req.enable_signed_distance = True
        pin.computeDistances(checker.model, checker.data, checker.geom_model, data, checker._config(q))
        return [float(r.min_distance) for r in data.distanceResults]

    rng = np.random.default_rng(5)
    lo, hi = np.array(kin.limits.lower), np.array(kin.limits.upper)
    qs = lo + rng.random((300, 6)) * (hi - lo)
    truth = [brute(q) for q in qs]
    assert sum(1 for d in truth if min(d) < 0.0) > 30         # penetrations among them: depths compared
    for k in list(range(0, 300, 2)) + list(range(299, 0, -2)):    # (each asked after others than before)
        d = truth[k]
        assert checker.min_distance(qs[k]) == min(d)
        near = checker.nearest(qs[k])
        assert near.distance == min(d) and checker.checked_pairs()[int(np.argmin(d))][:2] == (near.link_a, near.other)


@needs_libs
def test_home_and_zero_are_free_in_the_example_cell(checker):
    for q in (HOME, np.zeros(6)):
        assert not checker.in_collision(q)
        assert checker.contacts(q) == []
        assert checker.min_distance(q) > 0.05


@needs_libs
def test_reaching_into_the_table_names_the_links_and_the_table(checker):
    q = [0.0, 1.0, 0.0, 0.0, 1.0, 0.0]            # leaning forward, wrist down: flange below the top
    assert checker.in_collision(q)
    found = checker.contacts(q)
    assert {(c.link_a, c.other, c.world) for c in found} >= {("link_6", "table", True)}
    assert all(c.world and c.other == "table" for c in found), found
    assert all(c.distance < 0 for c in found)
    assert checker.min_distance(q) == pytest.approx(min(c.distance for c in found), abs=1e-9)
    assert "link_6 with object table" in str(found[0]) or "table" in str(found[0])


@needs_libs
def test_turning_the_stretched_arm_left_hits_the_pillar(checker):
    q = HOME.copy()
    q[0] = 0.8                                     # the pillar stands at 45 degrees, 0.88 m out
    found = checker.contacts(q)
    assert checker.in_collision(q)
    assert ("link_4", "pillar") in {(c.link_a, c.other) for c in found}


@needs_libs
def test_raising_the_forearm_turned_right_hits_the_shelf(checker):
    q = HOME.copy()
    q[0], q[2] = -0.9, -0.5                        # turned 52 degrees right, forearm raised 13 degrees
    assert checker.in_collision(q)
    assert {c.other for c in checker.contacts(q)} == {"shelf"}
    q[2] = HOME[2] + 0.3                           # the same turn with the forearm lowered passes under it
    assert not checker.in_collision(q)


@needs_libs
def test_a_folded_wrist_hits_the_forearm_unless_the_srdf_disables_the_pair(urdf, srdf, checker):
    from vr_driver.kinematics.collision import CollisionChecker

    folded = [0.0, 0.0, 0.0, 0.0, 2.0, 0.0]      # wrist bent back 115 degrees onto the forearm
    assert checker.in_collision(folded)
    assert [(c.link_a, c.other, c.world) for c in checker.contacts(folded)] == [("link_4", "link_6", False)]
    more = srdf.replace("</robot>", '<disable_collisions link1="link_6" link2="link_4" reason="Test"/></robot>')
    relaxed = CollisionChecker.from_urdf(urdf, more)
    assert not relaxed.in_collision(folded)
    assert ("link_4", "link_6", False) not in relaxed.checked_pairs()


@needs_libs
def test_srdf_pairs_and_adjacent_links_are_not_checked(urdf, srdf, checker):
    from vr_driver.kinematics.collision import CollisionChecker, read_disabled_pairs

    pairs = {frozenset((a, b)) for a, b, world in checker.checked_pairs() if not world}
    disabled = read_disabled_pairs(srdf)
    assert frozenset(("base_link", "link_2")) in disabled
    assert not pairs & disabled
    assert frozenset(("link_4", "link_6")) in pairs
    # without an SRDF the links joined by one joint are left out, the rest checked
    bare = CollisionChecker.from_urdf(urdf)
    bare_pairs = {frozenset((a, b)) for a, b, _ in bare.checked_pairs()}
    assert frozenset(("link_3", "link_4")) not in bare_pairs
    assert frozenset(("base_link", "link_2")) in bare_pairs
    assert not bare.in_collision(HOME)


@needs_libs
def test_the_fixed_base_is_not_checked_against_the_scene(urdf, srdf):
    """The surface the robot stands on touches base_link: it must not make every pose collide."""
    from vr_driver.kinematics.collision import CollisionChecker

    floor = Scene([SceneObject("floor", "box", (3.0, 3.0, 0.1), (0.0, 0.0, -0.05))])
    c = CollisionChecker.from_urdf(urdf, srdf, scene=floor)
    assert not c.in_collision(HOME)
    assert ("base_link", "floor", True) not in c.checked_pairs()
    assert c.in_collision([0.0, 1.8, 0.6, 0.0, 0.0, 0.0])     # the forearm down on the floor


@needs_libs
def test_padding_changes_the_verdict_at_a_known_distance(urdf, srdf):
    """At zero the upper arm (a 0.12 m deep box around x = 0.15) has its front face at x = 0.21: a
    ball of radius 0.05 at x = 0.29 is 30 mm away from it, and nothing else is nearer."""
    from vr_driver.kinematics.collision import CollisionChecker

    ball = Scene([SceneObject("ball", "sphere", (0.05,), (0.29, 0.0, 0.7))])
    c = CollisionChecker.from_urdf(urdf, srdf, padding=0.02, scene=ball)
    zero = np.zeros(6)
    assert c.nearest(zero).other == "ball" and c.nearest(zero).link_a == "link_2"
    assert c.nearest(zero).distance == pytest.approx(0.03, abs=1e-6)
    assert not c.in_collision(zero) and c.contacts(zero) == []
    c.set_padding(0.04)
    assert c.in_collision(zero)
    (contact,) = c.contacts(zero)
    assert (contact.link_a, contact.other, contact.world) == ("link_2", "ball", True)
    assert contact.distance == pytest.approx(0.03, abs=1e-6)       # the true distance, not the padded one
    # the constructor's padding does the same
    assert CollisionChecker.from_urdf(urdf, srdf, padding=0.04, scene=ball).in_collision(zero)
    # joint_1 turns the arm away from the ball: free again with the same padding
    assert not c.in_collision([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("obj", [
    SceneObject("cyl_x", "cylinder", (0.05, 0.3), (0.39, 0.0, 0.7), rpy=(0.0, math.pi / 2, 0.0)),
    SceneObject("cyl_z", "cylinder", (0.05, 0.3), (0.29, 0.0, 0.7)),
    SceneObject("box_x", "box", (0.3, 0.1, 0.1), (0.39, 0.0, 0.7)),
    SceneObject("box_yawed", "box", (0.1, 0.3, 0.1), (0.39, 0.0, 0.7), rpy=(0.0, 0.0, math.pi / 2)),
    SceneObject("box_quat", "box", (0.1, 0.3, 0.1), (0.39, 0.0, 0.7),
                quaternion=(0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))),
])
@needs_libs
def test_sizes_are_full_lengths_and_poses_turn_the_shape(urdf, srdf, obj):
    """Each solid, turned so that its long side points away from the upper arm, starts 30 mm in front
    of the arm's face at x = 0.21 (the cylinder's length and the box's size are full lengths, a
    cylinder's axis is its z, rpy and quaternion rotate it)."""
    from vr_driver.kinematics.collision import CollisionChecker

    c = CollisionChecker.from_urdf(urdf, srdf, scene=Scene([obj]))
    nearest = c.nearest(np.zeros(6))
    assert (nearest.link_a, nearest.other) == ("link_2", obj.name)
    assert nearest.distance == pytest.approx(0.03, abs=1e-6)


@needs_libs
def test_touching_counts_as_collision(urdf, srdf):
    from vr_driver.kinematics.collision import CollisionChecker

    for x, hit in ((0.2601, False), (0.26, True), (0.2599, True)):
        c = CollisionChecker.from_urdf(urdf, srdf, scene=Scene([SceneObject("ball", "sphere", (0.05,), (x, 0.0, 0.7))]))
        assert c.in_collision(np.zeros(6)) is hit, x


@needs_libs
def test_check_path_finds_the_first_colliding_sample(checker):
    goal = HOME.copy()
    goal[0] = 1.4                                   # beyond the pillar, same arm pose
    straight = interpolate(HOME, goal)
    first = next(i for i, q in enumerate(straight) if checker.in_collision(q))
    assert 0 < first < len(straight) - 1
    hit = checker.check_path(straight)
    assert hit is not None
    index, found = hit
    assert index == first
    assert "pillar" in {c.other for c in found}
    # the detour: raise the forearm and straighten the upper arm, turn, lower again
    retract = np.array([0.0, 0.0, -1.2, 0.0, 0.4, 0.0])
    turned = retract.copy()
    turned[0] = 1.4
    detour = interpolate(HOME, retract) + interpolate(retract, turned) + interpolate(turned, goal)
    assert checker.check_path(detour) is None
    assert checker.check_path([]) is None


@needs_libs
def test_set_scene_replaces_the_world(checker, cell):
    q = [0.0, 1.0, 0.0, 0.0, 1.0, 0.0]
    assert checker.in_collision(q)
    checker.set_scene(Scene())
    assert not checker.in_collision(q) and checker.scene.names() == []
    assert all(not world for _, _, world in checker.checked_pairs())
    changed = cell.copy()
    changed.remove("table")
    checker.set_scene(changed)
    assert not checker.in_collision(q)
    changed.add(SceneObject("box", "box", (0.5, 0.5, 0.5), (1.0, 0.0, 0.3)))   # a snapshot: not seen yet
    assert not checker.in_collision(q)
    checker.set_scene(changed)
    assert [c.other for c in checker.contacts(q)][0] == "box"


@needs_libs
def test_bad_input_is_refused(checker, urdf):
    from vr_driver.kinematics.collision import CollisionChecker

    for bad in ([0.0] * 5, [0.0] * 7, [0.0, float("nan"), 0, 0, 0, 0], "abc", [0.5], "abcdef", np.zeros(1)):
        with pytest.raises(PoseError):
            checker.in_collision(bad)
    with pytest.raises(PoseError, match="joint_3"):
        checker.contacts([0, 0, float("inf"), 0, 0, 0])
    collides = [0.0, 1.0, 0.0, 0.0, 1.0, 0.0]
    with pytest.raises(PoseError):           # every sample is validated before the first is checked
        checker.check_path([collides, [0.0] * 5])
    for padding in (-0.01, float("nan"), True, "0.1"):
        with pytest.raises(ValueError):
            checker.set_padding(padding)
    assert checker.padding == 0.0
    with pytest.raises(ModelError):
        CollisionChecker.from_urdf("<robot name='x'><link name='a'/>")
    with pytest.raises(ModelError, match="no joint 'joint_9'"):
        CollisionChecker.from_urdf(urdf, joint_names=["joint_9"])
    with pytest.raises(ModelError, match="SRDF"):
        CollisionChecker.from_urdf(urdf, "<robot><disable_collisions link1='a'/></robot>")


@needs_libs
def test_a_prefixed_model_takes_the_same_vectors():
    from vr_driver.kinematics.collision import CollisionChecker

    c = CollisionChecker.default(prefix="left_", scene=load_scene(EXAMPLE))
    assert c.joint_names == tuple("left_joint_%d" % i for i in range(1, 7))
    assert not c.in_collision(HOME)
    assert {x.other for x in c.contacts([0.0, 1.0, 0.0, 0.0, 1.0, 0.0])} == {"table"}
    assert [(x.link_a, x.other) for x in c.contacts([0.0, 0.0, 0.0, 0.0, 2.0, 0.0])] == [("left_link_4", "left_link_6")]


@needs_libs
def test_copy_is_independent(checker):
    other = checker.copy()
    other.set_scene(Scene())
    q = [0.0, 1.0, 0.0, 0.0, 1.0, 0.0]
    assert checker.in_collision(q) and not other.in_collision(q)
