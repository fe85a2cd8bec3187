"""The model applies the joint zero offsets of its calibration YAML (``zero_offsets.joint_N.value``
[rad], what ``kinematic_calibration.write_yaml`` writes): each joint's origin is turned about its
axis by the offset, so the URDF's joint variable is the angle the controller shows and the true
angle = that + the offset. Without offsets the URDF is exactly as before (rpy 0 0 0)."""
from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET

import numpy as np
import yaml

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src"))

from panasonic_vr006l_support import kinematic_calibration as kc  # noqa: E402
from panasonic_vr006l_support.description import default_kinematics_yaml, render_urdf  # noqa: E402
from panasonic_vr006l_support.model import RobotModel  # noqa: E402

OFFSETS = {"joint_2": 0.005, "joint_4": -0.01, "joint_6": 0.02}


def _origins(xml):
    root = ET.fromstring(xml)
    return {j.get("name"): tuple(float(v) for v in j.find("origin").get("rpy").split())
            for j in root.findall("joint") if j.get("type") == "revolute"}


def _with_offsets(tmp_path):
    with open(default_kinematics_yaml()) as f:
        cfg = yaml.safe_load(f)
    cfg["zero_offsets"] = {name: {"value": value} for name, value in OFFSETS.items()}
    path = tmp_path / "kinematics.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return str(path)


def test_without_offsets_the_origins_are_unturned():
    assert all(rpy == (0.0, 0.0, 0.0) for rpy in _origins(render_urdf()).values())


def test_each_offset_turns_its_joint_about_its_axis(tmp_path):
    origins = _origins(render_urdf(None, {"kinematics_config": _with_offsets(tmp_path)}))
    assert origins["joint_1"] == (0.0, 0.0, 0.0) and origins["joint_3"] == (0.0, 0.0, 0.0)
    assert np.allclose(origins["joint_2"], (0.0, 0.005, 0.0))      # axis y
    assert np.allclose(origins["joint_4"], (-0.01, 0.0, 0.0))      # axis x
    assert np.allclose(origins["joint_6"], (0.02, 0.0, 0.0))       # axis x


def test_the_urdf_agrees_with_the_calibration_model(tmp_path):
    """FK of the rendered URDF at controller angles q equals the calibration's parametrised FK with
    the same offsets (the convention the fit and write_yaml use)."""
    path = _with_offsets(tmp_path)
    model = RobotModel.from_urdf_string(render_urdf(None, {"kinematics_config": path}))
    params = kc.nominal_parameters(path)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-1.0, 1.0, 6)
        tf = np.linalg.inv(model.fixed_transform("base_link", "base")) @ model.chain_fk("base_link", "flange", q[None, :])[0]
        pos, rot = kc.fk(params, q)
        assert np.allclose(tf[:3, 3], pos, atol=1e-9) and np.allclose(tf[:3, :3], rot, atol=1e-9)
