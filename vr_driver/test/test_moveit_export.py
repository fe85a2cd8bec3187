"""What the stack gives MoveIt 1 (vr_driver.moveit, doc/moveit.md), checked without MoveIt:

- the cell as MoveIt's .scene text, read back the way MoveIt 1.1's
  ``PlanningScene::loadGeometryFromStream`` reads it (new format: an object pose, shapes with pose and
  colour, a subframe count; ``.`` ends it), holds the cell's shapes grown by the padding, and every
  point within the padding of a true shape is inside the exported one;
- the OPW parameters computed from the model give the poses of the stack's FK (KDL on the URDF) on
  1000 random configurations to 0.01 mm, also for a calibrated model with joint zero offsets, and
  every solution of the stack's analytic IK is a solution under them;
- the prefixed SRDF, controller list and joint limits, the per-protocol execution allowance, the
  command line, and the one-line refusal MoveIt's user reads."""
from __future__ import annotations

import math
import os
import random
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from vr_driver.errors import CollisionError, SceneError
from vr_driver.kinematics.collision import Contact
from vr_driver.kinematics.scene import Scene, SceneObject, load_scene
from vr_driver.moveit import config, opw, refusal, scene_text

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
CELL = os.path.join(REPO, "panasonic_vr006l_support", "config", "cell_example.yaml")
TRUE_MODEL = os.path.join(HERE, "data", "true_model_example.yaml")
NODE = os.path.join(REPO, "vr_driver", "nodes", "moveit_config")


# ------------------------------------------------------------------ MoveIt 1.1's scene reader, in Python
def read_scene(text):
    """(name, {id: (pose 4x4, [(shape, dims, pose 4x4, rgba)], subframes)}) as MoveIt 1.1 reads the
    text: the name line, then ``*`` objects; the format is "new" (object pose present) when the line
    after the first ``*`` line has a blank; numbers are read token by token; ``.`` ends it."""
    lines = text.split("\n")
    name = lines[0]
    rest = lines[1:]
    star = next(i for i, ln in enumerate(rest) if ln.startswith("*"))
    new_format = " " in rest[star + 1].strip()
    assert new_format, "MoveIt 1.1 would read the old format (no object pose)"
    tokens = iter(" ".join(rest).split())

    def nums(n):
        return [float(next(tokens)) for _ in range(n)]

    def pose():
        x, y, z, qx, qy, qz, qw = nums(7)
        t = np.eye(4)
        t[:3, :3] = SceneObject("q", "sphere", (1.0,), quaternion=(qx, qy, qz, qw)).rotation
        t[:3, 3] = (x, y, z)
        return t

    objects = {}
    while True:
        marker = next(tokens)
        if marker == ".":
            return name, objects
        assert marker == "*", "unknown marker %r" % marker
        oid = next(tokens)
        opose = pose()
        shapes = []
        for _ in range(int(next(tokens))):
            kind = next(tokens)
            dims = nums({"box": 3, "cylinder": 2, "sphere": 1}[kind])
            spose = pose()
            shapes.append((kind, dims, spose, nums(4)))
        subframes = int(next(tokens))
        assert subframes == 0
        objects[oid] = (opose, shapes, subframes)


def inside(kind, dims, local):
    """Is the point (in the shape's frame) inside the shape? (1 nm: the text's 10 digits)"""
    eps = 1e-9
    if kind == "box":
        return all(abs(c) <= d / 2.0 + eps for c, d in zip(local, dims))
    if kind == "cylinder":
        return math.hypot(local[0], local[1]) <= dims[0] + eps and abs(local[2]) <= dims[1] / 2.0 + eps
    return np.linalg.norm(local) <= dims[0] + eps


def near_surface_points(obj, distance, rng, n=400):
    """Points at ``distance`` from the true shape's surface, outside it (in base_link)."""
    out = []
    for _ in range(n):
        d = np.array([rng.gauss(0, 1) for _ in range(3)])
        d /= np.linalg.norm(d)
        if obj.shape == "sphere":
            local = d * (obj.size[0] + distance)
        elif obj.shape == "box":
            half = np.array(obj.size) / 2.0
            on = np.clip(d * 10.0, -half, half)              # a point on the box's surface
            normal = (np.abs(on) >= half - 1e-12) * np.sign(on)
            local = on + distance * normal / max(np.linalg.norm(normal), 1e-12)
        else:
            r, length = obj.size
            ang = rng.uniform(0, 2 * math.pi)
            if rng.random() < 0.5:
                local = np.array([(r + distance) * math.cos(ang), (r + distance) * math.sin(ang),
                                  rng.uniform(-length / 2, length / 2)])
            else:
                rr = rng.uniform(0, r)
                local = np.array([rr * math.cos(ang), rr * math.sin(ang),
                                  math.copysign(length / 2 + distance, rng.random() - 0.5)])
        out.append(obj.transform[:3, :3] @ local + obj.transform[:3, 3])
    return out


class TestScene:
    def test_the_example_cell_as_moveit_reads_it(self):
        cell = load_scene(CELL)
        name, objects = read_scene(scene_text.scene_text(cell, 0.01, "cell_example"))
        assert name == "cell_example"
        assert list(objects) == ["table", "pillar", "shelf"]
        for obj in cell.objects():
            opose, shapes, _ = objects[obj.name]
            np.testing.assert_allclose(opose, obj.transform, atol=1e-9)
            ((kind, dims, spose, rgba),) = shapes
            assert kind == obj.shape
            np.testing.assert_allclose(spose, np.eye(4), atol=1e-12)
            assert rgba[3] > 0
            grown = {"box": [s + 0.02 for s in obj.size], "cylinder": [obj.size[0] + 0.01, obj.size[1] + 0.02],
                     "sphere": [obj.size[0] + 0.01]}[obj.shape]
            np.testing.assert_allclose(dims, grown, atol=1e-9)

    @pytest.mark.parametrize("padding", [0.0, 0.01, 0.05])
    def test_every_point_within_the_padding_is_inside_the_exported_shape(self, padding):
        rng = random.Random(7)
        cell = Scene([SceneObject("tilted_box", "box", (0.4, 0.2, 0.1), (0.5, 0.1, 0.3), rpy=(0.3, -0.2, 1.0)),
                      SceneObject("tilted_cyl", "cylinder", (0.08, 0.5), (0.2, -0.6, 0.9), rpy=(1.1, 0.2, 0.0)),
                      SceneObject("ball", "sphere", (0.05,), (0.5, -0.5, 0.2))])
        _, objects = read_scene(scene_text.scene_text(cell, padding))
        for obj in cell.objects():
            opose, ((kind, dims, spose, _),), _ = objects[obj.name]
            frame = np.linalg.inv(opose @ spose)
            for p in near_surface_points(obj, padding * 0.999, rng):
                assert inside(kind, dims, frame[:3, :3] @ p + frame[:3, 3]), (obj.name, p)
            # and points well beyond the padding are outside (the check can fail; a grown box reaches
            # sqrt(3) x the padding diagonally from a corner)
            far = near_surface_points(obj, padding * math.sqrt(3.0) + 0.02, rng, 50)
            assert not all(inside(kind, dims, frame[:3, :3] @ p + frame[:3, 3]) for p in far), obj.name

    def test_bad_input_is_refused(self):
        cell = load_scene(CELL)
        for bad in (-0.01, float("nan"), True, "0.01"):
            with pytest.raises(SceneError, match="padding"):
                scene_text.scene_text(cell, bad)
        with pytest.raises(SceneError, match="without blanks"):
            scene_text.scene_text(Scene([SceneObject("two words", "sphere", (0.1,))]), 0.0)
        with pytest.raises(SceneError, match="one non-empty line"):
            scene_text.scene_text(cell, 0.0, "a\nb")

    def test_an_empty_cell_is_a_scene_without_objects(self):
        assert scene_text.scene_text(Scene(), 0.01, "empty") == "empty\n.\n"


class TestWorkspaceWalls:
    def test_walls_lie_on_the_faces_of_the_box_beyond_the_robot(self):
        from vr_driver.poses import Workspace
        walls = {w.name: w for w in scene_text.workspace_walls(Workspace(), base_frame_z=0.05)}
        assert sorted(walls) == ["workspace_x_max", "workspace_y_max", "workspace_y_min", "workspace_z_max"]

        def inner(name, axis, side):
            w = walls[name]
            return w.position[axis] + side * w.size[axis] / 2.0

        assert inner("workspace_x_max", 0, -1) == pytest.approx(1.4)
        assert inner("workspace_y_min", 1, +1) == pytest.approx(-0.9)
        assert inner("workspace_y_max", 1, -1) == pytest.approx(0.9)
        assert inner("workspace_z_max", 2, -1) == pytest.approx(1.45)       # 1400 mm above base, base 50 mm up
        _, objects = read_scene(scene_text.scene_text(Scene(), 0.01, walls=list(walls.values())))
        ((kind, dims, _, rgba),) = objects["workspace_x_max"][1]
        assert dims == pytest.approx(walls["workspace_x_max"].size) and rgba[3] < 0.5     # not padded, faint

    @pytest.mark.skipif(bool(__import__("vr_driver.kinematics.deps", fromlist=["x"]).missing_dependencies(
        ("pinocchio", "coal"))), reason="pinocchio / coal missing")
    def test_the_named_states_are_free_and_a_flange_beyond_the_box_touches_a_wall(self, kin):
        """With the example cell and the default box (the driver's checker, its padding): home and zero
        are free; the arm stretched up (flange above 1400 mm) or home turned right (flange 1080 mm to
        the right, beyond -900 mm) is not."""
        from vr_driver.kinematics.collision import CollisionChecker
        from vr_driver.poses import Workspace
        scene = load_scene(CELL)
        for wall in scene_text.workspace_walls(Workspace()):
            scene.add(wall)
        checker = CollisionChecker.default(padding=0.01, scene=scene)
        for q in kin.named_states.values():
            assert checker.contacts(q) == [], q
        up = (0.0, 0.0, -math.pi / 2, 0.0, 0.0, 0.0)              # forearm straight up: flange at 2.0 m
        assert kin.fk(up)[2, 3] > 1.4
        assert "workspace_z_max" in {c.other for c in checker.contacts(up)}
        right = (-1.3,) + tuple(kin.named_states["home"][1:])
        assert kin.fk(right)[1, 3] < -0.9
        assert "workspace_y_min" in {c.other for c in checker.contacts(right)}


class TestOpw:
    @pytest.fixture(scope="class")
    def kin(self):
        from vr_driver.kinematics.solver import Kinematics
        return Kinematics.default()

    def test_parameters_of_the_model(self):
        p = opw.parameters()
        assert p["opw_kinematics_geometric_parameters"] == {
            "a1": 0.15, "a2": -0.13, "b": 0.0, "c1": 0.42, "c2": 0.56, "c3": 0.56, "c4": 0.09}
        assert p["opw_kinematics_joint_sign_corrections"] == [1] * 6
        np.testing.assert_allclose(p["opw_kinematics_joint_offsets"], [0, 0, -math.pi / 2, 0, 0, math.pi])

    @staticmethod
    def worst(kin, params, n=1000, seed=1):
        rng = random.Random(seed)
        pos = rot = 0.0
        for _ in range(n):
            q = kin.random_joints(rng)
            a, b = kin.fk(q), opw.forward(params, q)
            pos = max(pos, float(np.abs(a[:3, 3] - b[:3, 3]).max()))
            rot = max(rot, float(np.abs(a[:3, :3] - b[:3, :3]).max()))
        return pos, rot

    def test_opw_forward_is_the_stacks_fk_on_1000_configurations(self, kin):
        pos, rot = self.worst(kin, opw.parameters())
        assert pos <= 1e-5 and rot <= 1e-8, (pos, rot)          # 0.01 mm

    def test_a_calibrated_model_with_zero_offsets_too(self):
        from vr_driver.kinematics.solver import Kinematics
        kin = Kinematics.from_true_model(TRUE_MODEL)
        params = opw.parameters(TRUE_MODEL)
        assert params["opw_kinematics_geometric_parameters"]["c2"] == pytest.approx(0.570)
        assert params["opw_kinematics_joint_offsets"][1] != 0.0          # joint_2's zero offset
        pos, rot = self.worst(kin, params)
        assert pos <= 1e-5 and rot <= 1e-8, (pos, rot)
        # the package's parameters do not fit it (the comparison can fail)
        assert self.worst(kin, opw.parameters(), n=50)[0] > 1e-3

    def test_every_analytic_ik_solution_is_an_opw_solution(self, kin):
        """1000 poses (FK of random configurations): each branch the stack's analytic IK returns puts
        the OPW model's flange on the pose to 0.01 mm."""
        rng = random.Random(3)
        params = opw.parameters()
        branches = 0
        for _ in range(1000):
            pose = kin.fk(kin.random_joints(rng))
            for q in kin.ik_solutions(pose)[:8]:
                branches += 1
                b = opw.forward(params, q)
                assert np.abs(b[:3, 3] - pose[:3, 3]).max() <= 1e-5
                assert np.abs(b[:3, :3] - pose[:3, :3]).max() <= 1e-6
        assert branches > 2000          # several branches per pose, not one


class TestConfig:
    def test_prefixed_srdf_names_only_the_prefixed_urdfs_links_and_joints(self):
        from panasonic_vr006l_support.description import render_urdf
        from panasonic_vr006l_support.model import RobotModel
        for prefix in ("", "left_"):
            model = RobotModel.from_urdf_string(render_urdf(mappings={"prefix": prefix} if prefix else None))
            root = ET.fromstring(config.srdf(prefix).encode())
            named = 0
            for elem in root.iter():
                for attr in config._NAME_ATTRS.get(elem.tag, ()):
                    value = elem.get(attr)
                    if value is None:
                        continue
                    named += 1
                    known = model.joints if elem.tag in ("joint", "passive_joint") else model.links
                    assert value in known, (prefix, elem.tag, attr, value)
                    assert value.startswith(prefix)
            assert named >= 20
            assert {g.get("name") for g in root.iter("group")} == {"manipulator", "endeffector"}

    def test_controller_list_and_joint_limits_with_a_prefix(self):
        (c,) = config.controller_list("left_")
        assert (c["name"], c["action_ns"], c["type"]) == ("joint_trajectory_action", "", "FollowJointTrajectory")
        assert c["joints"] == ["left_joint_%d" % i for i in range(1, 7)]
        limits = config.joint_limits(prefix="left_")
        with open(os.path.join(config.moveit_config_dir(), "config", "joint_limits.yaml")) as fh:
            plain = yaml.safe_load(fh)["joint_limits"]
        assert {k[len("left_"):]: v for k, v in limits.items()} == plain

    def test_a_models_limits_without_a_commissioning(self, tmp_path):
        with open(TRUE_MODEL) as fh:
            model = yaml.safe_load(fh)
        model["joints"]["joint_5"]["velocity"] = 4.0
        path = tmp_path / "model.yaml"
        path.write_text(yaml.safe_dump(model))
        limits = config.joint_limits(model=str(path))
        assert (limits["joint_5"]["max_velocity"], limits["joint_1"]["max_velocity"]) == (4.0, 2.09)
        del model["joints"]["joint_6"]
        path.write_text(yaml.safe_dump(model))
        with pytest.raises(config.MoveItConfigError, match="joint_6"):
            config.joint_limits(model=str(path))

    def test_the_commissioned_limits_are_the_file_beside_the_commissioning(self, tmp_path):
        commissioning = tmp_path / "g2.yaml"
        commissioning.write_text("controller: {interpreter_lookahead: 0}\n")
        lines = ["joint_limits:"] + ["  joint_%d: {has_velocity_limits: true, max_velocity: %g, "
                                     "has_acceleration_limits: true, max_acceleration: %g}" % (i, 1.0 + i, 5.0 + i)
                                     for i in range(1, 7)]
        (tmp_path / "joint_limits.yaml").write_text("\n".join(lines) + "\n")
        limits = config.joint_limits(str(commissioning))
        assert limits["joint_3"] == {"has_velocity_limits": True, "max_velocity": 4.0,
                                     "has_acceleration_limits": True, "max_acceleration": 8.0}
        # v3 on an interpreter without look-ahead stops at every point: v1's allowance
        assert config.execution_limits("v3", str(commissioning))["allowed_execution_duration_scaling"] == 2.5
        # ... and so does one whose look-ahead the commissioning could not measure (the driver streams
        # with stream_smooth 0 then); a measured look-ahead keeps v3's own allowance
        commissioning.write_text("controller: {not_measured: [interpreter_lookahead, ring_size]}\n")
        assert config.execution_limits("v3", str(commissioning))["allowed_execution_duration_scaling"] == 2.5
        commissioning.write_text("controller: {interpreter_lookahead: 2}\n")
        assert config.execution_limits("v3", str(commissioning))["allowed_execution_duration_scaling"] == 1.2
        commissioning.write_text("controller: {interpreter_lookahead: 0}\n")
        (tmp_path / "joint_limits.yaml").write_text("joint_limits: {joint_1: {has_velocity_limits: true}}\n")
        with pytest.raises(config.MoveItConfigError, match="joint_limits/joint_1/max_velocity|joint_2"):
            config.joint_limits(str(commissioning))

    def test_execution_allowance_per_protocol(self):
        assert [config.execution_limits(p)["allowed_execution_duration_scaling"] for p in ("v1", "v2", "v3")] \
            == [2.5, 1.4, 1.2]
        assert all(config.execution_limits(p)["execution_duration_monitoring"] for p in ("v1", "v2", "v3"))
        with pytest.raises(config.MoveItConfigError, match="protocol"):
            config.execution_limits("v4")


class TestCommandLine:
    def run(self, *args):
        return subprocess.run([sys.executable, NODE] + list(args), capture_output=True, text=True, timeout=60)

    def test_scene_takes_the_driver_parameter_files_padding(self, tmp_path):
        params = tmp_path / "driver.yaml"
        params.write_text("scene: %s\ncollision_padding: 0.03\n" % CELL)
        res = self.run("scene", "--config", str(params))
        assert res.returncode == 0, res.stderr
        _, objects = read_scene(res.stdout)
        assert objects["pillar"][1][0][1] == pytest.approx([0.13, 2.26])
        res = self.run("scene", CELL, "--config", str(params), "--padding=0")          # arguments win
        assert read_scene(res.stdout)[1]["pillar"][1][0][1] == pytest.approx([0.1, 2.2])

    def test_yaml_outputs_and_bad_input(self, tmp_path):
        res = self.run("kinematics", "--solver", "opw")
        assert res.returncode == 0, res.stderr
        entry = yaml.safe_load(res.stdout)
        assert entry["kinematics_solver"] == opw.PLUGIN and "kinematics_solver_attempts" not in entry
        assert entry["opw_kinematics_geometric_parameters"]["a2"] == -0.13
        res = self.run("execution", "--protocol", "v2", "--monitoring", "false")
        assert yaml.safe_load(res.stdout) == {"execution_duration_monitoring": False,
                                              "allowed_execution_duration_scaling": 1.4,
                                              "allowed_goal_duration_margin": 0.5, "allowed_start_tolerance": 0.01}
        bad = tmp_path / "bad.yaml"
        bad.write_text("objects: [{name: x, type: cone, radius: 1, position: [0, 0, 0]}]\n")
        res = self.run("scene", str(bad), "--padding", "0.01")
        assert res.returncode == 2 and res.stdout == "" and "objects[0]" in res.stderr and "type" in res.stderr
        res = self.run("scene", CELL, "--padding", "ten")
        assert res.returncode == 2 and "--padding" in res.stderr
        listed = tmp_path / "list.yaml"
        listed.write_text("- 1\n- 2\n")
        res = self.run("scene", "--config", str(listed))
        assert res.returncode == 2 and "expected a mapping" in res.stderr, res.stderr
        res = self.run("joint-limits", "--commissioning", str(tmp_path / "nowhere" / "g2.yaml"))
        assert res.returncode == 2 and "joint_limits.yaml" in res.stderr


class TestSceneNode:
    """``moveit_scene`` as the launch file starts it (roslaunch's ``__name:=`` handed on): it writes
    the .scene file, then becomes MoveIt's publish_scene_from_text -- not installed here, which it
    says (exit 1) after writing; without a cell and walls it says so and ends (exit 0)."""

    NODE = os.path.join(REPO, "vr_driver", "nodes", "moveit_scene")

    def test_it_writes_the_scene_and_names_the_missing_publisher(self, tmp_path):
        out = tmp_path / "cell.scene"
        res = subprocess.run([sys.executable, self.NODE, "--config=", "--padding=0.02", "--model=", "--workspace",
                              "-o", str(out), CELL, "__name:=moveit_scene"], capture_output=True, text=True,
                             timeout=60)
        name, objects = read_scene(out.read_text())
        assert name == "cell_example"
        assert sorted(objects) == ["pillar", "shelf", "table", "workspace_x_max", "workspace_y_max",
                                   "workspace_y_min", "workspace_z_max"]
        assert objects["pillar"][1][0][1] == pytest.approx([0.12, 2.24])
        assert res.returncode == 1 and "publish_scene_from_text is not installed" in res.stderr, res.stderr

    def test_without_a_cell_it_ends(self, tmp_path):
        params = tmp_path / "driver.yaml"
        params.write_text("scene: ''\n")
        res = subprocess.run([sys.executable, self.NODE, "--config=%s" % params, "--padding="],
                             capture_output=True, text=True, timeout=60)
        assert res.returncode == 0 and "stays empty" in res.stdout, res.stdout + res.stderr


class TestRefusal:
    def test_a_collision_with_an_object_names_the_cell_and_the_launch_argument(self):
        exc = CollisionError("trajectory collides between samples 3 and 4 of 9 (t = 0.4 s): link_4 with pillar\n"
                             "(penetration 12.0 mm); nothing was sent", [Contact("link_4", "pillar", -0.012, True)])
        text = refusal.for_moveit(exc, 0.01)
        assert "\n" not in text
        assert text.startswith("refused by the driver: trajectory collides between samples 3 and 4")
        assert "lacks pillar or the driver's padding (padding 10 mm)" in text and "scene:=CELL.yaml" in text

    def test_each_kind_names_its_setting(self):
        self_hit = CollisionError("trajectory collides: link_4 with link_6 (the arm itself)",
                                  [Contact("link_4", "link_6", -0.002, False)])
        assert "against itself" in refusal.for_moveit(self_hit, 0.01)
        assert "workspace box" in refusal.for_moveit(ValueError("point 3: Z = 1500 mm outside the workspace"))
        assert "protocol:=v2" in refusal.for_moveit(
            ValueError("point 2 of 5: leaves the start's configuration; plan a path that stays in one configuration"))
        assert "driver's log" in refusal.for_moveit(ValueError("something else"))
