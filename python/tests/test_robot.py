"""Robot models (FK, Jacobian, covariance, IK), robot calibration, ISO 9283 and the fusion
through Python."""
import pathlib
import unittest

import numpy as np

import mcms
from mcms_test_util import real_data


def joints(robot, seed, n=1):
    """Random joint values well inside the limits."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(robot.lower, -np.pi)
    hi = np.minimum(robot.upper, np.pi)
    span = hi - lo
    return rng.uniform(lo + 0.15 * span, hi - 0.15 * span, (n, robot.num_joints))


class Kinematics(unittest.TestCase):
    def setUp(self):
        self.robot = mcms.RobotModel.default()

    def test_default_robot_zero_pose(self):
        T = self.robot.T_base_flange(np.zeros(6))
        np.testing.assert_allclose(T[:3, 3], [0.915, 0, 1.120], atol=1e-12)
        np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-12)
        frames = self.robot.link_frames(np.zeros(6))
        self.assertEqual(frames.shape, (7, 4, 4))
        np.testing.assert_allclose(frames[-1], T)

    def test_jacobian_against_finite_differences(self):
        q = joints(self.robot, 1)[0]
        J = self.robot.jacobian(q, end="flange")
        T0 = self.robot.T_base_flange(q)
        h = 1e-7
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h
            d = (mcms.box_minus(self.robot.T_base_flange(q + dq), T0) -
                 mcms.box_minus(self.robot.T_base_flange(q - dq), T0)) / (2 * h)
            np.testing.assert_allclose(J[:, i], d, atol=1e-6)
        C = self.robot.pose_covariance(q, end="flange")
        np.testing.assert_allclose(C, J @ np.diag(self.robot.encoder_sigma ** 2) @ J.T, atol=1e-20)

    def test_ik_round_trip(self):
        q = joints(self.robot, 2)[0]
        goal = self.robot.T_base_flange(q)
        sol = self.robot.solve_ik(goal, q + 0.05)
        np.testing.assert_allclose(self.robot.T_base_flange(sol), goal, atol=1e-8)
        far = goal.copy()
        far[:3, 3] += [5, 0, 0]
        with self.assertRaisesRegex(RuntimeError, "no IK solution"):
            self.robot.solve_ik(far, q)

    def test_limits_and_bad_input(self):
        with self.assertRaisesRegex(mcms.InputError, r"A1.*limit"):
            self.robot.T_base_flange([3.0, 0, 0, 0, 0, 0])
        with self.assertRaisesRegex(mcms.InputError, r"'q'.*\(6,\).*\(5,\)"):
            self.robot.T_base_flange(np.zeros(5))
        with self.assertRaisesRegex(mcms.InputError, r"'q'.*element \[2\] is nan"):
            self.robot.T_base_flange([0, 0, np.nan, 0, 0, 0])
        with self.assertRaisesRegex(mcms.InputError, r"'q'.*dtype <U1"):
            self.robot.T_base_flange(list("abcdef"))
        with self.assertRaisesRegex(mcms.InputError, "nope.yaml"):
            mcms.RobotModel.read("nope.yaml")


class Calibration(unittest.TestCase):
    def test_recovers_dh_errors(self):
        nominal = mcms.RobotModel.default()
        text = nominal.to_yaml()
        # The true robot: link 2 is 1.2 mm longer, link 3 0.8 mm shorter (a_m).
        truth_text = text.replace("a_m: 0.59999999999999998", "a_m: 0.6012", 1)
        truth_text = truth_text.replace("a_m: 0.12", "a_m: 0.1192", 1)
        self.assertNotEqual(truth_text, text, "the YAML format changed: update this test")
        truth = mcms.RobotModel.parse(truth_text, "truth")
        T_meas_base = mcms.pose_from_rt([0.01, -0.02, 0.3, 1.5, -0.4, 0.2])
        q = joints(nominal, 3, 40)
        rng = np.random.default_rng(4)
        p = np.array([(T_meas_base @ truth.T_base_tool(x))[:3, 3] for x in q]) + rng.normal(0, 2e-5, (40, 3))
        r = mcms.calibrate_robot(nominal, q, p, position_sigma_m=2e-5)
        self.assertTrue(r["converged"])
        self.assertGreater(r["errors_before"]["rms_position_m"], 5e-4)
        self.assertLess(r["errors_after"]["rms_position_m"], 4e-5)
        predicted = np.array([(r["T_meas_base"] @ r["robot"].T_base_tool(x))[:3, 3] for x in q])
        np.testing.assert_allclose(predicted - p, r["errors_after"]["dp"], atol=1e-12)
        names = [x["name"] for x in r["parameters"]]
        a2 = r["parameters"][names.index("A2.a")]
        self.assertAlmostEqual(a2["estimate"], 0.0012, delta=5 * a2["sigma"] + 1e-5)
        # Held out: the calibrated model predicts unseen poses better than the registered nominal one.
        cv = mcms.cross_validate_robot(nominal, q, p, folds=4, position_sigma_m=2e-5)
        self.assertEqual(cv["calibrated"]["dp"].shape, (40, 3))
        self.assertLess(cv["calibrated"]["rms_position_m"], 0.2 * cv["nominal"]["rms_position_m"])

    def _audit_log(self, path, offset_rad, seed):
        """A measurement log of 30 poses x 3 repeats (0.02 mm noise) from a robot whose joint 3
        reads offset_rad less than it is (a hidden joint_offset)."""
        robot = mcms.RobotModel.default()
        q = joints(robot, seed, 30)
        rng = np.random.default_rng(seed + 100)
        T_meas_base = mcms.pose_from_rt([0.01, -0.02, 0.3, 1.5, -0.4, 0.2])
        rows = ["time_s," + ",".join(f"q{j + 1}_rad" for j in range(6)) + ",x_m,y_m,z_m"]
        t = 0.0
        for rep in range(3):
            for x in q:
                true_q = x.copy()
                true_q[2] += offset_rad
                p = (T_meas_base @ robot.T_base_tool(true_q))[:3, 3] + rng.normal(0, 2e-5, 3)
                rows.append(",".join(f"{v:.12g}" for v in [t, *x, *p]))
                t += 10.0
        pathlib.Path(path).write_text("\n".join(rows) + "\n")

    def test_audit_names_a_hidden_joint_offset(self):
        import tempfile
        with tempfile.TemporaryDirectory() as d:
            log = pathlib.Path(d) / "log.csv"
            only = ["joint_offset", "link_length"]
            self._audit_log(log, np.radians(0.03), 7)
            r = mcms.audit_robot(str(log), only=only)
            self.assertEqual(r["mode"], "robot")
            self.assertFalse(r["clean"], r["text"])
            found = [e for e in r["effects"] if e["name"] == "joint_offset" and e["where"] == "joint 3"]
            self.assertEqual(len(found), 1, r["text"])
            e = found[0]
            (name, value), = e["parameters"].items()
            self.assertLess(abs(value - np.radians(0.03)), 3 * e["sigma"][name], r["text"])
            self.assertGreater(e["heldout_loglik_gain"], 0)
            self.assertIsInstance(r["extended_robot"], mcms.RobotModel)
            # The same log without the offset: clean, nothing named.
            self._audit_log(log, 0.0, 7)
            r = mcms.audit_robot(str(log), only=only)
            self.assertTrue(r["clean"], r["text"])
            self.assertEqual(r["effects"], [])
            with self.assertRaisesRegex(mcms.InputError, "false"):
                mcms.audit_robot(str(log), false_alarm=2.0)
            with self.assertRaisesRegex(mcms.InputError, "nope.csv"):
                mcms.audit_robot(str(pathlib.Path(d) / "nope.csv"))

    def test_bad_measurements_name_the_argument(self):
        robot = mcms.RobotModel.default()
        q = joints(robot, 5, 10)
        with self.assertRaisesRegex(mcms.InputError, r"'p_meas'.*\(10, 3\)"):
            mcms.calibrate_robot(robot, q, np.zeros((9, 3)))
        with self.assertRaisesRegex(mcms.InputError, "unknown calibration option 'sigma'"):
            mcms.calibrate_robot(robot, q, np.zeros((10, 3)), sigma=1)

    def test_real_positioner_measurements(self):
        folder = real_data("industrial-calibration-positioner")
        if folder is None:
            self.skipTest("skipped: real data not present: industrial-calibration-positioner")
        m = mcms.read_robot_measurements(str(folder / "measurements.yaml"))
        self.assertEqual(m["q"].shape, (205, 2))
        self.assertEqual(m["R_meas"].shape, (205, 3, 3))
        try:
            import yaml
        except ImportError:  # pragma: no cover
            self.skipTest("skipped: python3-yaml not installed")
        with open(folder / "pose_initial_guesses.yaml") as f:
            g = yaml.safe_load(f)

        def pose(d):
            w, x, y, z = (d[k] for k in ("qw", "qx", "qy", "qz"))
            n = np.sqrt(w * w + x * x + y * y + z * z)
            w, x, y, z = w / n, x / n, y / n, z / n
            T = np.eye(4)
            T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
            T[:3, 3] = [d["x"], d["y"], d["z"]]
            return T

        # The upstream model (see tests/test_calib_positioner.cpp): base at Trans(2.2, 0, 1.6) Rx(pi/2)
        # in the world, the sensor and the target mount at the upstream guesses.
        T_world_base = mcms.pose_from_rt([np.pi / 2, 0, 0, 2.2, 0.0, 1.6])
        guess = np.linalg.inv(pose(g["camera_mount_to_camera_guess"])) @ T_world_base
        positioner = mcms.RobotModel.parse(
            "name: positioner\nconvention: standard_dh\njoints:\n"
            "  - {name: j1, d_m: 0, a_m: 0, alpha_rad: -1.5707963267948966, theta_offset_rad: 0,"
            " limits_rad: [-3.141592653589793, 3.141592653589793]}\n"
            "  - {name: j2, d_m: -0.475, a_m: 0, alpha_rad: 0, theta_offset_rad: -1.5707963267948966,"
            " limits_rad: [-6.283185307179586, 6.283185307179586]}\n", "positioner")
        positioner.T_flange_tool = pose(g["target_mount_to_target_guess"])
        r = mcms.calibrate_robot(positioner, m["q"], m["p_meas"], m["R_meas"], guess, position_sigma_m=0.25e-3,
                                 rotation_sigma_rad=np.radians(0.03))
        self.assertTrue(r["converged"])
        # The upstream acceptance: mean error below 2 mm and 0.2 deg, better than the start by > 10 %.
        after = np.linalg.norm(r["errors_after"]["dp"], axis=1).mean()
        before = np.linalg.norm(r["errors_before"]["dp"], axis=1).mean()
        self.assertLess(after, 2e-3)
        self.assertLess(np.degrees(r["errors_after"]["rotation_rad"]).mean(), 0.2)
        self.assertLess(after, 0.9 * before)
        fixed = {p["name"] for p in r["parameters"] if p["fixed"]}
        self.assertEqual(fixed, {"j1.theta_offset", "j1.d", "j2.theta_offset", "j2.d", "j2.a", "j2.alpha"})


class Iso9283(unittest.TestCase):
    def test_pose_characteristics_follow_the_standard(self):
        rng = np.random.default_rng(6)
        commanded = mcms.pose_from_rt([0.1, 0.2, 0.3, 0.5, 0.1, 0.8])
        attained = np.array([mcms.box_plus(commanded, np.r_[rng.normal(0, 1e-4, 3), 2e-4 + rng.normal(0, 5e-5, 3)])
                             for _ in range(30)])
        r = mcms.iso9283_pose(commanded, attained)
        x = attained[:, :3, 3]
        bar = x.mean(axis=0)
        l = np.linalg.norm(x - bar, axis=1)
        np.testing.assert_allclose(r["barycentre"], bar, atol=1e-15)
        self.assertAlmostEqual(r["AP_p"], np.linalg.norm(bar - commanded[:3, 3]), delta=1e-15)
        self.assertAlmostEqual(r["RP_l"], l.mean() + 3 * l.std(ddof=1), delta=1e-15)
        with self.assertRaisesRegex(mcms.InputError, "2"):
            mcms.iso9283_pose(commanded, attained[:1])
        with self.assertRaisesRegex(mcms.InputError, r"'attained'.*\(N, 4, 4\)"):
            mcms.iso9283_pose(commanded, attained[:, :3])

    def test_distance_and_path(self):
        c1, c2 = np.eye(4), np.eye(4)
        c2[:3, 3] = [0.3, 0.0, 0.0]
        a1 = np.array([np.eye(4)] * 3)
        a2 = np.array([c2.copy() for _ in range(3)])
        for j, dx in enumerate([1e-4, 2e-4, 3e-4]):
            a2[j, 0, 3] += dx
        r = mcms.iso9283_distance(c1, c2, a1, a2)
        self.assertAlmostEqual(r["AD_p"], 2e-4, delta=1e-12)
        self.assertAlmostEqual(r["RD_p"], 3 * 1e-4, delta=1e-12)
        path = np.column_stack([np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)])
        runs = [path + [0, 1e-3, 0], path + [0, 3e-3, 0]]
        p = mcms.iso9283_path(path, runs)
        self.assertAlmostEqual(p["AT_p"], 2e-3, delta=1e-9)
        self.assertEqual(len(p["AT_i"]), 11)


class Fusion(unittest.TestCase):
    SETUP = """
T_base_rig:
  translation_m: [2.0, 0.5, 0.3]
  quaternion_wxyz: [0.7071067811865476, 0, 0, 0.7071067811865476]
T_flange_target:
  translation_m: [0, 0, 0.1]
  quaternion_wxyz: [1, 0, 0, 0]
robot_accuracy:
  position_sigma_m: [1e-4, 1e-4, 1e-4]
  orientation_sigma_rad: 1e-4
"""

    def test_fuses_arrays_from_camera_and_robot(self):
        setup = mcms.FusionSetup.parse(self.SETUP)
        robot = setup.robot
        q = joints(robot, 8)[0]
        T_bf = robot.T_base_flange(q)
        T_rig_target = np.linalg.inv(setup.T_base_rig) @ T_bf @ setup.T_flange_target
        n = 10
        t = 0.1 * np.arange(n)
        cov = np.diag([1e-8] * 3 + [1e-8] * 3)
        rng = np.random.default_rng(9)
        poses = np.array([mcms.box_plus(T_rig_target, rng.normal(0, 1e-4, 6)) for _ in range(n)])
        tracker = {"time_s": t, "T_rig_target": poses, "cov": np.array([cov] * n)}
        joints_log = {"time_s": np.linspace(-0.05, 1.0, 22), "q": np.tile(q, (22, 1))}
        r = mcms.fuse(setup, tracker, robot=joints_log)
        self.assertEqual(len(r["method"]), 2 * n)
        self.assertEqual(set(r["method"]), {"moifa", "kf"})
        self.assertEqual(r["T_base_flange"].shape, (2 * n, 4, 4))
        self.assertEqual(r["cov"].shape, (2 * n, 6, 6))
        for T, C, sensors in zip(r["T_base_flange"], r["cov"], r["sensors"]):
            self.assertLess(np.linalg.norm(T[:3, 3] - T_bf[:3, 3]), 1e-3)
            self.assertTrue(np.all(np.linalg.eigvalsh(C) > 0))
            self.assertIn("camera", sensors)
        # One window over the standstill: one MOIFA row, tighter than a single frame's.
        w = mcms.fuse(setup, tracker, robot=joints_log, kalman=False, windows=[[-0.01, 1.0]])
        self.assertEqual(len(w["method"]), 1)
        self.assertLess(np.trace(w["cov"][0]), np.trace(r["cov"][0]))

    def test_single_sensor_measurements(self):
        setup = mcms.FusionSetup.parse(self.SETUP)
        q = joints(setup.robot, 10)[0]
        T_bf, C_robot = mcms.robot_flange_pose(setup, q)
        np.testing.assert_allclose(T_bf, setup.robot.T_base_flange(q))
        self.assertTrue(np.all(np.linalg.eigvalsh(C_robot) > 0))
        T_rig_target = np.linalg.inv(setup.T_base_rig) @ T_bf @ setup.T_flange_target
        T_cam, C_cam = mcms.camera_flange_pose(setup, T_rig_target, np.eye(6) * 1e-8)
        np.testing.assert_allclose(T_cam, T_bf, atol=1e-12)
        with self.assertRaisesRegex(mcms.InputError, "'cov'.*positive-definite"):
            mcms.camera_flange_pose(setup, T_rig_target, -np.eye(6))

    def test_bad_streams_name_the_argument(self):
        setup = mcms.FusionSetup.parse(self.SETUP)
        tracker = {"time_s": [0.0, 0.0], "T_rig_target": np.array([np.eye(4)] * 2), "cov": np.array([np.eye(6)] * 2)}
        with self.assertRaisesRegex(mcms.InputError, r"'tracker\['time_s'\]'.*strictly increase"):
            mcms.fuse(setup, tracker, robot={"time_s": [0.0], "q": np.zeros((1, 6))})
        tracker["time_s"] = [0.0, 0.1]
        with self.assertRaisesRegex(mcms.InputError, r"'robot\['q'\]'.*\(1, 6\)"):
            mcms.fuse(setup, tracker, robot={"time_s": [0.0], "q": np.zeros((1, 5))})
        with self.assertRaisesRegex(mcms.InputError, r"missing key 'cov'"):
            mcms.fuse(setup, {"time_s": [0.0], "T_rig_target": np.eye(4)[None]})
        with self.assertRaisesRegex(mcms.InputError, "/no/such/setup.yaml"):
            mcms.fuse("/no/such/setup.yaml", tracker)


if __name__ == "__main__":
    unittest.main()
