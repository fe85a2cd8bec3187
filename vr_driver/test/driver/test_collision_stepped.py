"""The driver's collision checks (issue 27; driver/checks/scene_guard.py) on a stepped world with the fake
clock: every path is checked before anything is queued -- a move's preview (PTP), a joint path's
PTPs, a trajectory, a joint_command step -- against the example cell and the arm itself; a refusal
names the sample, the link and the object, and nothing reaches the controller (its execution log
stays empty). Scene changes change the verdict; bad scene input changes nothing. Skipped (with the
reason) where pinocchio / coal are missing, except the tests of what the driver does then."""
from __future__ import annotations

import logging
import os

import pytest

from _world import World
from vr_driver.driver import DriverCore, DriverError, MoveRequest
from vr_driver.driver.checks import scene_guard
from vr_driver.driver.checks.joint_command import JointCommandRefused
from vr_driver.driver.motion.trajectories import TrajectoryGoal, validate
from vr_driver.errors import CollisionError, MissingDependency, SceneError
from vr_driver.kinematics.deps import missing_dependencies
from vr_driver.kinematics.scene import SceneObject
from vr_driver.params import DriverParams, ParamError
from vr_driver.poses import MoveType

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")
HOME = (0.0, 0.645469, -0.280043, 0.0, 0.419972, 0.0)      # the SRDF's home (where the world starts)
#: wide enough in y for a goal beyond the pillar with the arm stretched (y = 1104 mm)
WIDE = {"workspace": {"y": [-1200.0, 1200.0]}}

_MISSING = missing_dependencies(("pinocchio", "coal"))
needs_libs = pytest.mark.skipif(bool(_MISSING), reason="; ".join(r for _, r in _MISSING))


def joints(j1=HOME[0], j2=HOME[1], j3=HOME[2], j4=HOME[3], j5=HOME[4], j6=HOME[5]):
    return (j1, j2, j3, j4, j5, j6)


def world(kin, scene=CELL, protocol="v1", **params):
    w = World(kin, dict(WIDE, scene=scene, **params), protocol=protocol)
    w.ready()
    return w


def ptp(kin, q):
    return MoveRequest(MoveType.PTP, kin.fk_pose(q))


def nothing_sent(w):
    return w.executed() == [] and w.status().counters.targets_sent == 0 and w.status().queue_length == 0


#: beyond the pillar (45 degrees left, 0.88 m out) with the arm stretched as at home: the joint_1
#: sweep from home passes through it
BEYOND = joints(j1=1.4)


@needs_libs
def test_a_ptp_through_the_pillar_is_refused_naming_the_link_and_the_object(kin):
    w = world(kin)
    with pytest.raises(CollisionError) as err:
        w.core.submit(ptp(kin, BEYOND))
    text = str(err.value)
    assert text.startswith("PTP path collides at sample ")
    assert "link_4 with pillar" in text and "penetration" in text and "(t = " in text, text
    assert err.value.sample is not None and err.value.time is not None and 0.0 < err.value.time
    assert ("link_4", "pillar") in {(c.link_a, c.other) for c in err.value.contacts}
    w.run_for(1.0)
    assert nothing_sent(w)
    assert w.core.scene_guard.refusals == 1 and "pillar" in w.core.scene_guard.last_refusal
    # a preview says the same and sends nothing either
    with pytest.raises(CollisionError, match="pillar"):
        w.core.preview(ptp(kin, BEYOND))
    assert nothing_sent(w)


@needs_libs
def test_the_same_ptp_runs_with_an_empty_scene(kin):
    w = world(kin, scene="")
    assert w.core.collision is not None and len(w.core.scene()) == 0
    job = w.core.submit(ptp(kin, BEYOND))
    assert w.finish(job).success
    assert [e[2] for e in w.executed()] == ["executed"]


@needs_libs
def test_a_joint_path_through_the_pillar_is_refused(kin):
    w = world(kin)
    with pytest.raises(DriverError, match=r"joint path point 1: PTP path collides .*link_4 with pillar"):
        w.core.submit_joint_path(w.core.joint_names, [joints(j1=0.3), BEYOND])
    w.run_for(1.0)
    assert nothing_sent(w)


def trajectory(w, times, points):
    names = w.core.joint_names
    lim = w.kin.limits
    return validate(TrajectoryGoal(tuple(names), tuple(points), tuple(times)), names, w.status().joints,
                    lim.lower, lim.upper, w.now)


#: leaning forward with the wrist down: the flange goes below the table's top (z = 0.3 m)
INTO_TABLE = joints(j2=1.0, j3=0.0, j5=1.0)


@needs_libs
@pytest.mark.parametrize("protocol", ["v1", "v2"])
def test_a_trajectory_through_the_table_is_refused(kin, protocol):
    w = world(kin, protocol=protocol)
    start = w.status().joints
    down = tuple(a + 0.5 * (b - a) for a, b in zip(start, INTO_TABLE))
    traj = trajectory(w, (0.0, 1.0, 2.0, 3.0), (start, down, INTO_TABLE, start))
    with pytest.raises(CollisionError) as err:
        w.core.submit_trajectory(traj)
    text = str(err.value)
    assert text.startswith("trajectory collides ") and "with table" in text and text.endswith("nothing was sent")
    assert "(t = " in text and 1.0 <= err.value.time <= 2.0, text
    w.run_for(1.0)
    assert nothing_sent(w)
    # the same trajectory above the table is accepted
    up = joints(j2=0.3, j3=-0.3, j5=0.6)
    ok = trajectory(w, (0.0, 1.5, 3.0), (start, up, start))
    run = w.core.submit_trajectory(ok)
    w.run_until(lambda: run.done, 20.0, "trajectory done")
    assert run.success


@needs_libs
def test_a_joint_command_step_into_the_pillar_is_refused(kin):
    w = World(kin, dict(WIDE, scene=CELL), protocol="v2", initial_pose=kin.fk_pose(joints(j1=0.4)))
    w.ready()
    start = w.status().joints
    names = w.core.joint_names
    with pytest.raises(JointCommandRefused) as err:
        w.core.joint_command(names, joints(j1=0.75), 0.2)
    assert err.value.kind == "collision"
    assert "the step from the arm's joints collides" in str(err.value) and "pillar" in str(err.value)
    assert w.core.joint_commander.counters().refused["collision"] == 1
    w.run_for(0.5)
    assert nothing_sent(w) and w.core.last_posted is None
    # a step away from it is accepted
    w.core.joint_command(names, joints(j1=0.3), 0.2)
    w.run_until(lambda: w.executed() != [], 2.0, "the step sent")
    assert abs(w.status().joints[0] - start[0]) < 0.2


#: the wrist bent back onto the forearm: link_6 hits link_4 (the SRDF does not disable the pair)
FOLDED = joints(j2=0.0, j3=0.0, j5=2.0)


@needs_libs
def test_a_self_collision_is_refused_with_an_empty_scene(kin):
    w = world(kin, scene="")
    with pytest.raises(DriverError) as err:
        w.core.submit_joint_path(w.core.joint_names, [FOLDED])
    assert "link_4 with link_6 (the arm itself" in str(err.value), str(err.value)
    w.run_for(0.5)
    assert nothing_sent(w)


@needs_libs
def test_scene_changes_change_the_verdict_and_bad_input_changes_nothing(kin):
    w = world(kin, scene="")
    goal = ptp(kin, joints(j1=-0.6))
    w.core.preview(goal)                                          # free
    checker = w.core.collision
    box = SceneObject("crate", "box", (0.3, 0.3, 0.6), position=(0.85, -0.55, 0.75))
    w.core.add_scene_object(box)
    assert w.core.collision is not checker                        # a new checker, swapped in whole
    assert w.core.scene().names() == ["crate"]
    with pytest.raises(CollisionError, match="with crate"):
        w.core.preview(goal)
    # a duplicate name without replace, a bad object: refused, nothing changes
    with pytest.raises(SceneError, match="already in the scene"):
        w.core.add_scene_object(SceneObject("crate", "sphere", (0.1,), position=(0.0, 2.0, 0.0)))
    with pytest.raises(SceneError):
        w.core.add_scene_object("crate")
    assert w.core.scene().objects() == [box]
    # replace moves it out of the way
    w.core.add_scene_object(SceneObject("crate", "box", (0.3, 0.3, 0.6), position=(0.85, -1.5, 0.75)),
                            replace=True)
    w.core.preview(goal)
    w.core.add_scene_object(box, replace=True)
    with pytest.raises(SceneError, match="no object named 'nothing'"):
        w.core.remove_scene_object("nothing")
    assert w.core.remove_scene_object("crate") == box
    w.core.preview(goal)
    # load replaces the whole scene; a bad file changes nothing
    loaded = w.core.load_scene(CELL)
    assert loaded.names() == w.core.scene().names() == ["table", "pillar", "shelf"]
    with pytest.raises(SceneError):
        w.core.load_scene(os.path.join(REPO, "nothing.yaml"))
    assert w.core.scene().names() == ["table", "pillar", "shelf"]
    w.core.clear_scene()
    assert len(w.core.scene()) == 0
    assert nothing_sent(w)


@needs_libs
def test_an_object_where_the_arm_stands_is_added_with_a_warning_and_the_arm_may_leave_it(kin, caplog):
    w = world(kin, scene="")
    tcp = kin.fk(w.status().joints)[:3, 3]
    with caplog.at_level(logging.WARNING, logger="vr_driver.driver"):
        warning = w.core.add_scene_object(SceneObject("bin", "sphere", (0.12,), position=tuple(tcp)))
    assert "current configuration collides" in warning and "link_6 with bin (penetration" in warning
    assert w.core.scene().names() == ["bin"]
    assert any("current configuration collides" in r.getMessage() and "with bin" in r.getMessage()
               for r in caplog.records)
    # deeper into something else (the wrist folded onto the forearm): refused
    with pytest.raises(DriverError, match="link_4 with link_6"):
        w.core.submit_joint_path(w.core.joint_names, [FOLDED])
    # out of the bin: backing off and up is accepted and runs
    job = w.core.submit(ptp(kin, joints(j2=0.2, j3=-0.5)))
    assert w.finish(job).success


@needs_libs
def test_collision_check_false_checks_nothing(kin):
    w = world(kin, collision_check=False)
    assert w.core.collision is None and len(w.core.scene()) == 3
    w.core.preview(ptp(kin, BEYOND))
    assert w.core.scene_guard.describe()["collision checking"].startswith("OFF (collision_check is false)")


@needs_libs
def test_padding_is_the_parameter(kin):
    near = ptp(kin, joints(j1=0.55))          # the stretched arm a few cm short of the pillar
    lo = world(kin, collision_padding=0.0)
    lo.core.preview(near)
    hi = world(kin, collision_padding=0.1)
    assert hi.core.collision.padding == 0.1
    with pytest.raises(CollisionError, match=r"with pillar \(.* mm apart, inside the 100 mm padding\)"):
        hi.core.preview(near)


def test_bad_scene_parameters_are_refused_naming_them(tmp_path):
    with pytest.raises(ParamError, match="~scene .* no such file"):
        DriverParams.from_dict({"scene": str(tmp_path / "none.yaml")})
    bad = tmp_path / "bad.yaml"
    bad.write_text("objects:\n  - {name: a, type: cone, radius: 1, position: [0, 0, 0]}\n")
    with pytest.raises(ParamError, match=r"~scene .*objects\[0\] \(a\): type must be one of"):
        DriverCore(DriverParams.from_dict({"scene": str(bad), "port": "x"}))
    for value in (-0.01, float("nan"), "0.1", True):
        with pytest.raises(ParamError, match="collision_padding"):
            DriverParams.from_dict({"collision_padding": value})
    with pytest.raises(ParamError, match="collision_check"):
        DriverParams.from_dict({"collision_check": "yes"})
    assert DriverParams.from_dict({"scene": CELL}).scene == CELL
    d = DriverParams()
    assert (d.scene, d.collision_padding, d.collision_check) == ("", 0.01, True)


def _no_libraries(prefix, model=""):
    raise MissingDependency("coal", "coal", "collision-aware planning", "ModuleNotFoundError: No module named 'coal'")


def test_without_the_libraries_a_scene_stops_the_driver_and_no_scene_warns(kin, monkeypatch, caplog):
    """Runs everywhere: the libraries are made missing."""
    monkeypatch.setattr(scene_guard, "_robot_checker", _no_libraries)
    with pytest.raises(MissingDependency, match="Python package coal"):
        DriverCore(DriverParams.from_dict(dict(WIDE, scene=CELL, port="x")), kinematics=kin)
    with caplog.at_level(logging.WARNING, logger="vr_driver.driver"):
        core = DriverCore(DriverParams.from_dict({"port": "x"}), kinematics=kin)
    assert core.collision is None
    warnings = [r.getMessage() for r in caplog.records if "collision checking is OFF" in r.getMessage()]
    assert len(warnings) == 1 and "coal" in warnings[0]
    assert core.scene_guard.describe()["collision checking"].startswith("OFF (")
    core.check_collision_path([HOME, FOLDED], "PTP path")           # nothing checked: no error
    with pytest.raises(MissingDependency):
        core.add_scene_object(SceneObject("box", "box", (0.1, 0.1, 0.1)))
    assert len(core.scene()) == 0


@needs_libs
def test_an_arm_that_stands_in_an_object_may_only_move_out_of_it(kin):
    """joint_command steps from inside a box that was added beside the wrist: a step towards it is
    refused (deeper), a step away is accepted although the arm is still inside the padding after it
    (farther out than it started), the next step away ends free."""
    w = world(kin, scene="", protocol="v2")
    names = w.core.joint_names
    start = w.status().joints
    tcp = kin.fk(start)[:3, 3]
    # the wrist's left side 20 mm into a box that stands beside it (y from 15 mm to 415 mm)
    warning = w.core.add_scene_object(SceneObject("box", "box", (0.3, 0.4, 0.3),
                                                  position=(tcp[0], 0.215, tcp[2])))
    assert "with box (penetration" in warning
    with pytest.raises(JointCommandRefused) as err:
        w.core.joint_command(names, joints(j1=start[0] + 0.02), 0.2)      # towards it: deeper
    assert err.value.kind == "collision" and "it starts in collision" in str(err.value)
    w.core.joint_command(names, joints(j1=start[0] - 0.02), 0.2)          # away: out by ~22 mm
    w.run_until(lambda: abs(w.status().joints[0] - (start[0] - 0.02)) < 1e-4, 2.0, "first step done")
    assert w.core.collision.in_collision(w.status().joints)                # still inside the padding
    w.core.joint_command(names, joints(j1=start[0] - 0.06), 0.2)
    w.run_until(lambda: abs(w.status().joints[0] - (start[0] - 0.06)) < 1e-4, 2.0, "second step done")
    assert not w.core.collision.in_collision(w.status().joints)
    # out: from here on the box is an obstacle like any other
    with pytest.raises(JointCommandRefused, match="collides .*with box") as err:
        w.core.joint_command(names, joints(j1=start[0] + 0.1), 0.2)
    assert "starts in collision" not in str(err.value)


@needs_libs
def test_with_a_calibrated_model_the_collision_model_has_its_dimensions():
    """The driver's ``model`` (calibrate fit --write) sets its kinematics; the arm it checks for
    collisions is the same arm (the links at the model's dimensions and joint zero offsets), not the
    package's: tool0 of the collision model is the driver's FK."""
    import numpy as np
    import pinocchio as pin
    from vr_driver.kinematics.solver import Kinematics
    path = os.path.join(REPO, "vr_driver", "test", "data", "true_model_example.yaml")
    core = DriverCore(DriverParams.from_dict({"port": "unused", "model": path}))
    checker = core.scene_guard.checker
    tool0 = checker.model.getFrameId("tool0")
    package = Kinematics.default()
    q = (0.3, 0.4, -0.2, 0.5, 0.6, 0.7)
    pin.framesForwardKinematics(checker.model, checker.data, checker._config(q))
    np.testing.assert_allclose(checker.data.oMf[tool0].homogeneous, core.kin.fk(q), atol=1e-9)
    assert np.abs(core.kin.fk(q)[:3, 3] - package.fk(q)[:3, 3]).max() > 0.003    # the models differ


def test_a_long_check_hands_the_interpreter_over_only_to_another_thread(monkeypatch):
    """scene_guard.hand_over: a sleep(0) between a long check's chunks lets another thread (the
    bus's) run; alone in its interpreter (the plan action's worker) the check goes on without it."""
    import threading
    naps = []
    monkeypatch.setattr(scene_guard.time, "sleep", naps.append)
    with monkeypatch.context() as alone:                # (the suite's runner may keep threads of its own)
        alone.setattr(scene_guard.threading, "active_count", lambda: 1)
        scene_guard.hand_over()
    assert naps == []
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        scene_guard.hand_over()
    finally:
        stop.set()
        other.join()
    assert naps == [0]
