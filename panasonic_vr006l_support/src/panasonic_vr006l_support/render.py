"""Draw the robot model's visual geometry at named poses into a PNG (matplotlib, no display needed).

    render_model [--output FILE.png] [--srdf FILE.srdf] [--states zero,home] [--collision]

Poses are the SRDF's group states (default: the moveit_config package's SRDF). The picture is drawn from
the URDF the xacro renders, so it shows exactly the model the driver and the tests use.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import xml.etree.ElementTree as ET
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .description import DescriptionError, package_dir, render_urdf
from .model import ModelError, RobotModel, Shape

DEFAULT_OUTPUT = os.path.join("doc", "vr006l_zero_home.png")


def default_srdf_path() -> str:
    try:
        import rospkg

        base = rospkg.RosPack().get_path("panasonic_vr006l_moveit_config")
    except Exception:
        base = os.path.join(os.path.dirname(package_dir()), "panasonic_vr006l_moveit_config")
    return os.path.join(base, "config", "panasonic_vr006l.srdf")


def read_group_states(srdf_path: str) -> Dict[str, Dict[str, float]]:
    """{state name: {joint: value}} of every group_state in an SRDF file."""
    try:
        root = ET.parse(srdf_path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ModelError("cannot read SRDF %s: %s" % (srdf_path, exc)) from exc
    states = {}
    for gs in root.findall("group_state"):
        states[gs.get("name")] = {j.get("name"): float(j.get("value")) for j in gs.findall("joint")}
    return states


def _primitive_faces(shape: Shape, segments: int = 28) -> List[np.ndarray]:
    """Polygons (each (k, 3)) of a primitive in its own frame."""
    if shape.kind == "box":
        x, y, z = (s / 2.0 for s in shape.size)
        c = np.array([[sx * x, sy * y, sz * z] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
        return [c[list(q)] for q in quads]
    if shape.kind == "cylinder":
        r, length = shape.size
        a = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
        ring = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
        bottom = np.column_stack([ring, np.full(segments, -length / 2.0)])
        top = np.column_stack([ring, np.full(segments, length / 2.0)])
        sides = [np.array([bottom[i], bottom[(i + 1) % segments], top[(i + 1) % segments], top[i]])
                 for i in range(segments)]
        return sides + [bottom, top]
    if shape.kind == "sphere":
        return _primitive_faces(Shape("box", (shape.size[0] * 2,) * 3, shape.origin, shape.rgba))
    return []  # meshes are not drawn


def pose_polygons(model: RobotModel, positions: Dict[str, float], collision: bool = False
                  ) -> Tuple[List[np.ndarray], List[Tuple[float, float, float, float]]]:
    poses = model.link_transforms(positions)
    shapes = model.collisions if collision else model.visuals
    polys, colors = [], []
    for link, link_shapes in shapes.items():
        for shape in link_shapes:
            t = poses[link] @ shape.origin
            for face in _primitive_faces(shape):
                polys.append(face @ t[:3, :3].T + t[:3, 3])
                colors.append(shape.rgba or (0.7, 0.7, 0.7, 1.0))
    return polys, colors


def render(model: RobotModel, states: Sequence[Tuple[str, Dict[str, float]]], output: str,
           collision: bool = False, frames: Sequence[str] = ("tool0",)) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(6.0 * len(states), 6.0), dpi=110)
    for i, (name, positions) in enumerate(states):
        ax = fig.add_subplot(1, len(states), i + 1, projection="3d")
        polys, colors = pose_polygons(model, positions, collision)
        shaded = []
        light = np.array([0.4, -0.5, 0.8]) / np.linalg.norm([0.4, -0.5, 0.8])
        for poly, rgba in zip(polys, colors):
            n = np.cross(poly[1] - poly[0], poly[2] - poly[0])
            norm = np.linalg.norm(n)
            k = 0.55 + 0.45 * abs(float(n @ light) / norm) if norm > 0 else 0.8
            shaded.append((rgba[0] * k, rgba[1] * k, rgba[2] * k, rgba[3]))
        ax.add_collection3d(Poly3DCollection(polys, facecolors=shaded, edgecolors="none"))
        poses = model.link_transforms(positions)
        for frame in frames:
            t = poses[frame]
            for axis, col in zip(range(3), ("r", "g", "b")):
                end = t[:3, 3] + 0.15 * t[:3, axis]
                ax.plot(*zip(t[:3, 3], end), color=col, linewidth=2)
            ax.text(*(t[:3, 3] + np.array([0.0, 0.0, 0.08])), frame, fontsize=8)
        g = np.linspace(-0.4, 1.4, 10)
        for v in g:
            ax.plot([v, v], [-0.9, 0.9], [0, 0], color="0.85", linewidth=0.5)
        for v in np.linspace(-0.9, 0.9, 10):
            ax.plot([-0.4, 1.4], [v, v], [0, 0], color="0.85", linewidth=0.5)
        ax.set_xlim(-0.4, 1.4)
        ax.set_ylim(-0.9, 0.9)
        ax.set_zlim(0.0, 1.8)
        ax.set_box_aspect((1.8, 1.8, 1.8))
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        ax.view_init(elev=18, azim=-60)
        flange = poses["flange"][:3, 3] * 1000.0 if "flange" in poses else None
        title = "%s pose" % name
        if flange is not None:
            title += "\nflange at x %.0f  y %.0f  z %.0f mm" % tuple(flange)
        ax.set_title(title, fontsize=10)
    fig.suptitle("Panasonic VR-006L model (%s geometry)" % ("collision" if collision else "visual"))
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(output)), exist_ok=True)
    fig.savefig(output)
    plt.close(fig)
    return output


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="render_model", description=__doc__.split("\n\n")[0])
    parser.add_argument("--output", "-o", default=os.path.join(package_dir(), DEFAULT_OUTPUT),
                        help="PNG file to write (default: the package's doc/vr006l_zero_home.png)")
    parser.add_argument("--srdf", default=None, help="SRDF with the named states (default: moveit_config's)")
    parser.add_argument("--states", default="zero,home", help="comma-separated SRDF group states to draw")
    parser.add_argument("--collision", action="store_true", help="draw the collision geometry instead")
    args = parser.parse_args(argv)
    try:
        model = RobotModel.from_urdf_string(render_urdf())
        known = read_group_states(args.srdf or default_srdf_path())
        names = [s.strip() for s in args.states.split(",") if s.strip()]
        missing = [n for n in names if n not in known]
        if missing:
            raise ModelError("no group_state %s in the SRDF (it has: %s)" % (missing, sorted(known)))
        out = render(model, [(n, known[n]) for n in names], args.output, args.collision)
    except (DescriptionError, ModelError) as exc:
        print("render_model: error: %s" % exc, file=sys.stderr)
        return 1
    print(out)
    return 0
