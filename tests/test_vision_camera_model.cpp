// Camera models through libmrcal: projection Jacobians against central differences,
// project/unproject round trips, and file round trips for .cameramodel and OpenCV YAML.
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include "core/error.h"
#include "tests/test_util.h"
#include "vision/camera_model.h"

namespace mcms {
namespace {

std::vector<CameraModel> Models() {
  std::vector<CameraModel> m;
  m.emplace_back("LENSMODEL_PINHOLE", std::vector<double>{1100, 1102, 640.3, 511.7}, 1280, 1024);
  m.emplace_back("LENSMODEL_OPENCV4", std::vector<double>{1100, 1102, 640.3, 511.7, -0.2, 0.05, 1e-4, -2e-4}, 1280,
                 1024);
  m.emplace_back("LENSMODEL_OPENCV5",
                 std::vector<double>{1100, 1102, 640.3, 511.7, -0.2, 0.05, 1e-4, -2e-4, 0.01}, 1280, 1024);
  m.emplace_back("LENSMODEL_OPENCV8",
                 std::vector<double>{1100, 1102, 640.3, 511.7, -0.2, 0.05, 1e-4, -2e-4, 0.01, 0.02, -0.01, 0.003},
                 1280, 1024);
  // A splined stereographic model: core plus 2*Nx*Ny control values, here a smooth field.
  const int Nx = 10, Ny = 8;
  std::vector<double> spl = {1000, 1001, 640, 512};
  for (int j = 0; j < Ny; ++j)
    for (int i = 0; i < Nx; ++i) {
      spl.push_back(0.01 * std::sin(0.3 * i + 0.2 * j));
      spl.push_back(-0.008 * std::cos(0.25 * i - 0.1 * j));
    }
  m.emplace_back("LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=10_Ny=8_fov_x_deg=80", spl, 1280, 1024);
  return m;
}

TEST(CameraModel, ProjectionJacobiansMatchCentralDifferences) {
  for (const CameraModel& cam : Models()) {
    SCOPED_TRACE(cam.LensModelName());
    for (const Vec3& p : {Vec3(0.1, -0.2, 1.5), Vec3(-0.4, 0.3, 1.2), Vec3(0.0, 0.0, 2.0)}) {
      Eigen::Matrix<double, 2, 3> J;
      std::vector<double> dq_di;
      cam.Project(p, &J, &dq_di);
      const Eigen::MatrixXd Jn = test::NumericJacobian(
          [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return cam.Project(Vec3(x)); }, p, 1e-6);
      EXPECT_LT((J - Jn).cwiseAbs().maxCoeff(), 1e-4 * (1.0 + Jn.cwiseAbs().maxCoeff()));
      const Eigen::VectorXd intr0 = Eigen::Map<const Eigen::VectorXd>(cam.Intrinsics().data(), cam.NumIntrinsics());
      const Eigen::MatrixXd Jin = test::NumericJacobian(
          [&](const Eigen::VectorXd& x) -> Eigen::VectorXd {
            CameraModel c = cam;
            c.MutableIntrinsics().assign(x.data(), x.data() + x.size());
            return c.Project(p);
          },
          intr0, 1e-7);
      const Eigen::MatrixXd Ji = Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          dq_di.data(), 2, cam.NumIntrinsics());
      EXPECT_LT((Ji - Jin).cwiseAbs().maxCoeff(), 1e-4 * (1.0 + Jin.cwiseAbs().maxCoeff()));
    }
  }
}

TEST(CameraModel, UnprojectRoundTrip) {
  for (const CameraModel& cam : Models()) {
    SCOPED_TRACE(cam.LensModelName());
    for (double u = 20; u < 1280; u += 310)
      for (double v = 20; v < 1024; v += 250) {
        const auto d = cam.Unproject(Vec2(u, v));
        ASSERT_TRUE(d.has_value());
        EXPECT_NEAR(d->norm(), 1.0, 1e-12);
        const Vec2 q = cam.Project(*d * 1.7);
        EXPECT_LT((q - Vec2(u, v)).norm(), 1e-6);
      }
  }
}

TEST(CameraModel, CameramodelFileRoundTrip) {
  const auto dir = test::ScratchDir("camera_model_io");
  double rt[6] = {0.1, -0.2, 0.3, 0.5, -0.25, 1.5};
  for (CameraModel cam : Models()) {
    SCOPED_TRACE(cam.LensModelName());
    cam.SetT_cam_rig(Pose::FromRt(rt));
    cam.WriteCameramodel(dir / "m.cameramodel");
    const CameraModel back = CameraModel::Read(dir / "m.cameramodel");
    EXPECT_EQ(back.LensModelName(), cam.LensModelName());
    EXPECT_EQ(back.Width(), 1280);
    ASSERT_EQ(back.NumIntrinsics(), cam.NumIntrinsics());
    for (int i = 0; i < cam.NumIntrinsics(); ++i) EXPECT_NEAR(back.Intrinsics()[i], cam.Intrinsics()[i], 1e-9);
    EXPECT_LT((back.T_cam_rig().t - cam.T_cam_rig().t).norm(), 1e-12);
    EXPECT_LT(RotationAngle(back.T_cam_rig().R, cam.T_cam_rig().R), 1e-12);
  }
}

TEST(CameraModel, OpenCvYamlRoundTrip) {
  const auto dir = test::ScratchDir("camera_model_cv");
  for (const CameraModel& cam : Models()) {
    if (cam.LensModelName().find("SPLINED") != std::string::npos) {
      EXPECT_THROW(cam.WriteOpenCvYaml(dir / "c.yaml"), InputError);
      continue;
    }
    cam.WriteOpenCvYaml(dir / "c.yaml");
    const CameraModel back = CameraModel::Read(dir / "c.yaml");
    EXPECT_EQ(back.LensModelName(), cam.LensModelName());
    for (int i = 0; i < cam.NumIntrinsics(); ++i) EXPECT_DOUBLE_EQ(back.Intrinsics()[i], cam.Intrinsics()[i]);
  }
}

TEST(CameraModel, ReadsRealMrcalModelAndOpenCvCalibration) {
  MCMS_REQUIRE_DATA(figueroa, "mrcal-figueroa");
  const CameraModel m = CameraModel::Read(figueroa / "opencv8-0.cameramodel");
  EXPECT_EQ(m.LensModelName(), "LENSMODEL_OPENCV8");
  EXPECT_EQ(m.Width(), 6016);
  EXPECT_NEAR(m.Intrinsics()[0], 2073.87, 0.01);
  const CameraModel s = CameraModel::Read(figueroa / "splined-0.cameramodel");
  EXPECT_NE(s.LensModelName().find("SPLINED"), std::string::npos);
  MCMS_REQUIRE_DATA(chess, "opencv-stereo-chessboard");
  const CameraModel l = CameraModel::Read(chess / "left_intrinsics.yml");
  EXPECT_NEAR(l.Intrinsics()[0], 535.916, 0.01);
  EXPECT_EQ(l.Width(), 640);
}

// OpenCV YAML is read with yaml-cpp, not cv::FileStorage (which asserted, allocated what a
// file claimed and, on the first input below, looped forever: found by fuzz/fuzz_camera).
TEST(CameraModel, OpenCvYamlBadInputNamesFieldAndLine) {
  const auto dir = test::ScratchDir("camera_model_cv_bad");
  const std::string head = "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n";
  const std::string k = "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"%YAML:1.0 24'extrinsics'rix\n%  rows:1\n   dt:e+0  \nix:-matrix\n%  rows:1\n   dt:e+0  \n",
       "cannot parse OpenCV YAML"},
      {head + k + "   data: [ 500., 0., 320., 0., 500., 240., 0., 0. ]\n",
       "field camera_matrix (line 5) declares 3x3 but data has 8 numbers"},
      {head + k + "   data: [ 500., 0., 320., 0., .nan, 240., 0., 0., 1. ]\n",
       "field camera_matrix (line 5) holds .nan in data; expected finite numbers"},
      {head + "camera_matrix: !!opencv-matrix\n   rows: 2147483647\n   cols: 3\n   dt: d\n   data: [ 1 ]\n",
       "declares rows '2147483647'; expected rows from 0 to 16"},
      {head + "camera_matrix: !!opencv-matrix\n   rows: 1\n   cols: 3\n   dt: 3d\n   data: [ 1, 2, 3 ]\n",
       "has dt '3d'; expected one channel"},
      {head + k + "   data: [ 500., 0., 320., 0., x, 240., 0., 0., 1. ]\n", "holds 'x' in data; expected numbers"},
      {"%YAML:1.0\n---\nimage_width: wide\n", "field image_width (line 3) is 'wide'"},
      {"%YAML:1.0\n---\n- 1\n- 2\n", "expected a map of fields"},
      {"%YAML:1.0\ncamera_matrix: [1, 2\n", "cannot parse OpenCV YAML"},
  };
  for (const auto& [text, expected] : cases) {
    std::ofstream(dir / "c.yaml", std::ios::trunc) << text;
    try {
      CameraModel::Read(dir / "c.yaml");
      ADD_FAILURE() << "accepted:\n" << text;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find((dir / "c.yaml").string()), std::string::npos) << what;
      EXPECT_NE(what.find(expected), std::string::npos) << what;
    }
  }
}

// Debian's mrcal tools (Python) must read what we write.
TEST(CameraModel, DebianMrcalReadsWhatWeWrite) {
  if (std::system("/usr/bin/python3 -c 'import mrcal' >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "skipped: python3-mrcal not installed";
  const auto dir = test::ScratchDir("camera_model_py");
  CameraModel cam = Models()[3];
  double rt[6] = {0.01, 0.02, -0.03, 0.1, 0.2, 0.3};
  cam.SetT_cam_rig(Pose::FromRt(rt));
  cam.WriteCameramodel(dir / "w.cameramodel");
  const Vec3 p(0.2, -0.1, 1.3);
  const Vec2 q = cam.Project(p);
  const std::string cmd = "/usr/bin/python3 -c \"import mrcal, numpy as np; m=mrcal.cameramodel('" +
                          (dir / "w.cameramodel").string() +
                          "'); print(*mrcal.project(np.array([0.2,-0.1,1.3]), *m.intrinsics()))\" > " +
                          (dir / "out.txt").string();
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  std::ifstream in(dir / "out.txt");
  double u = 0, v = 0;
  in >> u >> v;
  EXPECT_NEAR(u, q.x(), 1e-9);
  EXPECT_NEAR(v, q.y(), 1e-9);
}

TEST(CameraModel, BadInputNamesTheProblem) {
  EXPECT_THROW(CameraModel("LENSMODEL_NOPE", {1, 2, 3, 4}, 10, 10), InputError);
  EXPECT_THROW(CameraModel("LENSMODEL_OPENCV8", {1, 2, 3, 4}, 10, 10), InputError);
  EXPECT_THROW(CameraModel::Read("/nonexistent/x.cameramodel"), InputError);
  const auto dir = test::ScratchDir("camera_model_bad");
  std::ofstream(dir / "bad.cameramodel") << "{ 'lensmodel': 'LENSMODEL_OPENCV8', 'intrinsics': [1,2] }";
  try {
    CameraModel::Read(dir / "bad.cameramodel");
    FAIL() << "expected an error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.cameramodel"), std::string::npos);
  }
}

}  // namespace
}  // namespace mcms
