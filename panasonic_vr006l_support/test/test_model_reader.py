"""model.RobotModel is the stack's one URDF reader (vr_driver.kinematics.solver.UrdfModel builds on it). It
reads the rendered VR-006L exactly as urdf_parser_py does (joints, limits, shapes, colours), and
says what is wrong with a broken URDF."""
import os
import sys
import unittest

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src"))

from panasonic_vr006l_support.description import render_urdf  # noqa: E402
from panasonic_vr006l_support.model import ModelError, RobotModel, transform  # noqa: E402

try:
    from urdf_parser_py.urdf import URDF
except ImportError:  # pragma: no cover - scripts/setup installs urdfdom-py
    URDF = None


def _origin(o):
    return transform(o.xyz if o is not None and o.xyz else (0, 0, 0), o.rpy if o is not None and o.rpy else (0, 0, 0))


@unittest.skipIf(URDF is None, "urdf_parser_py is not installed")
class SameAsUrdfParserPy(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        xml = render_urdf()
        cls.model = RobotModel.from_urdf_string(xml)
        cls.ref = URDF.from_xml_string(xml)

    def test_name_root_links(self):
        self.assertEqual(self.model.name, self.ref.name)
        self.assertEqual(self.model.root, self.ref.get_root())
        self.assertEqual(self.model.links, [link.name for link in self.ref.links])

    def test_joints(self):
        self.assertEqual(list(self.model.joints), [j.name for j in self.ref.joints])
        for ref in self.ref.joints:
            j = self.model.joints[ref.name]
            self.assertEqual((j.type, j.parent, j.child), (ref.type, ref.parent, ref.child))
            np.testing.assert_allclose(j.origin, _origin(ref.origin), atol=1e-15)
            axis = np.array(ref.axis if ref.axis is not None else (1.0, 0.0, 0.0))
            np.testing.assert_allclose(j.axis, axis / np.linalg.norm(axis), atol=1e-15)
            for attr in ("lower", "upper", "velocity", "effort"):
                self.assertEqual(getattr(j, attr), getattr(ref.limit, attr, None), (ref.name, attr))

    def test_shapes_and_colours(self):
        materials = {m.name: m for m in self.ref.materials}
        for link in self.ref.links:
            for mine, theirs in ((self.model.visuals[link.name], link.visuals),
                                 (self.model.collisions[link.name], link.collisions)):
                self.assertEqual(len(mine), len(theirs), link.name)
                for shape, elem in zip(mine, theirs):
                    g = elem.geometry
                    kind = type(g).__name__.lower()
                    size = {"box": lambda: tuple(g.size), "cylinder": lambda: (g.radius, g.length),
                            "sphere": lambda: (g.radius,)}.get(kind, lambda: ())()
                    self.assertEqual((shape.kind, shape.size), (kind, size), link.name)
                    np.testing.assert_allclose(shape.origin, _origin(elem.origin), atol=1e-15)
                    mat = getattr(elem, "material", None)
                    color = None if mat is None else (mat.color or getattr(materials.get(mat.name), "color", None))
                    self.assertEqual(shape.rgba, None if color is None else tuple(color.rgba), link.name)


class BrokenUrdf(unittest.TestCase):
    def _fails(self, xml, words):
        with self.assertRaises(ModelError) as ctx:
            RobotModel.from_urdf_string(xml)
        self.assertIn(words, str(ctx.exception))

    def test_messages(self):
        self._fails("<robot name='x'><link name='a'/>", "not valid XML")
        self._fails("<robt/>", "not <robot>")
        self._fails("<robot name='x'><link name='a'/><link name='b'/></robot>", "exactly one root link")
        joint = ("<robot name='x'><link name='a'/><link name='b'/><joint name='j' type='revolute'>"
                 "<parent link='a'/><child link='b'/>%s</joint></robot>")
        self._fails(joint % "", "a revolute joint needs a <limit>")
        self._fails(joint % "<axis xyz='0 0 0'/><limit lower='0' upper='1' velocity='1' effort='1'/>", "zero axis")
        self._fails(joint % "<origin xyz='0 nan 0'/><limit lower='0' upper='1' velocity='1' effort='1'/>",
                    "not 3 finite numbers")
        self._fails(joint % "<limit lower='1' upper='0' velocity='1' effort='1'/>", "lower limit 1 above upper")


if __name__ == "__main__":
    unittest.main()
