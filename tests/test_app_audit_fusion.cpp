// `mcms audit fusion`: the tracker's poses against the robot's joints through the setup.
// Logs of a moving robot (joints at 100 Hz, tracker at 10 Hz with noise); a seed hides a
// clock offset of the joint log of 3..6 ms: the audit must name clock_offset at the robot
// with its size within 3 sigma; the same logs without it are clean.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <sstream>

#include "core/random.h"
#include "fuse_logs.h"
#include "test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

int RunCli(const std::string& args, const fs::path& cwd, std::string* out) {
  const std::string cmd = "cd " + cwd.string() + " && " + std::string(MCMS_CLI) + " " + args + " > out.txt 2> err.txt";
  const int status = std::system(cmd.c_str());
  *out = "";
  for (const char* f : {"out.txt", "err.txt"}) {
    std::ifstream in(cwd / f);
    std::stringstream s;
    s << in.rdbuf();  // sets failbit on s when the file is empty: one stream per file
    *out += s.str();
  }
  return WEXITSTATUS(status);
}

// Writes poses.csv, joints.csv, setup.yaml: 40 s of motion, the joint log's stamps late by
// `offset_s` on the tracker's clock.
void WriteLogs(const fs::path& dir, double offset_s, uint64_t seed) {
  test::Logs l = test::CleanLogs();  // its setup.yaml
  Rng rng(seed);
  const RobotModel robot = RobotModel::Default();
  Eigen::VectorXd q0(6);
  q0 << 0.1, -0.6, 0.9, 0.2, 0.7, 0.1;
  const auto q_at = [&](double t) {
    Eigen::VectorXd q = q0;
    for (int j = 0; j < 6; ++j) q[j] += 0.4 * std::sin((0.15 + 0.05 * j) * t + j);
    return q;
  };
  Pose T_base_rig;
  T_base_rig.R = ExpSO3(Vec3(0.0, 0.0, 0.4));
  T_base_rig.t = Vec3(2.0, -1.0, 0.5);
  Pose T_flange_target;
  T_flange_target.t = Vec3(0.0, 0.0, 0.1);
  test::Lines& j = l.files["joints.csv"];
  j = {"time_s,q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad"};
  for (int k = 0; k <= 4100; ++k) {
    const double t = k / 100.0;
    const Eigen::VectorXd q = q_at(t - offset_s);  // stamped late: the value of an earlier moment
    std::string row = test::N(t);
    for (int i = 0; i < 6; ++i) (row += ",") += test::N(q[i]);
    j.push_back(row);
  }
  test::Lines& p = l.files["poses.csv"];
  std::string header = "frame,time_s,status,reason,x_m,y_m,z_m,qw,qx,qy,qz";
  const char* ax[6] = {"rx", "ry", "rz", "px", "py", "pz"};
  for (auto& a : ax)
    for (auto& b : ax) header += std::string(",cov_") + a + "_" + b;
  p = {header};
  const double sr = 5e-5, sp = 3e-5;
  for (int m = 0; m < 400; ++m) {
    const double t = 0.5 + m / 10.0;
    Pose T = T_base_rig.Inverse() * robot.T_base_flange(q_at(t)) * T_flange_target;
    T.R = ExpSO3(Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * sr) * T.R;
    T.t += Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * sp;
    const auto q = T.Quaternion();
    std::string row = std::to_string(m) + "," + test::N(t) + ",ok,\"\"," + test::N(T.t.x()) + "," + test::N(T.t.y()) +
                      "," + test::N(T.t.z()) + "," + test::N(q.w()) + "," + test::N(q.x()) + "," + test::N(q.y()) +
                      "," + test::N(q.z());
    for (int r = 0; r < 6; ++r)
      for (int c = 0; c < 6; ++c) (row += ",") += test::N(r != c ? 0.0 : r < 3 ? sr * sr : sp * sp);
    p.push_back(row);
  }
  l.files.erase("incl.csv");
  test::Write(dir, l);
}

TEST(AppAuditFusion, FindsAClockOffsetOfTheJointLog) {
  for (uint64_t seed : {1, 2}) {
    Rng pick(seed * 31);
    const double offset = (pick.Uniform() < 0.5 ? -1 : 1) * (0.003 + 0.003 * pick.Uniform());
    const fs::path d = test::ScratchDir("audit_fusion_" + std::to_string(seed));
    WriteLogs(d, offset, seed);
    std::string out;
    ASSERT_EQ(RunCli("audit fusion -q --tracker poses.csv --robot joints.csv --setup setup.yaml --json a.json", d, &out), 0)
        << out;
    std::printf("hidden clock offset %.4f s\n%s", offset, out.c_str());
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(d / "a.json"));
    EXPECT_EQ(j["mode"], "fusion");
    ASSERT_GE(j["effects"].size(), 1u) << out;
    EXPECT_EQ(j["effects"][0]["name"], "clock_offset");
    EXPECT_EQ(j["effects"][0]["where"], "robot");
    const double est = j["effects"][0]["parameters"]["offset_s"].get<double>();
    const double sig = j["effects"][0]["sigma"]["offset_s"].get<double>();
    // clock_offset is the joint log's stamp's correction to the tracker's clock
    // (model/extensions.h ReferenceTimeT): stamps late by `offset` need -offset.
    EXPECT_LT(std::abs(est + offset), 3 * sig) << est << " +- " << sig;
  }
}

TEST(AppAuditFusion, SameLogsWithoutTheOffsetAreClean) {
  const fs::path d = test::ScratchDir("audit_fusion_clean");
  WriteLogs(d, 0.0, 5);
  std::string out;
  ASSERT_EQ(RunCli("audit fusion -q --tracker poses.csv --robot joints.csv --setup setup.yaml --json a.json", d, &out), 0)
      << out;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(d / "a.json"));
  EXPECT_TRUE(j["clean"].get<bool>()) << out;
}

TEST(AppAuditFusion, LogsOnDifferentClocksAreRefused) {
  const fs::path d = test::ScratchDir("audit_fusion_bad");
  WriteLogs(d, 0.0, 6);
  // Joint log shifted by an hour: no tracked frame falls inside it.
  std::ifstream in(d / "joints.csv");
  std::ostringstream o;
  std::string line;
  std::getline(in, line);
  o << line << "\n";
  while (std::getline(in, line)) {
    const auto c = line.find(',');
    o << test::N(std::stod(line.substr(0, c)) + 3600.0) << line.substr(c) << "\n";
  }
  in.close();
  std::ofstream(d / "joints.csv") << o.str();
  std::string out;
  EXPECT_NE(RunCli("audit fusion -q --tracker poses.csv --robot joints.csv --setup setup.yaml --json a.json", d, &out), 0);
  EXPECT_NE(out.find("same clock"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(d / "a.json"));
}

}  // namespace
}  // namespace mcms
