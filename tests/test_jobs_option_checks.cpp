// Issue 54: every option struct says what is wrong with it (IsValid), and the function that
// takes it refuses it with that reason instead of running on it.
#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "jobs/fov_map.h"
#include "jobs/lab_experiment.h"
#include "model/robot_validation.h"
#include "vision/image_file.h"

namespace mcms {
namespace {

TEST(OptionChecks, ImageFileOptionsRefuseANonPositiveSize) {
  ImageFileOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why)) << why;
  o.expected_size = std::array<int, 2>{1280, 0};
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("1280 x 0"), std::string::npos) << why;
  std::string problem;
  EXPECT_THROW(ReadImageFile("any.png", o, &problem), InputError);
}

TEST(OptionChecks, PlacementOptionsRefuseABadNoiseOrRate) {
  PlacementOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why)) << why;
  o.false_alarm = 0.7;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("false_alarm"), std::string::npos) << why;
  o = PlacementOptions{};
  o.noise(1, 1) = -1e-8;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("positive definite"), std::string::npos) << why;
}

TEST(OptionChecks, LabExperimentOptionsRefuseANegativeProcessNoise) {
  LabExperimentOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why)) << why;
  o.kf_linear_psd = -1e-16;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("process noise"), std::string::npos) << why;
}

TEST(OptionChecks, FovSimulationOptionsRefuseTooFewRepeats) {
  FovSimulationOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why)) << why;
  o.repeats = 1;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("--repeats"), std::string::npos) << why;
  o = FovSimulationOptions{};
  o.threads = -1;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("threads"), std::string::npos) << why;
}

}  // namespace
}  // namespace mcms
