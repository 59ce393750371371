"""Camera models through Python, compared with Debian's mrcal and cv2 on the same files."""
import os
import tempfile
import unittest

import numpy as np

import mcms
from mcms_test_util import real_data

try:
    import mrcal
except ImportError:  # pragma: no cover
    mrcal = None
try:
    import cv2
except ImportError:  # pragma: no cover
    cv2 = None


def points_in_view(cam, n, depth=(2.0, 20.0), seed=1):
    """Camera-frame points whose pixels lie inside the image (and the model's valid region)."""
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(0.15, 0.85, n) * cam.width, rng.uniform(0.15, 0.85, n) * cam.height])
    v = cam.unproject(q)
    return v * rng.uniform(*depth, n)[:, None]


class CameraAgainstMrcal(unittest.TestCase):
    def setUp(self):
        folder = real_data("mrcal-figueroa")
        if folder is None:
            self.skipTest("skipped: real data not present: mrcal-figueroa")
        if mrcal is None:
            self.skipTest("skipped: python3-mrcal not installed")
        self.folder = folder

    def check_model(self, name, tol_px):
        path = str(self.folder / name)
        cam = mcms.CameraModel.read(path)
        ref = mrcal.cameramodel(path)
        lensmodel, intrinsics = ref.intrinsics()
        self.assertEqual(cam.lensmodel, lensmodel)
        np.testing.assert_allclose(cam.intrinsics, intrinsics, rtol=0, atol=0)
        self.assertEqual(cam.imagersize, tuple(ref.imagersize()))
        np.testing.assert_allclose(mcms.rt_from_pose(cam.T_cam_rig), ref.extrinsics_rt_fromref(), atol=1e-12)

        p = points_in_view(cam, 200)
        q, dq_dp, dq_di = cam.project(p, get_gradients=True)
        q_ref, dq_dp_ref, dq_di_ref = mrcal.project(p, lensmodel, intrinsics, get_gradients=True)
        np.testing.assert_allclose(q, q_ref, atol=tol_px, rtol=0)
        np.testing.assert_allclose(dq_dp, dq_dp_ref, atol=1e-6 * np.abs(dq_dp_ref).max(), rtol=0)
        np.testing.assert_allclose(dq_di, dq_di_ref, atol=1e-6 * np.abs(dq_di_ref).max(), rtol=0)

        v = cam.unproject(q_ref)
        v_ref = mrcal.unproject(q_ref, lensmodel, intrinsics, normalize=True)
        np.testing.assert_allclose(v, v_ref, atol=1e-8)
        np.testing.assert_allclose(v, p / np.linalg.norm(p, axis=1)[:, None], atol=1e-8)
        return cam

    def test_opencv8_matches_mrcal(self):
        self.check_model("opencv8-0.cameramodel", 1e-9)

    def test_splined_matches_mrcal(self):
        self.check_model("splined-0.cameramodel", 1e-9)

    def test_write_is_read_by_mrcal(self):
        cam = mcms.CameraModel.read(str(self.folder / "opencv8-1.cameramodel"))
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "copy.cameramodel")
            cam.write(out)
            ref = mrcal.cameramodel(out)
            np.testing.assert_allclose(ref.intrinsics()[1], cam.intrinsics, rtol=1e-15)
            np.testing.assert_allclose(ref.extrinsics_rt_fromref(), mcms.rt_from_pose(cam.T_cam_rig), atol=1e-15)
            again = mcms.CameraModel.read(out)
            np.testing.assert_array_equal(again.intrinsics, cam.intrinsics)


class CameraAgainstOpenCv(unittest.TestCase):
    def test_opencv_yaml_matches_cv2_project_points(self):
        folder = real_data("opencv-stereo-chessboard")
        if folder is None:
            self.skipTest("skipped: real data not present: opencv-stereo-chessboard")
        if cv2 is None:
            self.skipTest("skipped: python3-opencv not installed")
        cam = mcms.CameraModel.read(str(folder / "left_intrinsics.yml"))
        fs = cv2.FileStorage(str(folder / "left_intrinsics.yml"), cv2.FILE_STORAGE_READ)
        K = fs.getNode("camera_matrix").mat()
        dist = fs.getNode("distortion_coefficients").mat()
        self.assertEqual(cam.lensmodel, "LENSMODEL_OPENCV5")
        p = points_in_view(cam, 100, depth=(0.3, 2.0))
        q_cv, _ = cv2.projectPoints(p.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
        np.testing.assert_allclose(cam.project(p), q_cv.reshape(-1, 2), atol=1e-8)


class Gradients(unittest.TestCase):
    def setUp(self):
        self.cam = mcms.CameraModel("LENSMODEL_OPENCV8",
                                    [1400, 1410, 640, 500, -0.2, 0.05, 1e-3, -2e-3, 0.01, 0.01, 0.001, 0.0002],
                                    1280, 1024)

    def test_unproject_gradients_against_finite_differences(self):
        q = np.array([[100.0, 200.0], [640.0, 500.0], [1100.0, 900.0]])
        v, dv_dq, dv_di = self.cam.unproject(q, get_gradients=True)
        h = 1e-4
        for k in range(2):
            dq = np.zeros(2)
            dq[k] = h
            num = (self.cam.unproject(q + dq) - self.cam.unproject(q - dq)) / (2 * h)
            np.testing.assert_allclose(dv_dq[:, :, k], num, atol=1e-8)
        intr = self.cam.intrinsics.copy()
        for k in range(len(intr)):
            step = 1e-6 * max(1.0, abs(intr[k]))
            plus, minus = self.cam.intrinsics.copy(), self.cam.intrinsics.copy()
            plus[k] += step
            minus[k] -= step
            self.cam.intrinsics = plus
            vp = self.cam.unproject(q)
            self.cam.intrinsics = minus
            vm = self.cam.unproject(q)
            self.cam.intrinsics = intr
            np.testing.assert_allclose(dv_di[:, :, k], (vp - vm) / (2 * step), atol=1e-6)

    def test_single_point_shapes(self):
        q, dq_dp, dq_di = self.cam.project([0.1, -0.2, 2.0], get_gradients=True)
        self.assertEqual(q.shape, (2,))
        self.assertEqual(dq_dp.shape, (2, 3))
        self.assertEqual(dq_di.shape, (2, 12))
        self.assertEqual(self.cam.project(np.zeros((0, 3)) + 1).shape, (0, 2))


class BadInput(unittest.TestCase):
    def setUp(self):
        self.cam = mcms.CameraModel("LENSMODEL_PINHOLE", [1000, 1000, 639.5, 511.5], 1280, 1024)

    def assert_names(self, fn, *words):
        with self.assertRaises(mcms.InputError) as ctx:
            fn()
        for w in words:
            self.assertIn(w, str(ctx.exception))
        self.assertIsInstance(ctx.exception, ValueError)

    def test_wrong_dtype(self):
        self.assert_names(lambda: self.cam.project(np.array([["a", "b", "c"]])), "'p_cam'", "dtype")
        self.assert_names(lambda: self.cam.project(np.array([1 + 1j, 2, 3])), "'p_cam'", "complex")
        self.assert_names(lambda: self.cam.project(np.array([True, False, True])), "'p_cam'", "bool")
        self.assert_names(lambda: self.cam.project(None), "'p_cam'", "None")

    def test_wrong_shape(self):
        self.assert_names(lambda: self.cam.project(np.zeros((4, 2))), "'p_cam'", "(N, 3)", "(4, 2)")
        self.assert_names(lambda: self.cam.unproject(np.zeros((2, 3))), "'q'", "(N, 2)")
        self.assert_names(lambda: setattr(self.cam, "intrinsics", [1.0, 2.0]), "'intrinsics'", "(4,)")
        self.assert_names(lambda: setattr(self.cam, "T_cam_rig", np.eye(3)), "'T_cam_rig'", "(4, 4)")

    def test_nan(self):
        p = np.ones((5, 3))
        p[3, 1] = np.nan
        self.assert_names(lambda: self.cam.project(p), "'p_cam'", "[3, 1]", "nan")
        self.assert_names(lambda: self.cam.unproject([np.inf, 1.0]), "'q'", "inf")

    def test_not_a_rotation(self):
        T = np.eye(4)
        T[0, 0] = 2
        self.assert_names(lambda: setattr(self.cam, "T_cam_rig", T), "'T_cam_rig'", "rotation")

    def test_file_errors_carry_the_cpp_message(self):
        self.assert_names(lambda: mcms.CameraModel.read("/nonexistent/cam.cameramodel"), "/nonexistent/cam.cameramodel")
        self.assert_names(lambda: mcms.CameraModel("LENSMODEL_NOPE", [1, 2, 3], 10, 10), "LENSMODEL_NOPE")
        with tempfile.TemporaryDirectory() as d:
            bad = os.path.join(d, "bad.cameramodel")
            with open(bad, "w") as f:
                f.write("{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [1, 2] }\n")
            self.assert_names(lambda: mcms.CameraModel.read(bad), bad)


class Rig(unittest.TestCase):
    def test_round_trip(self):
        from mcms_test_util import pinhole_rig
        rig = pinhole_rig(3)
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "rig.yaml")
            rig.write(path)
            back = mcms.CameraRig.read(path)
        self.assertEqual(len(back), 3)
        self.assertEqual(back.names, rig.names)
        for a, b in zip(rig.cameras, back.cameras):
            np.testing.assert_allclose(a.T_cam_rig, b.T_cam_rig, atol=1e-12)
            np.testing.assert_allclose(a.intrinsics, b.intrinsics)
        self.assertEqual(back["cam1"].width, 1280)
        self.assertEqual(back[-1].height, 1024)

    def test_pickle(self):
        # Models cross process boundaries (multiprocessing, Dask) by pickle.
        import pickle
        from mcms_test_util import pinhole_rig
        rig = pickle.loads(pickle.dumps(pinhole_rig(2)))
        self.assertEqual(rig.names, ["cam0", "cam1"])
        np.testing.assert_array_equal(rig[1].T_cam_rig, pinhole_rig(2)[1].T_cam_rig)
        robot = pickle.loads(pickle.dumps(mcms.RobotModel.default()))
        np.testing.assert_array_equal(robot.T_base_flange(np.zeros(6)),
                                      mcms.RobotModel.default().T_base_flange(np.zeros(6)))
        target = pickle.loads(pickle.dumps(mcms.Target.default()))
        np.testing.assert_array_equal(target.balls, mcms.Target.default().balls)


if __name__ == "__main__":
    unittest.main()


class CameramodelWithBom(unittest.TestCase):
    """Issue 29: a UTF-8 byte order mark before a .cameramodel is skipped by the reader."""

    def test_bom_is_skipped(self):
        text = ("{'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [534, 531, 322, 245, -0.28, 0.09, 0.001, -0.0005], "
                "'extrinsics': [0, 0, 0, 0, 0, 0], 'imagersize': [640, 480]}\n")
        with tempfile.TemporaryDirectory() as d:
            plain, bom = os.path.join(d, "plain.cameramodel"), os.path.join(d, "bom.cameramodel")
            with open(plain, "w") as f:
                f.write(text)
            with open(bom, "wb") as f:
                f.write(b"\xef\xbb\xbf" + text.encode())
            a, b = mcms.CameraModel.read(plain), mcms.CameraModel.read(bom)
            self.assertEqual(b.lensmodel, a.lensmodel)
            np.testing.assert_array_equal(b.intrinsics, a.intrinsics)
