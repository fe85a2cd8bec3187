"""The picture script draws the model at the SRDF's named poses into a real PNG."""
import os
import struct
import subprocess
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src"))

from panasonic_vr006l_support.render import main, read_group_states, default_srdf_path  # noqa: E402

PKG_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    return struct.unpack(">II", head[16:24])


class RenderTest(unittest.TestCase):
    def test_renders_zero_and_home_side_by_side(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "model.png")
            self.assertEqual(main(["--output", out]), 0)
            width, height = png_size(out)
            self.assertGreater(width, 1.5 * height)  # two views side by side
            one = os.path.join(d, "one.png")
            self.assertEqual(main(["--output", one, "--states", "home"]), 0)
            w1, h1 = png_size(one)
            self.assertEqual(h1, height)
            self.assertLess(w1, width)

    def test_unknown_state_is_refused(self):
        with tempfile.TemporaryDirectory() as d:
            self.assertEqual(main(["--output", os.path.join(d, "x.png"), "--states", "dance"]), 1)
            self.assertFalse(os.path.exists(os.path.join(d, "x.png")))

    def test_committed_picture_exists_and_script_runs_as_executable(self):
        self.assertTrue(os.path.isfile(os.path.join(PKG_DIR, "doc", "vr006l_zero_home.png")))
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "p.png")
            env = dict(os.environ)
            env["PYTHONPATH"] = os.path.join(PKG_DIR, "src") + os.pathsep + env.get("PYTHONPATH", "")
            res = subprocess.run([os.path.join(PKG_DIR, "scripts", "render_model"), "-o", out, "--collision"],
                                 capture_output=True, text=True, timeout=120, env=env)
            self.assertEqual(res.returncode, 0, res.stderr)
            self.assertEqual(res.stdout.strip(), out)
            png_size(out)

    def test_group_states_read_from_the_srdf(self):
        states = read_group_states(default_srdf_path())
        self.assertIn("home", states)
        self.assertIn("zero", states)
        self.assertEqual(sorted(states["zero"]), ["joint_%d" % i for i in range(1, 7)])


if __name__ == "__main__":
    unittest.main()
