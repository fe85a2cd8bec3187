"""A virtual G2 with its own kinematics (issue 25, item 1): panasonic_vr006l_support.true_model renders the
URDF of a robot whose dimensions and joint zeros come from a file of its own, Kinematics.from_true_model
builds its kinematics, and the virtual controller's ``true_model`` option makes the simulated arm and
the v3 program compute with it while the driver keeps the model. The example file is the model with
the upper arm +10 mm, the forearm -5 mm and joint_2's zero 0.3 deg off."""
from __future__ import annotations

import math
import os
from typing import Any, Dict

import numpy as np
import pytest
import yaml

from panasonic_vr006l_support import description, true_model
from vr_driver.controller.cli import main
from vr_driver.controller.options import SimOptions
from vr_driver.controller.simulator import SimError
from vr_driver.controller.virtual_controller import VirtualController
from vr_driver.controller.program_v3 import ControllerProgramV3
from vr_driver.errors import ModelError
from vr_driver.kinematics.solver import Kinematics
from vr_driver.poses import HOME_POSE
from vr_driver.protocol.v2 import FeedbackV2, joints_from_wire

from test_controller_v3 import START_JOINTS, RigV3, pose_error, stream_of, zigzag

EXAMPLE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "true_model_example.yaml")
D_UPPER, D_FOREARM = 0.010, -0.005               # [m] the example's changes
J2_OFFSET = math.radians(0.3)                    # [rad] the example's joint_2 zero offset
CONFIGS = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.4, -0.3, 0.0, 0.6, 0.0), (0.7, -0.5, 0.9, 1.2, -0.8, 2.0),
           (-1.9, 1.1, -1.4, -2.5, 1.7, -4.0), (2.3, 0.2, 0.5, 0.3, 0.05, 0.0)]


@pytest.fixture(scope="module")
def true_kin():
    return Kinematics.from_true_model(EXAMPLE)


def example_tree() -> Dict[str, Any]:
    with open(EXAMPLE) as f:
        return yaml.safe_load(f)


def write(tmp_path, tree, name="bad.yaml") -> str:
    path = str(tmp_path / name)
    with open(path, "w") as f:
        yaml.safe_dump(tree, f)
    return path


# ------------------------------------------------------------------------------- the true model

def test_the_example_file_reads_as_written():
    model = true_model.load(EXAMPLE)
    assert model.geometry["upper_arm"] == 0.570 and model.geometry["forearm"] == 0.555
    assert model.zero_offsets == {"joint_2": pytest.approx(J2_OFFSET, abs=1e-15)}
    assert model.accelerations == {"joint_%d" % i: 20.9 if i <= 4 else 52.3 for i in range(1, 7)}


def test_the_true_kinematics_differ_from_the_models_by_exactly_the_files_changes(kin, true_kin):
    """At each configuration q (the controller's angles): the true arm's tool0 is where the model's
    is at q with joint_2 + the offset, moved by +10 mm along the upper arm and -5 mm along the
    forearm; its orientation is the model's at that angle."""
    assert true_kin.has_analytic_solver, true_kin.analytic_reason
    assert true_kin.joint_names == kin.joint_names and true_kin.limits == kin.limits
    for q in CONFIGS:
        shifted = list(q)
        shifted[1] += J2_OFFSET
        links = kin.model.link_transforms(dict(zip(kin.joint_names, shifted)))
        expected = kin.fk(shifted)
        expected[:3, 3] += D_UPPER * links["link_2"][:3, 2] + D_FOREARM * links["link_4"][:3, 0]
        got = true_kin.fk(q)
        np.testing.assert_allclose(got, expected, atol=1e-12)
        # and the change is what it should be in size: up to 15 mm plus 0.3 deg at the arm's lever
        assert 1e-3 < np.linalg.norm(got[:3, 3] - kin.fk(q)[:3, 3]) < 0.015 + J2_OFFSET * 1.5


def test_the_true_ik_solves_its_own_fk(true_kin):
    for q in CONFIGS[1:]:
        back = true_kin.ik(true_kin.fk(q), seed=q)
        np.testing.assert_allclose(true_kin.fk(back), true_kin.fk(q), atol=1e-9)
        np.testing.assert_allclose(back, q, atol=1e-7)


def test_without_a_file_the_true_model_is_the_model(kin):
    default = Kinematics.from_true_model(None)
    again = Kinematics.from_true_model("")
    model_yaml = Kinematics.from_true_model(description.default_kinematics_yaml())   # the model's own file
    for q in CONFIGS:
        for k in (default, again, model_yaml):
            np.testing.assert_allclose(k.fk(q), kin.fk(q), atol=1e-15)
    assert true_model.render_urdf(None) == description.render_urdf()
    assert true_model.load(None).zero_offsets == {} and true_model.load(None).path is None


def test_rendering_a_file_leaves_the_packages_xacro_alone():
    urdf_dir = os.path.join(description.package_dir(), "urdf")

    def snapshot():
        out = {}
        for name in sorted(os.listdir(urdf_dir)):
            with open(os.path.join(urdf_dir, name), "rb") as f:
                out[name] = (f.read(), os.stat(os.path.join(urdf_dir, name)).st_mtime_ns)
        return out
    before = snapshot()
    true_model.render_urdf(EXAMPLE)
    assert snapshot() == before


def test_zero_offsets_follow_the_documented_sign(kin):
    """The controller's angle is the true angle minus the offset: at controller angle q the arm is
    where the model's arm is at q + offset (here on joint_4, about the forearm's axis)."""
    tree = {"geometry": example_tree()["geometry"], "joints": example_tree()["joints"]}
    tree["geometry"]["upper_arm"]["value"] = tree["geometry"]["forearm"]["value"] = 0.560
    tree["joints"]["joint_2"].pop("zero_offset")
    tree["joints"]["joint_4"]["zero_offset"] = -0.02
    k = Kinematics.from_urdf_string(true_model.render_urdf(true_model.from_mapping(tree)))
    q = CONFIGS[2]
    np.testing.assert_allclose(k.fk(q), kin.fk(np.add(q, (0, 0, 0, -0.02, 0, 0))), atol=1e-12)


def test_zero_offsets_may_sit_in_a_zero_offsets_section(tmp_path, true_kin):
    """As kinematic_calibration writes them: the same robot as joint_2's zero_offset."""
    tree = example_tree()
    offset = tree["joints"]["joint_2"].pop("zero_offset")
    tree["zero_offsets"] = {"joint_2": {"value": offset, "source": "fit"}, "joint_5": 0.0}
    model = true_model.load(write(tmp_path, tree, "section.yaml"))
    assert model.zero_offsets == {"joint_2": offset, "joint_5": 0.0}
    k = Kinematics.from_urdf_string(true_model.render_urdf(model))
    for q in CONFIGS:
        np.testing.assert_allclose(k.fk(q), true_kin.fk(q), atol=1e-15)


@pytest.mark.parametrize("change, words", [
    (lambda t: t["geometry"].pop("forearm"), ["missing key geometry.forearm"]),
    (lambda t: t.pop("joints"), ["missing key 'joints'"]),
    (lambda t: t["joints"]["joint_3"].pop("upper"), ["missing key joints.joint_3.upper"]),
    (lambda t: t["geometry"]["upper_arm"].update(value=float("nan")), ["geometry.upper_arm", "finite"]),
    (lambda t: t["joints"]["joint_2"].update(zero_offset=float("nan")), ["joints.joint_2.zero_offset", "finite"]),
    (lambda t: t["geometry"]["elbow_offset"].update(value=-0.13), ["geometry.elbow_offset", "negative"]),
    (lambda t: t["geometry"].update(wrist=0.1), ["unknown geometry key", "wrist"]),
    (lambda t: t["joints"].update(joint_7={"lower": -1, "upper": 1, "velocity": 1, "effort": 1}),
     ["unknown joint", "joint_7"]),
    (lambda t: t["joints"]["joint_1"].update(lower="far"), ["joints.joint_1.lower", "number"]),
    (lambda t: t["joints"]["joint_5"].update(lower=5.0), ["joints.joint_5", "lower limit"]),
    (lambda t: t["joints"]["joint_6"].update(zero_offset=2.0), ["joints.joint_6.zero_offset"]),
    (lambda t: t.update(zero_offsets={"joint_2": 0.001}), ["joints.joint_2.zero_offset", "zero_offsets.joint_2"]),
    (lambda t: t.update(zero_offsets={"joint_0": 0.001}), ["unknown joint", "joint_0", "zero_offsets"]),
    (lambda t: t.update(zero_offsets={"joint_3": {"value": None}}), ["zero_offsets.joint_3", "number"]),
])
def test_bad_files_are_refused_naming_the_file_and_the_key(tmp_path, change, words):
    tree = example_tree()
    change(tree)
    path = write(tmp_path, tree)
    for call in (lambda: true_model.load(path), lambda: true_model.render_urdf(path)):
        with pytest.raises(true_model.TrueModelError) as err:
            call()
        assert path in str(err.value)
        for word in words:
            assert word in str(err.value)
    with pytest.raises(ModelError, match="bad.yaml"):
        Kinematics.from_true_model(path)
    with pytest.raises(SimError, match="true_model: .*bad.yaml"):
        SimOptions(true_model=path)


def test_unreadable_files_are_refused(tmp_path):
    missing = str(tmp_path / "none.yaml")
    with pytest.raises(true_model.TrueModelError, match="cannot read the true model .*none.yaml"):
        true_model.load(missing)
    broken = tmp_path / "broken.yaml"
    broken.write_text("geometry: [1, 2\n")
    with pytest.raises(true_model.TrueModelError, match="broken.yaml is not valid YAML"):
        true_model.load(str(broken))
    assert main(["--true-model", missing]) == 2


# ----------------------------------------------------------------------- the virtual controller

def test_the_option_reaches_the_virtual_controller():
    assert SimOptions().true_model is None and SimOptions(true_model="").true_model is None
    assert SimOptions.from_mapping({"true_model": EXAMPLE}).true_model == EXAMPLE
    with pytest.raises(SimError, match="true_model must be a path"):
        SimOptions(true_model=3)
    with pytest.raises(SimError, match="do not give kinematics"):
        VirtualController(kinematics=Kinematics.from_true_model(EXAMPLE), true_model=EXAMPLE)


def test_v1_and_v2_arms_are_the_true_robot(kin, true_kin):
    """v1: the SimArm (FK, IK, planner) computes with the true robot: it starts at home in the true
    robot, with joints that differ from the model's home. v2: the joints it reports are its own
    angles (the true ones minus the zero offset)."""
    home_model = kin.ik_pose(HOME_POSE, seed=kin.named_states["home"])
    for protocol in ("v1", "v2"):
        vc = VirtualController(protocol=protocol, true_model=EXAMPLE)
        try:
            assert vc.arm.kin is not kin and vc.arm.kin.fk(CONFIGS[2]) == pytest.approx(true_kin.fk(CONFIGS[2]))
            if protocol == "v1":
                assert vc.arm.planner.kin is vc.arm.kin
            assert tuple(vc.pose) == tuple(round(v) for v in HOME_POSE.as_tuple())
            assert true_kin.fk_pose(vc.joints).as_tuple() == pytest.approx(HOME_POSE.as_tuple(), abs=1e-6)
            assert max(abs(a - b) for a, b in zip(vc.joints, home_model)) > math.radians(0.3)
            fb = vc.step()
            if protocol == "v2":
                assert isinstance(fb, FeedbackV2)
                assert joints_from_wire(fb.joints) == pytest.approx(vc.joints, abs=1e-4)
        finally:
            vc.stop()


class TrueRigV3(RigV3):
    """RigV3's master against a stepped v3 VirtualController with the true model (its slave, arm and
    program; the controller's pty is never served: the master calls the slave directly)."""

    def __init__(self, **kwargs: Any) -> None:
        self.t = 1000.0
        self.vc = VirtualController(protocol="v3", true_model=EXAMPLE, clock=self.clock, brake_time=0.2,
                                    **kwargs)
        super().__init__(self.vc.arm.kin)
        self.slave, self.arm, self.prog = self.vc.slave, self.vc.arm, self.vc.program


def test_a_pose_streamed_from_the_drivers_fk_lands_where_the_true_robot_puts_it(kin, true_kin):
    """The driver plans joints in the model and streams their poses (its FK); the virtual G2 solves
    them with its own kinematics: the arm ends exactly on the pose in the true robot, and ~the
    dimension change (plus 0.3 deg at the arm's lever) away from where the driver's model puts those
    joints -- the effect a calibration removes."""
    rig = TrueRigV3(initial_pose=kin.fk_pose(START_JOINTS).as_tuple())
    try:
        assert isinstance(rig.prog, ControllerProgramV3) and rig.prog.kin is rig.arm.kin
        rig.connect()
        plan = zigzag(4)
        stream = stream_of(kin, plan, 500, 0)
        fb = rig.run_stream(stream)
        assert fb.done_seq == stream[-1].seq
        q_end = rig.arm.joints
        assert pose_error(true_kin, q_end, stream[-1])[0] < 1e-6      # exact in the controller's own model
        off_mm, _ = pose_error(kin, q_end, stream[-1])                  # where the driver believes it is
        lever = np.linalg.norm(kin.fk(plan[-1])[:3, 3] - kin.model.link_transforms(
            dict(zip(kin.joint_names, plan[-1])))["link_2"][:3, 3])
        assert 2.0 < off_mm < 1e3 * (abs(D_UPPER) + abs(D_FOREARM) + J2_OFFSET * lever)
        # the joints differ from the plan (the collision-checked one)
        assert max(abs(a - b) for a, b in zip(q_end, plan[-1])) > math.radians(0.1)
        # the pose the controller reports is the pose it was given (its FK, whole mm / 0.01 deg)
        reported = rig.arm.pose.as_tuple()
        assert max(abs(a - b) for a, b in zip(reported[:3], stream[-1].controller_pose.as_tuple()[:3])) < 1e-6
    finally:
        rig.vc.stop()


def test_a_true_joints_sample_is_dated_by_the_arms_step_not_by_its_reading():
    """~true_joints' stamp (ros/virtual_controller.py) is the ROS time now minus the sample's age:
    the time since the program loop's step that put the arm there. Read 35 ms after that step (a
    busy machine runs the publisher late), the position is dated 35 ms back, not now -- a 0.2 s
    speed window read 13 % fast under load with the reading's time (pose_terminal_check test_11)."""
    t = [1000.0]
    for protocol in ("v1", "v3"):
        vc = VirtualController(protocol=protocol, true_model=EXAMPLE, clock=lambda: t[0])
        try:
            joints, age = vc.true_joints_sample()
            assert joints == vc.true_joints and age == 0.0          # before any step: as read
            vc.step()
            t[0] += 0.035
            joints, age = vc.true_joints_sample()
            assert joints == vc.true_joints and age == pytest.approx(0.035)
            assert joints != tuple(vc.joints)                        # the true robot's angles
        finally:
            vc.stop()
