"""Triangulation, the tracker (points and images in, poses with 6x6 covariance out), the audit
and the field-of-view prediction through Python."""
import os
import tempfile
import unittest

import numpy as np

import mcms
from mcms_test_util import pinhole_rig, transform

try:
    import cv2
except ImportError:  # pragma: no cover
    cv2 = None


def target_pose(angle=0.3, t=(0.02, -0.01, 0.05)):
    c, s = np.cos(angle), np.sin(angle)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = t
    return T


def ball_pixels(rig, balls_rig):
    """Per camera an (N, 2) array of the ball centres' projections."""
    out = []
    for cam in rig.cameras:
        out.append(cam.project(transform(cam.T_cam_rig, balls_rig)))
    return out


class Triangulation(unittest.TestCase):
    def setUp(self):
        self.rig = pinhole_rig(4)
        self.p = np.array([0.05, -0.03, 0.1])

    def test_recovers_the_point_with_covariance(self):
        q = [cam.project(transform(cam.T_cam_rig, self.p)) for cam in self.rig.cameras]
        r = mcms.triangulate(self.rig, q, sigma_px=0.1)
        np.testing.assert_allclose(r["p_rig"], self.p, atol=1e-9)
        self.assertEqual(r["views"], 4)
        self.assertTrue(np.all(np.linalg.eigvalsh(r["cov"]) > 0))
        # Fewer views, larger covariance.
        r2 = mcms.triangulate(self.rig, [q[0], q[1], None, None], sigma_px=0.1)
        self.assertGreater(np.trace(r2["cov"]), np.trace(r["cov"]))
        self.assertIsNone(mcms.triangulate(self.rig, [q[0], None, None, None]))
        # Per-camera covariances: a camera with 4x the variance gets less weight; None = sigma_px.
        r3 = mcms.triangulate(self.rig, q, covariances=[np.eye(2) * 0.04, None, None, None], sigma_px=0.1)
        self.assertGreater(np.trace(r3["cov"]), np.trace(r["cov"]))
        with self.assertRaisesRegex(mcms.InputError, r"'covariances\[1\]'.*\(2, 2\)"):
            mcms.triangulate(self.rig, q, covariances=[None, np.eye(3), None, None])

    def test_matches_cv2_triangulate_points(self):
        if cv2 is None:
            self.skipTest("skipped: python3-opencv not installed")
        rng = np.random.default_rng(3)
        noisy = []
        P = []
        for cam in self.rig.cameras[:2]:
            q = cam.project(transform(cam.T_cam_rig, self.p)) + rng.normal(0, 0.3, 2)
            noisy.append(q)
            fx, fy, cx, cy = cam.intrinsics
            K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
            P.append(K @ cam.T_cam_rig[:3, :])
        X = cv2.triangulatePoints(P[0], P[1], noisy[0].reshape(2, 1), noisy[1].reshape(2, 1))
        X = (X[:3] / X[3]).ravel()
        r = mcms.triangulate(self.rig, noisy + [None, None])
        # Both are the optimal two-view point to well below the noise's effect (about 0.2 mm).
        self.assertLess(np.linalg.norm(r["p_rig"] - X), 2e-5)
        self.assertGreater(np.linalg.norm(r["p_rig"] - self.p), 1e-5)

    def test_match_and_triangulate(self):
        pts = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.05], [-0.05, 0.12, 0.02]])
        q = ball_pixels(self.rig, pts)
        q = [x[::-1] if i % 2 else x for i, x in enumerate(q)]  # unlabeled: any order per camera
        found = mcms.match_and_triangulate(self.rig, q)
        self.assertEqual(len(found), 3)
        got = np.array(sorted((tuple(f["p_rig"]) for f in found)))
        np.testing.assert_allclose(got, np.array(sorted(map(tuple, pts))), atol=1e-8)

    def test_bad_input_names_the_argument(self):
        with self.assertRaisesRegex(mcms.InputError, r"'points\[1\]'.*\(2,\)"):
            mcms.triangulate(self.rig, [[1.0, 2.0], [1.0, 2.0, 3.0], None, None])
        with self.assertRaisesRegex(mcms.InputError, r"'points'.*one entry per camera \(4\)"):
            mcms.triangulate(self.rig, [[1.0, 2.0]])
        with self.assertRaisesRegex(mcms.InputError, r"'points\[0\]'.*nan"):
            mcms.match_and_triangulate(self.rig, [np.array([[np.nan, 1.0]]), None, None, None])


class Tracker(unittest.TestCase):
    def setUp(self):
        self.rig = pinhole_rig(4)
        self.target = mcms.Target.default()

    def test_points_in_pose_and_covariance_out(self):
        tracker = mcms.Tracker(self.rig, self.target)
        rng = np.random.default_rng(5)
        for k in range(5):
            T = target_pose(0.3 + 0.02 * k, (0.02 + 0.005 * k, -0.01, 0.05))
            q = ball_pixels(self.rig, transform(T, self.target.balls))
            q = [x + rng.normal(0, 0.05, x.shape) for x in q]
            r = tracker.process_points(q, frame=k, time_s=0.1 * k, sigma_px=0.05)
            self.assertEqual(r.status, "ok", r.reason)
            self.assertEqual(r.cov.shape, (6, 6))
            self.assertTrue(np.all(np.linalg.eigvalsh(r.cov) > 0))
            d = mcms.box_minus(r.T_rig_target, T)
            # The tracker models the sphere's image centroid, the points here are centre
            # projections: a sub-0.1 mm bias on top of the noise.
            self.assertLess(np.linalg.norm(d[3:]), 2e-4)
            self.assertLess(np.linalg.norm(d[:3]), 2e-3)

    def draw(self, T):
        """Grey images of the target's balls at pose T: bright anti-aliased discs, blurred."""
        balls = transform(T, self.target.balls)
        images = []
        for cam in self.rig.cameras:
            img = np.full((cam.height, cam.width), 20, np.uint8)
            p_cam = transform(cam.T_cam_rig, balls)
            for p, q in zip(p_cam, cam.project(p_cam)):
                r_px = cam.intrinsics[0] * self.target.ball_radius_m / p[2]
                cv2.circle(img, (int(round(q[0] * 16)), int(round(q[1] * 16))), int(round(r_px * 16)), 220, -1,
                           cv2.LINE_AA, shift=4)
            images.append(cv2.GaussianBlur(img, (5, 5), 1.0))
        return images

    def test_images_in(self):
        if cv2 is None:
            self.skipTest("skipped: python3-opencv not installed")
        tracker = mcms.Tracker(self.rig, self.target, read_noise_dn=2.0)
        T = target_pose()
        images = self.draw(T)
        images[2] = None  # a missing camera
        r = tracker.process_frame(images, frame=0, time_s=0.0)
        self.assertIn(r.status, ("ok", "degraded"), r.reason)
        self.assertEqual(r.cameras_used, 3)
        self.assertLess(np.linalg.norm(r.T_rig_target[:3, 3] - T[:3, 3]), 1e-3)

    def test_predicted_windows_give_the_same_poses(self):
        if cv2 is None:
            self.skipTest("skipped: python3-opencv not installed")
        whole = mcms.Tracker(self.rig, self.target, read_noise_dn=2.0)
        windows = mcms.Tracker(self.rig, self.target, read_noise_dn=2.0, predicted_windows=True)
        for k in range(6):
            images = self.draw(target_pose(0.3 + 0.01 * k, (0.004 * k, 0.002 * k, 0.05)))
            a = whole.process_frame(images, frame=k, time_s=0.1 * k)
            b = windows.process_frame(images, frame=k, time_s=0.1 * k)
            self.assertEqual(a.status, b.status, (a.reason, b.reason))
            np.testing.assert_allclose(b.T_rig_target, a.T_rig_target, atol=1e-9)
        # Frames 0 and 1 whole (no velocity yet), then windows; the whole-image tracker never.
        self.assertGreaterEqual(windows.window_detections, 12)
        self.assertEqual(whole.window_detections, 0)
        with self.assertRaisesRegex(mcms.InputError, "'predicted_windows': expected True or False"):
            mcms.Tracker(self.rig, self.target, predicted_windows="yes")
        with self.assertRaisesRegex(mcms.InputError, "'full_scan_every': expected a whole number"):
            mcms.Tracker(self.rig, self.target, full_scan_every=0.5)

    def test_sequence_on_disk_to_csv_and_arrays(self):
        if cv2 is None:
            self.skipTest("skipped: python3-opencv not installed")
        truth = [target_pose(0.3 + 0.05 * k, (0.01 * k, 0.0, 0.05)) for k in range(3)]
        with tempfile.TemporaryDirectory() as d:
            for k, T in enumerate(truth):
                for name, img in zip(self.rig.names, self.draw(T)):
                    os.makedirs(os.path.join(d, "images", name), exist_ok=True)
                    cv2.imwrite(os.path.join(d, "images", name, "%04d.png" % (10 + k)), img)
            noise = mcms.estimate_sequence_noise(self.rig, os.path.join(d, "images"))
            self.assertEqual(noise["cameras"], self.rig.names)
            self.assertEqual(len(noise["gain_e_per_dn"]), 4)
            self.assertTrue(noise["description"])
            tracker = mcms.Tracker(self.rig, self.target, read_noise_dn=2.0,
                                   camera_gain_e_per_dn=noise["gain_e_per_dn"])
            results = tracker.track_sequence(os.path.join(d, "images"), frame_rate_hz=5.0, threads=2)
            csv = os.path.join(d, "poses.csv")
            mcms.write_pose_csv(csv, results)
            with open(csv) as f:
                rows = [line for line in f if line[:1].isdigit()]
        self.assertEqual(len(rows), 3)
        a = mcms.results_to_arrays(results)
        np.testing.assert_array_equal(a["frame"], [10, 11, 12])
        np.testing.assert_allclose(a["time_s"], [2.0, 2.2, 2.4])
        # The discs drawn here only approximate the spheres' images (ellipses): some observations
        # fail the tracker's outlier test and the frames may be degraded, never lost.
        self.assertTrue(all(s in ("ok", "degraded") for s in a["status"]), a["reason"])
        for T_est, T in zip(a["T_rig_target"], truth):
            self.assertLess(np.linalg.norm(T_est[:3, 3] - T[:3, 3]), 1e-3)
        with self.assertRaisesRegex(mcms.InputError, "/no/such/images"):
            tracker.track_sequence("/no/such/images")

    def test_bad_images_name_the_argument(self):
        tracker = mcms.Tracker(self.rig, self.target)
        good = np.zeros((1024, 1280), np.uint8)
        with self.assertRaisesRegex(mcms.InputError, r"'images\[1\]'.*dtype uint8 or uint16, got float64"):
            tracker.process_frame([good, np.zeros((1024, 1280)), None, None])
        with self.assertRaisesRegex(mcms.InputError, r"'images\[0\]'.*shape \(1024, 1280\)"):
            tracker.process_frame([np.zeros((10, 10), np.uint8), None, None, None])
        with self.assertRaisesRegex(mcms.InputError, r"unknown tracker option 'nope'"):
            mcms.Tracker(self.rig, self.target, nope=1)

    def test_bad_frame_number_and_time_are_named(self):
        # Issue 29: time_s NaN, infinite or going backwards was tracked; frame=-5 gave pybind's
        # "incompatible function arguments" with the arrays printed.
        tracker = mcms.Tracker(self.rig, self.target)
        none = [None] * len(self.rig.cameras)
        with self.assertRaisesRegex(mcms.InputError, r"argument 'frame': expected a frame number >= 0, got -5"):
            tracker.process_frame(none, frame=-5, time_s=0.0)
        for bad in (float("nan"), float("inf")):
            with self.assertRaisesRegex(mcms.InputError, r"frame 3: time_s .* is not a finite number"):
                tracker.process_frame(none, frame=3, time_s=bad)
        tracker.process_frame(none, frame=4, time_s=2.0)
        tracker.process_frame(none, frame=5, time_s=2.0)  # the same time twice is fine
        with self.assertRaisesRegex(mcms.InputError, r"frame 6: time_s 1.5 is before the previous frame's 2 s"):
            tracker.process_frame(none, frame=6, time_s=1.5)
        with self.assertRaisesRegex(mcms.InputError, r"frame 7: time_s 1 is before"):
            tracker.process_points(none, frame=7, time_s=1.0)

    def test_audit_names_a_moved_camera(self):
        # Camera 1's observations come from a camera turned by 3 mrad; the rig does not know.
        moved = [mcms.CameraModel(c.lensmodel, c.intrinsics, c.width, c.height, c.T_cam_rig) for c in self.rig.cameras]
        moved[1].T_cam_rig = mcms.box_plus(moved[1].T_cam_rig, [0.003, 0, 0, 0, 0, 0])
        truth = mcms.CameraRig(moved)
        tracker = mcms.Tracker(self.rig, self.target)
        rng = np.random.default_rng(7)
        results = []
        for k in range(30):
            T = target_pose(0.2 + 0.05 * k, (0.1 * np.sin(k), 0.1 * np.cos(k), 0.05 * (k % 3)))
            q = [x + rng.normal(0, 0.05, x.shape) for x in ball_pixels(truth, transform(T, self.target.balls))]
            results.append(tracker.process_points(q, frame=k, time_s=0.1 * k, sigma_px=0.05))
        audit = mcms.audit_cameras(self.rig, self.target, results)
        named = [(e["name"], e["where"]) for e in audit["effects"]]
        self.assertIn(("camera_moved", self.rig.names[1]), named, audit["report"])
        self.assertFalse(audit["clean"], audit["report"])
        fixed = audit["repaired_rig"][1].T_cam_rig
        self.assertLess(np.linalg.norm(mcms.box_minus(fixed, moved[1].T_cam_rig)[:3]),
                        np.linalg.norm(mcms.box_minus(self.rig[1].T_cam_rig, moved[1].T_cam_rig)[:3]) / 3)


class FieldOfView(unittest.TestCase):
    def test_prediction_grows_with_distance_and_noise(self):
        rig = pinhole_rig(4)
        target = mcms.Target.default()
        near = mcms.predict_fov_point(rig, target, target_pose(), centre_sigma_px=0.05)
        self.assertTrue(near["trackable"])
        self.assertTrue(np.all(np.linalg.eigvalsh(near["cov"]) > 0))
        noisy = mcms.predict_fov_point(rig, target, target_pose(), centre_sigma_px=0.1)
        # The Cramer-Rao covariance scales with the centre variance.
        np.testing.assert_allclose(noisy["cov"], 4 * near["cov"], rtol=1e-6)
        away = mcms.predict_fov_point(rig, target, target_pose(t=(5.0, 5.0, 0.0)), centre_sigma_px=0.05)
        self.assertFalse(away["trackable"])
        self.assertTrue(np.all(np.isnan(away["cov"])))

    def test_grid_map_as_the_cli(self):
        rig = pinhole_rig(4)
        target = mcms.Target.default()
        with tempfile.TemporaryDirectory() as d:
            m = mcms.fov_map(rig, target, "-0.2:0.2:3,0:0.1:2,0:0:1", output_dir=os.path.join(d, "map"))
            self.assertTrue(os.path.exists(os.path.join(d, "map", "map.csv")))
        self.assertEqual(m["shape"], (1, 2, 3))
        np.testing.assert_allclose(m["positions"][:4], [[-0.2, 0, 0], [0, 0, 0], [0.2, 0, 0], [-0.2, 0.1, 0]])
        self.assertTrue(np.all(m["trackable"]))
        self.assertIn("sigma_d", m["summary"])
        # The same predictions as at arbitrary positions (each with a centre-noise table for its own range).
        r = mcms.predict_fov_points(rig, target, m["positions"])
        np.testing.assert_allclose(r["sigma_d"], m["sigma_d"], rtol=0.05)
        with self.assertRaisesRegex(mcms.InputError, "'grid'"):
            mcms.fov_map(rig, target, "0:1")
        # Issue 37: a thread count past the limit is an error naming it, not a dead interpreter.
        with self.assertRaisesRegex(mcms.InputError, "'threads': expected 1 to 256 threads, got 100000"):
            mcms.fov_map(rig, target, "-0.2:0.2:3,0:0.1:2,0:0:1", threads=100000)

    def test_predict_points_with_the_detector_noise(self):
        rig = pinhole_rig(4)
        r = mcms.predict_fov_points(rig, mcms.Target.default(), [[0, 0, 0], [0.2, 0, 0], [9, 9, 9]])
        self.assertEqual(r["sigma_d"].shape, (3,))
        self.assertTrue(r["trackable"][0] and r["trackable"][1] and not r["trackable"][2])
        self.assertTrue(0 < r["sigma_d"][0] < 1e-3)
        self.assertTrue(np.isnan(r["sigma_d"][2]))


if __name__ == "__main__":
    unittest.main()
