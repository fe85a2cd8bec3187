"""The VR-006L in the OPW parameterisation (Brandstötter, Angerer, Hofbaur 2014: an ortho-parallel
base and a spherical wrist), the seven lengths and the joint offsets and signs that
``moveit_opw_kinematics_plugin`` reads, computed from the model YAML (``kinematics_vr006l.yaml`` or a
calibrated one: its dimensions and joint zero offsets).

The OPW arm at its zero points straight up: J1 about z, J2 and J3 about y, the wrist J4 z, J5 y, J6 z
of the forearm frame; ``c1`` the height of J2, ``a1`` its forward offset, ``b`` a sideways one,
``c2`` the upper arm, ``c3`` the forearm to the wrist centre, ``a2`` the elbow's offset across it,
``c4`` the wrist centre to the flange. The plugin's joint value ``q`` is the OPW angle
``q * sign - offset``. The VR-006L's zero has the forearm along +x (OPW J3 at +90 deg: offset
-pi/2), its elbow offset above the forearm (``a2 = -elbow_offset``) and ``tool0`` turned by pi about
the flange axis from the OPW flange frame (J6 offset pi); a calibrated zero offset ``z`` of a joint
(true angle = shown angle + z) adds ``-z`` to that joint's offset.

:func:`forward` is the OPW forward model written from that parameterisation; the tests check it
against the stack's FK (KDL on the URDF) on random configurations."""
from __future__ import annotations

import math
from typing import Any, Dict, Mapping, Sequence

import numpy as np

#: the plugin's class name (kinematics.yaml: kinematics_solver)
PLUGIN = "moveit_opw_kinematics_plugin/MoveItOPWKinematicsPlugin"
#: the VR-006L's zero in OPW angles (forearm along +x; tool0 turned by pi about the flange axis)
_ZERO_IN_OPW = (0.0, 0.0, math.pi / 2.0, 0.0, 0.0, math.pi)


def parameters(model_yaml: str = "") -> Dict[str, Any]:
    """The plugin's parameters for the model YAML at ``model_yaml`` ("" : the package's model):
    ``{"opw_kinematics_geometric_parameters": {a1, a2, b, c1, c2, c3, c4},
    "opw_kinematics_joint_offsets": [6], "opw_kinematics_joint_sign_corrections": [6]}``.
    A bad YAML raises panasonic_vr006l_support's CalibrationError (a ValueError) naming the key."""
    from panasonic_vr006l_support import kinematic_calibration as kc

    p = kc.nominal_parameters(model_yaml) if model_yaml else kc.nominal_parameters()
    geometric = {"a1": p["shoulder_offset"], "a2": -p["elbow_offset"], "b": 0.0, "c1": p["j2_height"],
                 "c2": p["upper_arm"], "c3": p["forearm"], "c4": p["j5_to_flange"]}
    offsets = [-(zero + p["zero_joint_%d" % (i + 1)]) for i, zero in enumerate(_ZERO_IN_OPW)]
    return {"opw_kinematics_geometric_parameters": {k: float(v) for k, v in geometric.items()},
            "opw_kinematics_joint_offsets": [_wrap(v) for v in offsets],
            "opw_kinematics_joint_sign_corrections": [1, 1, 1, 1, 1, 1]}


def _wrap(angle: float) -> float:
    """An angle in (-pi, pi] (pi stays pi: the plugin's offsets are read as written)."""
    a = math.remainder(angle, 2.0 * math.pi)
    return math.pi if abs(a + math.pi) < 1e-12 else a + 0.0     # + 0.0: no -0.0 in the YAML


def _rz(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def forward(params: Mapping[str, Any], joints: Sequence[float]) -> np.ndarray:
    """The flange frame (4x4, metres) in the base at the plugin's joint values ``joints``."""
    g = params["opw_kinematics_geometric_parameters"]
    q = [v * s - o for v, s, o in zip(joints, params["opw_kinematics_joint_sign_corrections"],
                                      params["opw_kinematics_joint_offsets"])]
    # the wrist centre in the plane of the arm (J1 turned back), then turned by J1 and lifted by c1
    elbow = q[1] + q[2] + math.atan2(g["a2"], g["c3"])
    reach = math.hypot(g["a2"], g["c3"])
    in_plane = np.array([g["a1"] + g["c2"] * math.sin(q[1]) + reach * math.sin(elbow), g["b"],
                         g["c2"] * math.cos(q[1]) + reach * math.cos(elbow)])
    centre = _rz(q[0]) @ in_plane + np.array([0.0, 0.0, g["c1"]])
    rot = _rz(q[0]) @ _ry(q[1] + q[2]) @ _rz(q[3]) @ _ry(q[4]) @ _rz(q[5])
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = centre + g["c4"] * rot[:, 2]
    return out


def kinematics_entry(model_yaml: str = "", timeout: float = 0.005) -> Dict[str, Any]:
    """The planning group's kinematics.yaml entry for the OPW plugin with :func:`parameters`."""
    entry: Dict[str, Any] = {"kinematics_solver": PLUGIN, "kinematics_solver_search_resolution": 0.005,
                             "kinematics_solver_timeout": timeout}
    entry.update(parameters(model_yaml))
    return entry
