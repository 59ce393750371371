"""Errors through Python carry the library's messages: the same text the CLI prints."""
import os
import subprocess
import tempfile
import unittest

import mcms


class SameMessagesAsTheCli(unittest.TestCase):
    def setUp(self):
        self.cli = os.environ.get("MCMS_CLI")
        if not self.cli or not os.path.exists(self.cli):
            self.skipTest("skipped: the mcms CLI is not built (MCMS_CLI unset)")

    def cli_error(self, *args):
        with tempfile.TemporaryDirectory() as d:
            r = subprocess.run([self.cli, *args, "-o", os.path.join(d, "out")], capture_output=True, text=True)
        self.assertEqual(r.returncode, 2, r.stderr)
        prefix = "mcms: error: "
        self.assertTrue(r.stderr.startswith(prefix), r.stderr)
        return r.stderr[len(prefix):].rstrip("\n")

    def test_bad_rig_file(self):
        with tempfile.TemporaryDirectory() as d:
            rig = os.path.join(d, "rig.yaml")
            with open(rig, "w") as f:
                f.write("cameras:\n  - name: cam0\n    lensmodel: LENSMODEL_OPENCV8\n"
                        "    intrinsics: [1000, 1000, 640, 512]\n    imagersize: [1280, 1024]\n")
            with self.assertRaises(mcms.InputError) as ctx:
                mcms.CameraRig.read(rig)
            self.assertIn(rig, str(ctx.exception))
            self.assertEqual(str(ctx.exception), self.cli_error("fov-map", "--rig", rig))

    def test_bad_target_file(self):
        with tempfile.TemporaryDirectory() as d:
            target = os.path.join(d, "target.yaml")
            with open(target, "w") as f:
                f.write("name: t\nball_radius_m: 0.01\nballs_m: [[0, 0, 0], [0, 0, 0], [0.1, 0, 0]]\n")
            with self.assertRaises(mcms.InputError) as ctx:
                mcms.Target.read(target)
            self.assertEqual(str(ctx.exception), self.cli_error("fov-map", "--target", target))


if __name__ == "__main__":
    unittest.main()
