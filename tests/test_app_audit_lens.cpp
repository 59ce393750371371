// `mcms audit lens` (audit/lens_audit.h) through the command: mrcal's real Figueroa
// calibration (6016x4016, 186 chessboard views, 10x10 corners): the stored OPENCV8
// solution has RMS 0.551 px per coordinate, mrcal's own splined fit of the same
// observations 0.430 px. The audit refits both with libmrcal and must find that the
// splined model earns its 1,188 extra parameters on held-out boards (minutes: six splined
// solves). Bad input: the file named, a non-zero exit, nothing written.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "tests/cli_runner.h"

namespace mcms {
namespace {

TEST(AuditLensCli, FigueroaOpencv8AgainstSplined) {
  MCMS_REQUIRE_DATA(dir, "mrcal-figueroa");
  const auto d = test::ScratchDir("audit_lens_figueroa");
  const test::CliRun run =
      test::Mcms(d, "audit lens '" + (dir / "opencv8-0.cameramodel").string() + "' --candidates splined -o out --json r.json");
  std::printf("%s%s", run.out.c_str(), run.err.c_str());
  ASSERT_EQ(run.code, 0) << run.err;
  const nlohmann::json j = nlohmann::json::parse(test::ReadAll(d / "r.json"));
  EXPECT_EQ(j["mode"], "lens");
  EXPECT_FALSE(j["clean"].get<bool>());
  ASSERT_EQ(j["effects"].size(), 1u);
  const auto& e = j["effects"][0];
  EXPECT_EQ(e["name"], "lens_model");
  EXPECT_EQ(e["where"], "cam0");
  EXPECT_NE(e["parameters"]["lensmodel"].get<std::string>().find("LENSMODEL_SPLINED_STEREOGRAPHIC"), std::string::npos);
  EXPECT_EQ(e["parameters"]["nominal_lensmodel"], "LENSMODEL_OPENCV8");
  EXPECT_NEAR(e["parameters"]["rms_px_before"].get<double>(), 0.551, 0.005);  // mrcal's own (data README)
  EXPECT_NEAR(e["parameters"]["rms_px_after"].get<double>(), 0.430, 0.015);   // mrcal's splined-0.cameramodel
  EXPECT_GT(e["heldout_loglik_gain"].get<double>(), 0.0);
  EXPECT_LT(e["heldout_rms_after"].get<double>(), e["heldout_rms_before"].get<double>());
  EXPECT_GT(e["bic_gain"].get<double>(), 0.0);
  EXPECT_TRUE(std::filesystem::exists(d / "out" / "report.txt"));
  EXPECT_TRUE(std::filesystem::exists(d / "out" / "report.json"));
  EXPECT_TRUE(std::filesystem::exists(d / "out" / "plots" / "cam0.svg"));
  const std::string csv = test::ReadAll(d / "out" / "residuals.csv");
  EXPECT_EQ(csv.rfind("board,point,u_px,v_px,weight,nominal_ex_px,nominal_ey_px,candidate_ex_px,candidate_ey_px\n", 0), 0u);
  // The named model, readable by mrcal's tools: the splined intrinsics.
  const std::string model = test::ReadAll(d / "out" / "cam0.cameramodel");
  EXPECT_NE(model.find("LENSMODEL_SPLINED_STEREOGRAPHIC"), std::string::npos);
}

TEST(AuditLensCli, BadInputNamesTheFileAndWritesNothing) {
  const auto d = test::ScratchDir("audit_lens_bad");
  test::WriteText(d / "plain.cameramodel",
                  "{'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [534, 531, 322, 245, -0.28, 0.09, 0.001, -0.0005], "
                  "'imagersize': [640, 480], 'rt_cam_ref': [0, 0, 0, 0, 0, 0]}\n");
  const test::CliRun run = test::Mcms(d, "audit lens plain.cameramodel -q -o out --json out.json");
  EXPECT_EQ(run.code, 2) << run.err;
  EXPECT_NE(run.err.find("plain.cameramodel"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("optimization_inputs"), std::string::npos) << run.err;
  EXPECT_FALSE(std::filesystem::exists(d / "out"));
  EXPECT_FALSE(std::filesystem::exists(d / "out.json"));
  const test::CliRun missing = test::Mcms(d, "audit lens nothere.cameramodel -q");
  EXPECT_EQ(missing.code, 2);
  EXPECT_NE(missing.err.find("nothere.cameramodel"), std::string::npos) << missing.err;
  const test::CliRun folds = test::Mcms(d, "audit lens plain.cameramodel -q --folds 1");
  EXPECT_EQ(folds.code, 2);
  EXPECT_NE(folds.err.find("--folds"), std::string::npos) << folds.err;
}

}  // namespace
}  // namespace mcms
