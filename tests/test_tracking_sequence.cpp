// The recording's frames.csv with each camera's exposure time (cameras not triggered
// together): read per frame in the listing's order, carried into every FrameResult by the
// streaming tracker, and a column naming no rig camera refused with the file and column.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "tracking/sequence.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

CameraRig SmallRig() {
  CameraRig rig;
  for (const char* name : {"left", "right"}) {
    rig.names.push_back(name);
    rig.cameras.emplace_back("LENSMODEL_PINHOLE", std::vector<double>{100, 100, 31.5, 23.5}, 64, 48);
  }
  return rig;
}

// Frames 1-3 of two cameras, blank images, and frames.csv.
std::filesystem::path Recording(const std::string& name, const std::string& frames_csv) {
  const auto dir = test::ScratchDir(name);
  for (const char* cam : {"left", "right"}) {
    std::filesystem::create_directories(dir / "images" / cam);
    for (int f = 1; f <= 3; ++f)
      cv::imwrite((dir / "images" / cam / (std::to_string(f) + ".pgm")).string(), cv::Mat(48, 64, CV_8UC1, cv::Scalar(0)));
  }
  std::ofstream(dir / "frames.csv") << frames_csv;
  return dir;
}

TEST(SequenceCameraTimes, ReadPerFrameAndCarriedIntoEveryResult) {
  const CameraRig rig = SmallRig();
  // Frame 2 twice (the last row counts, its cameras' times too), the columns in another
  // order than the rig's cameras, one cell empty.
  const auto dir = Recording("seq_camera_times",
                             "frame,time_s,time_s_right,time_s_left\n"
                             "1,0.1,0.12,0.09\n"
                             "2,0.2,0.2,0.205\n"
                             "2,0.25,0.26,0.24\n"
                             "3,0.3,0.31,\n");
  const ImageSequence seq = ScanImageSequence({dir / "images", dir / "frames.csv", 10.0}, rig);
  ASSERT_EQ(seq.frames, (std::vector<size_t>{1, 2, 3}));
  ASSERT_EQ(seq.camera_times_s.size(), 6u);
  EXPECT_DOUBLE_EQ(seq.times_s[1], 0.25);
  EXPECT_DOUBLE_EQ(seq.camera_times_s[0], 0.09);   // frame 1, left
  EXPECT_DOUBLE_EQ(seq.camera_times_s[1], 0.12);   // frame 1, right
  EXPECT_DOUBLE_EQ(seq.camera_times_s[2], 0.24);   // frame 2, left
  EXPECT_DOUBLE_EQ(seq.camera_times_s[3], 0.26);   // frame 2, right
  EXPECT_TRUE(std::isnan(seq.camera_times_s[4]));  // frame 3, left: empty cell
  EXPECT_DOUBLE_EQ(seq.camera_times_s[5], 0.31);

  Tracker tracker(rig, Target::Default(), TrackerOptions{});
  std::vector<FrameResult> results;
  TrackImageSequenceStreaming(seq, tracker, [&](FrameResult&& r) { results.push_back(std::move(r)); }, {}, 2);
  ASSERT_EQ(results.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    ASSERT_EQ(results[i].camera_time_s.size(), 2u) << i;
    EXPECT_EQ(results[i].frame, seq.frames[i]);
    for (size_t c = 0; c < 2; ++c) {
      const double want = seq.camera_times_s[2 * i + c];
      if (std::isnan(want))
        EXPECT_TRUE(std::isnan(results[i].camera_time_s[c]));
      else
        EXPECT_DOUBLE_EQ(results[i].camera_time_s[c], want);
    }
  }

  // Without the columns, nothing.
  std::ofstream(dir / "frames.csv") << "frame,time_s\n1,0.1\n2,0.2\n3,0.3\n";
  EXPECT_TRUE(ScanImageSequence({dir / "images", dir / "frames.csv", 10.0}, rig).camera_times_s.empty());
}

TEST(SequenceCameraTimes, AColumnOfNoRigCameraIsRefused) {
  const CameraRig rig = SmallRig();
  const auto dir = Recording("seq_camera_times_bad", "frame,time_s,time_s_middle\n1,0.1,0.1\n2,0.2,0.2\n3,0.3,0.3\n");
  const std::string m = test::ErrorOf([&] { ScanImageSequence({dir / "images", dir / "frames.csv", 10.0}, rig); });
  EXPECT_NE(m.find("frames.csv"), std::string::npos) << m;
  EXPECT_NE(m.find("time_s_middle"), std::string::npos) << m;
  EXPECT_NE(m.find("left, right"), std::string::npos) << m;
  std::ofstream(dir / "frames.csv") << "frame,time_s,time_s_left\n1,0.1,0.1\n2,0.2,soon\n3,0.3,0.3\n";
  EXPECT_THROW(ScanImageSequence({dir / "images", dir / "frames.csv", 10.0}, rig), InputError);
}

}  // namespace
}  // namespace mcms
