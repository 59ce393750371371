// mcms demo --camera-model: bad names and files refused before any simulation (nothing
// written), and the JSON of `mcms fov-map --measured --json` read back: it is the preset
// `paper` (the preset is what the project's own fit of the paper's Table 1 gives).
#include <gtest/gtest.h>

#include <cmath>

#include "synthetic/camera_error_model.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

TEST(DemoCameraModelCli, BadModelRefusedNothingWritten) {
  const fs::path s = test::ScratchDir("demo_camera_model_bad");
  test::WriteText(s / "bad.json", "{\"effects\": 3}");
  for (const std::string& spec : {std::string("papr"), std::string("missing.json"), std::string("bad.json")}) {
    const test::CliRun r = test::Mcms(s, "demo --points 2 --no-iso9283 -q --camera-model " + spec + " -o out");
    EXPECT_NE(r.code, 0) << spec;
    EXPECT_NE(r.err.find("--camera-model"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(spec), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(s / "out")) << spec;
  }
}

// `mcms fov-map --measured TABLE1 --lines TABLE2 --json fit.json` -> `mcms demo --camera-model
// fit.json`: the model read is the preset `paper` (to the JSON's 9 digits).
TEST(DemoCameraModelCli, FitJsonRoundTripsAndIsThePaperPreset) {
  MCMS_REQUIRE_DATA(paper, "paper");
  const fs::path s = test::ScratchDir("demo_camera_model_json");
  const test::CliRun fit = test::Mcms(s, "fov-map --quiet --measured " + (paper / "table1_point_repeatability.csv").string() +
                                             " --lines " + (paper / "table2_line_lengths.csv").string() +
                                             " --json fit.json -o fov");
  ASSERT_EQ(fit.code, 0) << fit.err;
  const CameraErrorModel m = ReadCameraErrorModel((s / "fit.json").string());
  const CameraErrorModel preset = PaperCameraErrorModel();
  EXPECT_NEAR(m.pixel_noise_scale, preset.pixel_noise_scale, 1e-6 * preset.pixel_noise_scale);
  EXPECT_NEAR(m.floor_m, preset.floor_m, 1e-9);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(m.anisotropy_m[a], preset.anisotropy_m[a], 1e-9) << a;
  const test::CliRun demo = test::Mcms(s, "demo --points 2 --no-iso9283 --no-html -q --threads 2 --camera-model fit.json -o demo");
  ASSERT_EQ(demo.code, 0) << demo.err;
  EXPECT_NE(demo.out.find("camera model: fit.json: pixel noise x11.08"), std::string::npos) << demo.out;
  EXPECT_NE(test::ReadAll(s / "demo" / "summary.txt").find("Against the paper's lab experiment"), std::string::npos);
  EXPECT_FALSE(fs::exists(s / "demo" / "report.html")) << "--no-html";
  EXPECT_EQ(demo.out.find("report:"), std::string::npos) << demo.out;
}

}  // namespace
}  // namespace mcms
