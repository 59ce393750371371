// Hostile inputs of issue 37, through one mechanism each: the number limits of
// core/limits.h (threads, a robot's lengths, encoder noise, masses, temperatures), the one
// YAML loader that refuses a duplicated key (core/yaml.h), unique joint names, and
// calib-robot's refusal to write a calibration it cannot trust (calib-rig's rule, with
// --allow-poor-fit). Each is refused before any work with the input and the limit named,
// a non-zero exit, and nothing written.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/random.h"
#include "model/robot_model.h"
#include "tests/cli_runner.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;
using test::CliRun;

const fs::path kSource = MCMS_SOURCE_DIR;

// Refused: non-zero exit, every part in stderr, the folder unchanged.
CliRun ExpectRefused(const fs::path& dir, const std::string& args, const std::vector<std::string>& parts) {
  const auto before = test::Snapshot(dir);
  const CliRun r = test::Mcms(dir, args);
  EXPECT_NE(r.code, 0) << args;
  EXPECT_EQ(r.err.find("internal error"), std::string::npos) << args << "\n" << r.err;
  for (const auto& p : parts) EXPECT_NE(r.err.find(p), std::string::npos) << args << "\nmissing: " << p << "\n" << r.err;
  EXPECT_EQ(test::Snapshot(dir), before) << args << ": something was written";
  return r;
}

std::string Kr5Yaml() { return test::ReadAll(kSource / "model" / "robots" / "kuka_kr5_arc.yaml"); }

TEST(AttackLimits, ThreadsBeyondTheLimitAreRefusedBeforeAnyWork) {
  const auto d = test::ScratchDir("attack_limits_threads");
  ExpectRefused(d, "fov-map --threads 100000 -o out --quiet", {"--threads", "256"});
  ExpectRefused(d, "render --threads 100000 -o rec -q", {"--threads", "256"});
  ExpectRefused(d, "track rec --threads 100000", {"--threads", "256"});
  ExpectRefused(d, "demo --threads 100000 -o demo", {"--threads", "256"});
  // Issue 53: a read noise or threshold beyond any level an image holds (was "target never found").
  ExpectRefused(d, "track rec --read-noise 1e300", {"--read-noise", "65535"});
  ExpectRefused(d, "track rec --threshold 1e9", {"--threshold", "65535"});
  ExpectRefused(d, "fov-map --read-noise 1e300 -o out --quiet", {"--read-noise", "65535"});
}

TEST(AttackLimits, RobotLengthsEncoderNoiseAndMassesBeyondAnyRobot) {
  const auto d = test::ScratchDir("attack_limits_robot");
  fs::copy_file(kSource / "examples" / "robot_measurements.yaml", d / "m.yaml", fs::copy_options::overwrite_existing);
  std::string huge = Kr5Yaml();
  huge.replace(huge.find("a_m: 0.600"), 10, "a_m: 1.0e300");
  test::WriteText(d / "huge.yaml", huge);
  ExpectRefused(d, "calib-robot m.yaml --robot huge.yaml -o out.yaml --quiet", {"huge.yaml", "A2", "1e+300", "1000 m"});
  ExpectRefused(d, "calib-robot m.yaml --tool-guess 0 0 1e300 1 0 0 0 -o out.yaml --quiet",
                {"--tool-guess z", "1000 m"});
  std::string noisy = Kr5Yaml();
  noisy.replace(noisy.find("encoder_sigma_rad: 1.0e-5"), 25, "encoder_sigma_rad: 1.0e300");
  test::WriteText(d / "noisy.yaml", noisy);
  ExpectRefused(d, "calib-robot m.yaml --robot noisy.yaml -o out.yaml --quiet", {"noisy.yaml", "encoder_sigma", "0.1 rad"});
  // A log's payload and temperature.
  std::string log = test::ReadAll(kSource / "examples" / "robot_log.csv");
  std::string cold = std::regex_replace(log, std::regex(",21\\.001\\n"), ",-300\n");
  test::WriteText(d / "cold.csv", cold);
  ExpectRefused(d, "audit robot cold.csv -o aud -q", {"cold.csv", "temperature_c", "-300", "-100"});
}

TEST(AttackLimits, DuplicatedYamlKeysAndJointNamesAreRefusedNamingBoth) {
  const auto d = test::ScratchDir("attack_limits_yaml");
  fs::copy_file(kSource / "examples" / "robot_measurements.yaml", d / "m.yaml", fs::copy_options::overwrite_existing);
  std::string twice = Kr5Yaml();
  twice.replace(twice.find("convention: standard_dh"), 23, "convention: standard_dh\nconvention: modified_dh");
  test::WriteText(d / "twice.yaml", twice);
  ExpectRefused(d, "calib-robot m.yaml --robot twice.yaml -o out.yaml --quiet",
                {"twice.yaml", "key 'convention' appears twice"});
  std::string names = Kr5Yaml();
  names.replace(names.find("name: A3"), 8, "name: A2");
  test::WriteText(d / "names.yaml", names);
  ExpectRefused(d, "calib-robot m.yaml --robot names.yaml -o out.yaml --quiet", {"names.yaml", "'A2'", "unique"});
  // A scenario and a fusion setup go through the same loader.
  std::string scenario = test::ReadAll(kSource / "examples" / "short_scenario.yaml");
  scenario += "\nseed: 3\nseed: 4\n";
  test::WriteText(d / "scenario.yaml", scenario);
  ExpectRefused(d, "render scenario.yaml -o rec -q", {"scenario.yaml", "key 'seed' appears twice"});
}

TEST(AttackLimits, RenderOfAnImageNoMemoryHoldsIsRefusedBeforeAnyWork) {
  const auto d = test::ScratchDir("attack_limits_render");
  std::string scenario = test::ReadAll(kSource / "examples" / "short_scenario.yaml");
  scenario.replace(scenario.find("imagersize: [1280, 1024]"), 24, "imagersize: [100000, 100000]");
  test::WriteText(d / "big.yaml", scenario);
  ExpectRefused(d, "render big.yaml -o rec -q", {"cam0", "100000 x 100000", "2e+08 px"});
}

TEST(AttackLimits, CalibRobotWritesNothingItCannotTrustUnlessAllowed) {
  const auto d = test::ScratchDir("attack_limits_calib");
  fs::copy_file(kSource / "examples" / "robot_measurements.yaml", d / "m.yaml", fs::copy_options::overwrite_existing);
  ExpectRefused(d, "calib-robot m.yaml --max-iterations 1 -o out.yaml --report rep.txt --quiet",
                {"m.yaml", "not trustworthy", "did not converge", "no output written", "--allow-poor-fit"});
  const CliRun r = test::Mcms(d, "calib-robot m.yaml --max-iterations 1 --allow-poor-fit -o out.yaml --report rep.txt --quiet");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(d / "out.yaml"));
  EXPECT_NE(test::ReadAll(d / "rep.txt").find("WARNING: the calibration is not trustworthy"), std::string::npos);
  // The example converges and is written without a warning.
  const CliRun ok = test::Mcms(d, "calib-robot m.yaml -o good.yaml --report good.txt --quiet");
  ASSERT_EQ(ok.code, 0) << ok.err;
  EXPECT_EQ(test::ReadAll(d / "good.txt").find("WARNING"), std::string::npos);
}

// Two outputs of one run on one file (calib-robot -o x.yaml --report x.yaml): refused before
// the work, naming both, instead of one silently replacing the other; and a file output
// inside a folder output that is replaced as a whole.
TEST(AttackLimits, TwoOutputsOnOneFileAreRefusedNamingBoth) {
  const auto d = test::ScratchDir("attack_limits_clash");
  fs::copy_file(kSource / "examples" / "robot_measurements.yaml", d / "m.yaml", fs::copy_options::overwrite_existing);
  ExpectRefused(d, "calib-robot m.yaml -o x.yaml --report x.yaml --quiet",
                {"calib-robot -o x.yaml", "calib-robot --report x.yaml", "name the same file"});
  ExpectRefused(d, "calib-robot m.yaml -o x.yaml --report sub/../x.yaml --quiet", {"name the same file"});
  // A file the robot's URDF names (a mesh) is the user's, like the URDF (issue 53).
  {
    std::string urdf = test::ReadAll(kSource / "examples" / "robots" / "kuka_kr5_arc.urdf");
    const std::string link = "<link name=\"A1_link\">";
    urdf.replace(urdf.find(link), link.size(),
                 link + "<visual><geometry><mesh filename=\"meshes/a1.xml\"/></geometry></visual>");
    test::WriteText(d / "kr5m.urdf", urdf);
    fs::create_directories(d / "meshes");
    test::WriteText(d / "meshes" / "a1.xml", "<mesh of the user's/>\n");
    ExpectRefused(d, "calib-robot m.yaml --robot kr5m.urdf -o meshes/a1.xml --quiet",
                  {"meshes/a1.xml", "which this run read; it was not replaced"});
    EXPECT_EQ(test::ReadAll(d / "meshes" / "a1.xml"), "<mesh of the user's/>\n");
  }
  ExpectRefused(d, "calib-robot m.yaml -o x.yaml --plot x.yaml --quiet", {"--plot", "name the same file"});
  ExpectRefused(d, "fov-map --quiet -o out --json out/fov.json", {"fov-map -o out", "fov-map --json out/fov.json",
                                                                 "inside the other's output folder"});
}

// Lengths in mm where metres are expected (issue 37: a tracker log in mm fused the flange at
// 142 m; a setup's T_base_rig in mm at 745 m): refused, naming the file, the line or key
// and the likely unit, before any fusion.
TEST(AttackLimits, TrackerPosesAndRigRegistrationInMillimetresAreRefused) {
  const auto d = test::ScratchDir("attack_limits_units");
  for (const char* f : {"tracker_poses.csv", "robot_joints.csv", "inclinometer.csv", "fusion_setup.yaml"})
    fs::copy_file(kSource / "examples" / "fusion" / f, d / f, fs::copy_options::overwrite_existing);
  // x_m, y_m, z_m (columns 5-7) times 1000.
  std::istringstream in(test::ReadAll(d / "tracker_poses.csv"));
  std::string line, mm;
  for (int row = 0; std::getline(in, line); ++row) {
    if (row > 0 && !line.empty() && line[0] != '#') {
      std::vector<std::string> cells;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
      for (int k = 4; k < 7; ++k) cells[k] = std::to_string(1000.0 * std::stod(cells[k]));
      line.clear();
      for (size_t k = 0; k < cells.size(); ++k) line += (k ? "," : "") + cells[k];
    }
    mm += line + "\n";
  }
  test::WriteText(d / "tracker_mm.csv", mm);
  std::string setup = test::ReadAll(d / "fusion_setup.yaml");
  const std::string t = "translation_m: [0.75, 0, 0.050000000000000044]";
  ASSERT_NE(setup.find(t), std::string::npos);
  setup.replace(setup.find(t), t.size(), "translation_m: [750, 0, 50]");
  test::WriteText(d / "setup_mm.yaml", setup);
  const std::string logs = " --robot robot_joints.csv --inclinometer inclinometer.csv -o fused.csv";
  ExpectRefused(d, "fuse --tracker tracker_mm.csv --setup fusion_setup.yaml" + logs,
                {"tracker_mm.csv line", "m from the rig", "in mm? expected metres"});
  ExpectRefused(d, "fuse --tracker tracker_poses.csv --setup setup_mm.yaml" + logs,
                {"setup_mm.yaml", "T_base_rig puts the rig 751", "in mm? expected metres"});
}

// The ownership rule of output folders (core/output_folder.h): a folder holding the
// user's own files is refused and nothing in it touched; the run's own earlier output is
// replaced; what an interrupted run left beside it is removed.
TEST(AttackLimits, OutputFoldersHoldingTheUsersFilesAreRefusedAndKept) {
  const auto d = test::ScratchDir("attack_limits_folders");
  fs::copy_file(kSource / "examples" / "robot_log.csv", d / "log.csv", fs::copy_options::overwrite_existing);
  fs::create_directories(d / "keep");
  test::WriteText(d / "keep" / "report.json", "{}\n");
  test::WriteText(d / "keep" / "notes.txt", "my notes\n");
  ExpectRefused(d, "audit robot log.csv -o keep -q", {"keep", "notes.txt", "nothing in it was touched"});
  EXPECT_EQ(test::ReadAll(d / "keep" / "notes.txt"), "my notes\n");

  // Twice into the same folder: the second run replaces the first's output.
  ASSERT_EQ(test::Mcms(d, "audit robot log.csv -o aud -q").code, 0);
  EXPECT_TRUE(fs::exists(d / "aud" / ".mcms-output"));
  const CliRun again = test::Mcms(d, "audit robot log.csv -o aud -q");
  EXPECT_EQ(again.code, 0) << again.err;
  // Its plots/ made read-only: it cannot be replaced whole, so it is refused before the work
  // (not replaced half-way with the old output left beside it). Run as an ordinary user
  // (root writes anyway): setpriv to nobody when the tests run as root.
  {
    fs::path ro = test::ScratchDir("attack_limits_readonly");
    std::string as_user, cli = MCMS_CLI, log = (d / "log.csv").string();
    if (::geteuid() == 0) {
      // nobody may not reach a checkout in a private folder (mode 700, as mktemp -d makes
      // them, issue 53): the run happens in a folder of the system's temporary directory
      // with the program and the log copied into it.
      ro = fs::temp_directory_path() / ("mcms_attack_readonly-" + std::to_string(::getpid()));
      fs::remove_all(ro);
      fs::create_directories(ro);
      fs::copy_file(MCMS_CLI, ro / "mcms");
      fs::copy_file(d / "log.csv", ro / "log.csv");
      ASSERT_EQ(std::system(("chmod 755 '" + ro.string() + "' && chown -R 65534:65534 '" + ro.string() + "'").c_str()),
                0);
      cli = (ro / "mcms").string();
      log = (ro / "log.csv").string();
      as_user = "setpriv --reuid=65534 --regid=65534 --clear-groups ";
    }
    const std::string run = as_user + "'" + cli + "' audit robot '" + log + "' -o aro -q";
    ASSERT_EQ(test::Shell(ro, run).code, 0);
    fs::permissions(ro / "aro" / "plots", fs::perms::owner_write, fs::perm_options::remove);
    const auto before = test::Snapshot(ro);
    const CliRun r = test::Shell(ro, run);
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find("folder plots is not writable"), std::string::npos) << r.err;
    EXPECT_EQ(test::Snapshot(ro), before);
    fs::permissions(ro / "aro" / "plots", fs::perms::owner_write, fs::perm_options::add);
    if (::geteuid() == 0) fs::remove_all(ro);
  }
  // A file added to it since is the user's: refused, kept.
  test::WriteText(d / "aud" / "mine.txt", "x\n");
  ExpectRefused(d, "audit robot log.csv -o aud -q", {"aud", "mine.txt"});
  // Issue 53: the record edited to list it (with or without a fingerprint made up) does not
  // make it the run's: refused, kept; and so is a file the run wrote that was edited since.
  {
    const std::string record = test::ReadAll(d / "aud" / ".mcms-output");
    test::WriteText(d / "aud" / ".mcms-output", record + "mine.txt\n");
    ExpectRefused(d, "audit robot log.csv -o aud -q", {"aud", "mine.txt", "or that changed since"});
    test::WriteText(d / "aud" / ".mcms-output", record + "mine.txt\tf 2 0000000000000000\n");
    ExpectRefused(d, "audit robot log.csv -o aud -q", {"aud", "mine.txt"});
    EXPECT_EQ(test::ReadAll(d / "aud" / "mine.txt"), "x\n");
    fs::remove(d / "aud" / "mine.txt");
    test::WriteText(d / "aud" / ".mcms-output", record);
    test::WriteText(d / "aud" / "report.txt", test::ReadAll(d / "aud" / "report.txt") + "my remark\n");
    ExpectRefused(d, "audit robot log.csv -o aud -q", {"aud", "report.txt", "or that changed since"});
    EXPECT_NE(test::ReadAll(d / "aud" / "report.txt").find("my remark"), std::string::npos);
    test::WriteText(d / "aud" / "mine.txt", "x\n");
  }
  // Another command's output folder is not replaced either.
  ExpectRefused(d, "fov-map -o aud --quiet", {"aud", "audit robot", "not of"});

  // The demo writes in place: a folder of the user's own logs named like the demo's is
  // refused before minutes of simulation, its files untouched.
  fs::create_directories(d / "logs");
  test::WriteText(d / "logs" / "robot_joints.csv", "my joints\n");
  ExpectRefused(d, "demo -o logs -q --points 3 --no-iso9283", {"demo -o", "logs", "robot_joints.csv"});
  EXPECT_EQ(test::ReadAll(d / "logs" / "robot_joints.csv"), "my joints\n");

  // What a killed run left (a process id that no longer runs) is removed by the next run.
  fs::create_directories(d / ".aud2.partial-999999999");
  ASSERT_EQ(test::Mcms(d, "audit robot log.csv -o aud2 -q").code, 0);
  EXPECT_FALSE(fs::exists(d / ".aud2.partial-999999999"));
}

// Files a run reads through another input are inputs too (core/io.h RunInputsRecord): a
// rig's camera model files, a fusion setup's robot, the files of a reported folder; and
// nothing is written into a folder a run reads whole (a poses.csv among the images).
TEST(AttackLimits, FilesReadThroughAnotherInputAreNeverReplaced) {
  const auto d = test::ScratchDir("attack_limits_read_through");
  fs::remove_all(d / "rec");
  ASSERT_EQ(test::Mcms(d, "render --frames 3 -q -o rec").code, 0);
  fs::remove(d / "rec" / ".mcms-output");
  std::string rig = "cameras:\n";
  for (int c = 0; c < 4; ++c)
    rig += "  - {name: cam" + std::to_string(c) + ", model: rec/cameras/cam" + std::to_string(c) + ".cameramodel}\n";
  test::WriteText(d / "rigm.yaml", rig);
  ExpectRefused(d, "track rec --rig rigm.yaml -q -o rec/cameras/cam0.cameramodel",
                {"track -o rec/cameras/cam0.cameramodel", "reads through another of its inputs"});
  ExpectRefused(d, "track rec -q -o rec/images/zz/poses.csv",
                {"rec/images/zz/poses.csv", "lies inside the input folder", "reads whole"});
  ExpectRefused(d, "report rec -o rec/truth/poses.csv", {"rec/truth/poses.csv", "inside the reported folder"});
  ExpectRefused(d, "report rec -o rec/cameras/cam0.cameramodel", {"cam0.cameramodel", "inside the reported folder"});
  // A rig of model files in the audited recording.
  fs::copy_file(d / "rigm.yaml", d / "rec" / "rig_models.yaml");
  std::string in_rec = rig;
  for (size_t p; (p = in_rec.find("rec/cameras")) != std::string::npos;) in_rec.replace(p, 11, "cameras");
  fs::copy(d / "rec", d / "recm", fs::copy_options::recursive);
  test::WriteText(d / "recm" / "rig.yaml", in_rec);
  ExpectRefused(d, "audit cameras recm -q --json recm/cameras/cam1.cameramodel",
                {"--json recm/cameras/cam1.cameramodel", "reads through another of its inputs"});

  // A setup naming its robot file.
  for (const char* f : {"tracker_poses.csv", "robot_joints.csv", "inclinometer.csv", "fusion_setup.yaml"})
    fs::copy_file(kSource / "examples" / "fusion" / f, d / f, fs::copy_options::overwrite_existing);
  test::WriteText(d / "kr5.yaml", Kr5Yaml());
  test::WriteText(d / "s.yaml", "robot: kr5.yaml\n" + test::ReadAll(d / "fusion_setup.yaml"));
  fs::create_directories(d / "aud");
  test::WriteText(d / "aud" / "robot.yaml", Kr5Yaml());
  test::WriteText(d / "s2.yaml", "robot: aud/robot.yaml\n" + test::ReadAll(d / "fusion_setup.yaml"));
  const std::string logs = " --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer inclinometer.csv";
  ExpectRefused(d, "fuse" + logs + " --setup s.yaml -o kr5.yaml", {"fuse -o kr5.yaml", "reads through another"});
  ExpectRefused(d, "audit fusion" + logs + " --setup s.yaml -q --json kr5.yaml",
                {"--json kr5.yaml", "reads through another"});
  ExpectRefused(d, "audit fusion" + logs + " --setup s2.yaml -q -o aud", {"-o aud holds", "robot.yaml"});
}

// Interrupted runs leave nothing behind: render and demo ended by SIGTERM while their
// temporary folder is being filled (core/interrupt.h) leave neither it nor an output.
TEST(AttackLimits, InterruptedRunsLeaveNothingBehind) {
  const auto d = test::ScratchDir("attack_limits_interrupt");
  for (const std::string run : {"render -q -o out", "demo -q --no-iso9283 -o out"}) {
    fs::remove_all(d);
    fs::create_directories(d);
    // Started, then killed once its temporary folder exists (polled, at most 60 s).
    const CliRun r = test::Shell(d, std::string("{ '").append(MCMS_CLI).append("' ").append(run).append(
                                        " & pid=$!; for i in $(seq 1 1200); do ls -a | grep -q '^.out.partial-' && break; "
                                        "sleep 0.05; done; sleep 0.5; kill -TERM $pid; wait $pid; echo \"exit=$?\"; }"));
    EXPECT_NE(r.out.find("exit=143"), std::string::npos) << run << ": " << r.out << r.err;
    for (const auto& e : fs::directory_iterator(d)) {
      const std::string name = e.path().filename().string();
      EXPECT_TRUE(name == "stdout.txt" || name == "stderr.txt") << run << " left " << name;
    }
  }
}

// A CSV with `change` applied to every data row's cells (given the header's cells);
// comment lines are kept.
std::string ChangedCsv(const fs::path& file,
                       const std::function<void(const std::vector<std::string>&, std::vector<std::string>&, int)>& change) {
  std::istringstream in(test::ReadAll(file));
  std::string line, out;
  std::vector<std::string> header;
  for (int row = 0; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') {
      out += line + "\n";
      continue;
    }
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    if (header.empty()) {
      header = cells;
    } else {
      change(header, cells, row++);
      line.clear();
      for (size_t k = 0; k < cells.size(); ++k) line += (k ? "," : "") + cells[k];
    }
    out += line + "\n";
  }
  return out;
}

size_t Col(const std::vector<std::string>& header, const std::string& name) {
  return std::find(header.begin(), header.end(), name) - header.begin();
}

// Units and layouts that used to turn into answers (issue 37, 3): each refused naming the
// file and the likely cause, nothing written.
TEST(AttackLimits, UnitsAndSwappedColumnsAreNamedNotAnswered) {
  const auto d = test::ScratchDir("attack_limits_more_units");
  for (const char* f : {"tracker_poses.csv", "robot_joints.csv", "inclinometer.csv", "fusion_setup.yaml"})
    fs::copy_file(kSource / "examples" / "fusion" / f, d / f, fs::copy_options::overwrite_existing);
  const auto times1000 = [](const std::vector<std::string>& h, std::vector<std::string>& c, int,
                            const std::vector<std::string>& cols) {
    for (const auto& name : cols) c[Col(h, name)] = std::to_string(1000.0 * std::stod(c[Col(h, name)]));
  };
  test::WriteText(d / "joints_ms.csv", ChangedCsv(d / "robot_joints.csv", [&](const auto& h, auto& c, int r) {
                    times1000(h, c, r, {"time_s"});
                  }));
  test::WriteText(d / "incl_swapped.csv", ChangedCsv(d / "inclinometer.csv", [](const auto& h, auto& c, int) {
                    std::swap(c[Col(h, "tilt_x_rad")], c[Col(h, "tilt_y_rad")]);
                  }));
  ExpectRefused(d,
                "fuse --tracker tracker_poses.csv --robot joints_ms.csv --inclinometer inclinometer.csv "
                "--setup fusion_setup.yaml -o fused.csv",
                {"joints_ms.csv: its times span 10", "times as long as those of tracker_poses.csv", "in ms?"});
  ExpectRefused(d, "audit fusion --tracker tracker_poses.csv --robot joints_ms.csv --setup fusion_setup.yaml -q",
                {"joints_ms.csv: its times span", "in ms?"});
  ExpectRefused(d,
                "audit fusion --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer incl_swapped.csv "
                "--setup fusion_setup.yaml -q",
                {"incl_swapped.csv", "tilt_x and tilt_y exchanged", "columns swapped?"});
  // The untouched logs pass both.
  EXPECT_EQ(test::Mcms(d, "audit fusion --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer "
                          "inclinometer.csv --setup fusion_setup.yaml -q")
                .code,
            0);

  // ISO 9283 attained positions in mm.
  test::WriteText(d / "iso_mm.csv", ChangedCsv(kSource / "examples" / "iso9283" / "poses.csv",
                                               [&](const auto& h, auto& c, int r) { times1000(h, c, r, {"x_m", "y_m", "z_m"}); }));
  ExpectRefused(d, "iso9283 iso_mm.csv", {"iso_mm.csv", "attained positions x_m, y_m, z_m in mm?"});
  // x and y exchanged in every other row of a robot log: 880 mm RMS, no joint offset named.
  test::WriteText(d / "xy_half.csv", ChangedCsv(kSource / "examples" / "robot_log.csv", [](const auto& h, auto& c, int r) {
                    if (r % 2) std::swap(c[Col(h, "x_m")], c[Col(h, "y_m")]);
                  }));
  ExpectRefused(d, "audit robot xy_half.csv -q", {"xy_half.csv", "mm RMS", "x and y swapped in some?"});
  // The paper's Table 1 in metres under its _mm headers.
  // (the real table when ../shared/data is there)
  const fs::path table = test::DataRoot() / "paper" / "table1_point_repeatability.csv";
  if (fs::exists(table)) {
    test::WriteText(d / "t1_m.csv", ChangedCsv(table, [](const auto&, auto& c, int) {
                      for (size_t k = 2; k < c.size(); ++k) c[k] = std::to_string(std::stod(c[k]) / 1000);
                    }));
    ExpectRefused(d, "fov-map --quiet --measured t1_m.csv -o fm", {"t1_m.csv", "median", "metres under the _mm"});
  }
}

// A recording without frames.csv tracked without --rate: frames 10 Hz apart, said in the
// output and on stderr (it used to be silent); an implausible --rate is refused.
TEST(AttackLimits, TrackWithoutFrameTimesSaysWhatItAssumes) {
  const auto d = test::ScratchDir("attack_limits_rate");
  fs::remove_all(d / "rec");
  ASSERT_EQ(test::Mcms(d, "render --frames 3 -q -o rec").code, 0);
  fs::remove(d / "rec" / "frames.csv");
  fs::remove(d / "rec" / ".mcms-output");
  const CliRun r = test::Mcms(d, "track rec -o p.csv");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE((r.out + r.err).find("an assumed 10 Hz; give --rate"), std::string::npos) << r.out << r.err;
  EXPECT_NE(test::ReadAll(d / "p.csv").find("# frame times: no frames CSV"), std::string::npos);
  const CliRun given = test::Mcms(d, "track rec --rate 25 -o p25.csv");
  ASSERT_EQ(given.code, 0) << given.err;
  EXPECT_EQ((given.out + given.err).find("assumed"), std::string::npos) << given.out << given.err;
  EXPECT_NE(test::ReadAll(d / "p25.csv").find("\n2,0.08,"), std::string::npos) << "frame 2 at 2 / 25 s";
  ExpectRefused(d, "track rec --rate 1e-300 -o q.csv", {"--rate", "0.001 to 1e6 Hz"});
  ExpectRefused(d, "track rec --rate 1e300 -o q.csv", {"--rate", "0.001 to 1e6 Hz"});
}

// A 50-joint chain: its whole catalog (5961 parameters) would need some 15 GB to
// linearise (it took 170 s); refused before any work with what to do, and audited in
// seconds with the effects the user names (--only).
TEST(AttackLimits, AuditRobotOfAVeryLongChainIsBoundedAndSaysHow) {
  const auto d = test::ScratchDir("attack_limits_long_chain");
  std::string yaml = "name: snake50\nconvention: standard_dh\nencoder_sigma_rad: 1.0e-5\njoints:\n";
  for (int j = 0; j < 50; ++j)
    yaml += "  - {name: J" + std::to_string(j + 1) + ", d_m: 0, a_m: 0.03, theta_offset_rad: 0, alpha_deg: " + (j % 2 ? "90" : "-90") +
            ", limits_deg: [-90, 90]}\n";
  test::WriteText(d / "r50.yaml", yaml);
  const RobotModel robot = RobotModel::Read(d / "r50.yaml");
  Rng rng(50);
  std::string log = "time_s";
  for (int j = 0; j < 50; ++j) log += ",q" + std::to_string(j + 1) + "_rad";
  log += ",x_m,y_m,z_m\n";
  for (int i = 0; i < 120; ++i) {
    Eigen::VectorXd q(50);
    for (int j = 0; j < 50; ++j) q[j] = rng.Uniform(-0.5, 0.5);
    const Vec3 p = robot.T_base_tool(q).t + Vec3(rng.Normal(), rng.Normal(), rng.Normal()) * 2e-5;
    std::ostringstream row;
    row.precision(12);
    row << 10 * i;
    for (int j = 0; j < 50; ++j) row << "," << q[j];
    row << "," << p.x() << "," << p.y() << "," << p.z() << "\n";
    log += row.str();
  }
  test::WriteText(d / "log50.csv", log);
  ExpectRefused(d, "audit robot log50.csv --robot r50.yaml -q -o out",
                {"log50.csv (120 measurements)", "50 joints, 5961 parameters", "MB to linearise", "--only"});
  const CliRun only = test::Mcms(d, "audit robot log50.csv --robot r50.yaml --only joint_offset -q -o out");
  EXPECT_EQ(only.code, 0) << only.err;
}

// What the second attack (360 new inputs) found, one line each: outputs onto devices and
// FIFOs, two image folders of one camera name, the user's own report.html, YAML alias
// bombs, URDFs nested beyond any robot, sigmas and counts no run can hold, and the
// temporaries a killed track left, removed by the next run.
TEST(AttackLimits, SecondAttackFindings) {
  const auto d = test::ScratchDir("attack_limits_second");
  {
    // (not through ExpectRefused: its snapshot would read the FIFO and wait for a writer)
    const auto f = test::ScratchDir("attack_limits_fifo");
    ASSERT_EQ(::system(("rm -f '" + (f / "fifo.csv").string() + "' && mkfifo '" + (f / "fifo.csv").string() + "'").c_str()), 0);
    const CliRun r = test::Mcms(f, "iso9283 '" + (kSource / "examples" / "iso9283" / "poses.csv").string() + "' -o fifo.csv");
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find("fifo.csv is a device, FIFO or socket"), std::string::npos) << r.err;
    EXPECT_TRUE(fs::is_fifo(f / "fifo.csv"));
  }

  fs::create_directories(d / "a");
  fs::create_directories(d / "b");
  fs::copy(kSource / "examples" / "boards" / "cam0", d / "a" / "cam0", fs::copy_options::recursive | fs::copy_options::skip_existing);
  fs::copy(kSource / "examples" / "boards" / "cam0", d / "b" / "cam0", fs::copy_options::recursive | fs::copy_options::skip_existing);
  fs::copy_file(kSource / "examples" / "boards" / "board.yaml", d / "board.yaml", fs::copy_options::overwrite_existing);
  ExpectRefused(d, "calib-rig board.yaml a/cam0 b/cam0 -o out", {"a/cam0", "b/cam0", "both name camera 'cam0'"});

  fs::create_directories(d / "rp");
  test::WriteText(d / "rp" / "notes.txt", "run notes\n");
  test::WriteText(d / "rp" / "report.html", "<html>my own page</html>\n");
  ExpectRefused(d, "report rp", {"rp/report.html exists and is not a page mcms report wrote"});
  fs::remove(d / "rp" / "report.html");
  ASSERT_EQ(test::Mcms(d, "report rp").code, 0);
  EXPECT_EQ(test::Mcms(d, "report rp").code, 0) << "its own page is replaced";
  // Issue 53: a link in the folder to a system file is listed, never followed into the page;
  // a file name that is not UTF-8 is shown with U+FFFD, the page stays UTF-8.
  {
    fs::create_directories(d / "rl");
    test::WriteText(d / "rl" / "notes.txt", "run notes\n");
    test::WriteText(d / "rl" / "odd\xff\xfe.txt", "x\n");
    test::WriteText(d / "secret.yaml", "token: s3cr3t-value\n");
    fs::remove(d / "rl" / "robot.yaml");
    fs::create_symlink(d / "secret.yaml", d / "rl" / "robot.yaml");
    fs::remove(d / "rl" / "report.html");
    const CliRun r = test::Mcms(d, "report rl");
    ASSERT_EQ(r.code, 0) << r.err;
    const std::string page = test::ReadAll(d / "rl" / "report.html");
    EXPECT_EQ(page.find("s3cr3t-value"), std::string::npos) << "a link followed into the page";
    EXPECT_NE(page.find("robot.yaml (a symbolic link, not followed)"), std::string::npos);
    EXPECT_EQ(page.find("\xff"), std::string::npos) << "a byte that is not UTF-8 in the page";
    EXPECT_NE(page.find("odd\xef\xbf\xbd\xef\xbf\xbd.txt"), std::string::npos);
  }

  // 9 levels of 9 aliases: 387 million values once expanded.
  std::string bomb = "a0: &a0 [x, x, x, x, x, x, x, x, x]\n";
  for (int k = 1; k < 10; ++k) {
    const std::string p = "*a" + std::to_string(k - 1);
    bomb += "a" + std::to_string(k) + ": &a" + std::to_string(k) + " [" + p;
    for (int j = 1; j < 9; ++j) bomb += ", " + p;
    bomb += "]\n";
  }
  test::WriteText(d / "bomb.yaml", bomb);
  ExpectRefused(d, "convert-robot bomb.yaml -o r.urdf", {"bomb.yaml", "aliases", "YAML bomb?"});
  std::string deep = "<robot name=\"r\">";
  for (int k = 0; k < 5000; ++k) deep += "<link name=\"l\">";
  test::WriteText(d / "deep.urdf", deep);
  ExpectRefused(d, "convert-robot deep.urdf -o r.yaml", {"deep.urdf", "nested more than 100 deep"});

  fs::copy_file(kSource / "examples" / "robot_measurements.yaml", d / "m.yaml", fs::copy_options::overwrite_existing);
  ExpectRefused(d, "calib-robot m.yaml -o r.yaml --quiet --position-sigma-mm 1e-300", {"--position-sigma-mm", "1e-4 mm (an interferometer's 0.1 um) to 1000 mm"});
  ExpectRefused(d, "iso9283 --simulate --cycles 2000000000 -o x.csv", {"--cycles"});
  ExpectRefused(d, "paper fusion --repetitions 1000000 --points 1000000", {"--repetitions", "1e7"});

  // A killed track's rows file (a process id that no longer runs) goes with the next run.
  fs::remove_all(d / "rec");
  ASSERT_EQ(test::Mcms(d, "render --frames 3 -q -o rec").code, 0);
  test::WriteText(d / "p.csv.rows.partial-999999999", "0,0\n");
  ASSERT_EQ(test::Mcms(d, "track rec -q -o p.csv").code, 0);
  EXPECT_FALSE(fs::exists(d / "p.csv.rows.partial-999999999"));
}

// The third round (findings of the second attack left for later): answers from wrapped
// or absurd numbers, outputs that fail late, options that were silently ignored.
TEST(AttackLimits, ThirdAttackFindings) {
  const auto d = test::ScratchDir("attack_limits_third");
  const std::string poses = "'" + (kSource / "examples" / "iso9283" / "poses.csv").string() + "'";
  // Seeds are whole numbers of 64 bits, not wrapped or saturated.
  ExpectRefused(d, "render --frames 3 -q -o rec --seed -1", {"seed '-1'", "2^64 - 1"});
  ExpectRefused(d, "render --frames 3 -q -o rec --seed 18446744073709551616", {"18446744073709551616", "2^64 - 1"});
  ExpectRefused(d, "fov-map -o fm --quiet --seed 1.5", {"seed '1.5'"});
  // CLI11's own range message printed 1.8e308 in 300 digits.
  ExpectRefused(d, "render --frames -3 -q -o rec", {"--frames", "expected a number > 0, found '-3'"});
  // A file output named like a folder, before any work (it left an empty folder o.csv).
  ExpectRefused(d, "iso9283 " + poses + " -o o.csv/", {"o.csv/", "ends with '/'"});
  // --write-measurements is the simulation's; never over the user's files.
  ExpectRefused(d, "iso9283 " + poses + " --write-measurements w", {"--write-measurements", "--simulate"});
  fs::create_directories(d / "mine");
  test::WriteText(d / "mine" / "attained_1.csv", "my own measurements\n");
  ExpectRefused(d, "iso9283 --simulate --cycles 3 --write-measurements mine", {"mine", "attained_1.csv"});
  EXPECT_EQ(test::ReadAll(d / "mine" / "attained_1.csv"), "my own measurements\n");
  fs::remove_all(d / "mine");
  ASSERT_EQ(test::Mcms(d, "iso9283 --simulate --cycles 3 --write-measurements sim").code, 0);
  EXPECT_TRUE(fs::exists(d / "sim" / "attained_1.csv"));
  EXPECT_EQ(test::Mcms(d, "iso9283 --simulate --cycles 3 --write-measurements sim").code, 0) << "its own output is replaced";
  // Scenario values that rendered nothing, or what the tracker refuses.
  std::string scenario = test::Mcms(d, "render --print-default").out;
  ASSERT_NE(scenario.find("target: default"), std::string::npos);
  ASSERT_NE(scenario.find("spurious_radius_px: [1, 4]"), std::string::npos);
  std::string coincident = scenario;
  coincident.replace(coincident.find("target: default"), 15,
                     "target:\n  ball_radius_m: 0.01\n  balls_m: [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]");
  test::WriteText(d / "coincident.yaml", coincident);
  ExpectRefused(d, "render coincident.yaml --frames 3 -q -o rec", {"target.balls_m", "balls 0 and 1 overlap"});
  std::string huge = scenario;
  huge.replace(huge.find("spurious_radius_px: [1, 4]"), 26, "spurious_radius_px: [1e6, 1e7]");
  test::WriteText(d / "huge.yaml", huge);
  ExpectRefused(d, "render huge.yaml --frames 3 -q -o rec", {"spurious radius", "1000"});
  ExpectRefused(d, "fov-map -o fm --quiet --grid=-1e308:1e308:3,0:0:1,2:2:1", {"--grid", "beyond 1000 m"});
  // Issue 53: a grid outside every camera's view is said as such (was blamed on the blob detector).
  ExpectRefused(d, "fov-map -o fm --quiet --grid=100:101:2,0:0:1,0:0:1",
                {"fov-map --grid", "none of its 2 points is in the view of two cameras"});
  // A camera name too long for a folder name (it blamed -o: 'File name too long').
  std::string long_name = scenario;
  ASSERT_NE(long_name.find("names: [cam0, cam1"), std::string::npos);
  long_name.replace(long_name.find("names: [cam0, cam1"), 18, "names: [cam0, " + std::string(300, 'c'));
  test::WriteText(d / "long_name.yaml", long_name);
  ExpectRefused(d, "render long_name.yaml --frames 3 -q -o rec", {"camera name", "300 characters, at most 100"});
  ExpectRefused(d, "demo --camera-rate 0.1 -o dm", {"--camera-rate", "0.143"});
  // Recordings: a frames.csv without rows, an image folder that is a file.
  ASSERT_EQ(test::Mcms(d, "render --frames 3 -q -o rec").code, 0);
  test::WriteText(d / "rec" / "frames.csv", "frame,time_s\n");
  ExpectRefused(d, "track rec -q -o p.csv", {"frames.csv", "a header and no rows"});
  ExpectRefused(d, "track rec -q --images /dev/null -o p.csv", {"/dev/null is not a folder"});
  // A truth file in millimetres under metre headers: named, nothing written (it printed a
  // position error of 769511 mm and a mean NEES of 3.8e15 and exited 0).
  ASSERT_EQ(test::Mcms(d, "render --frames 4 -q -o rec_mm").code, 0);
  {
    std::istringstream in(test::ReadAll(d / "rec_mm" / "truth" / "poses.csv"));
    std::string line, out;
    std::getline(in, line);
    out = line + "\n";
    while (std::getline(in, line)) {
      std::vector<std::string> f;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) f.push_back(c);
      ASSERT_EQ(f.size(), 9u) << line;
      for (int k = 2; k < 5; ++k) f[k] = std::to_string(1e3 * std::stod(f[k]));
      for (size_t k = 0; k < f.size(); ++k) out += f[k] + (k + 1 < f.size() ? "," : "\n");
    }
    test::WriteText(d / "truth_mm.csv", out);
  }
  ExpectRefused(d, "track rec_mm -q --truth truth_mm.csv -o p.csv", {"truth_mm.csv", "millimetres under metre headers"});
  EXPECT_EQ(test::Mcms(d, "track rec_mm -q --truth rec_mm/truth/poses.csv -o p.csv").code, 0) << "the truth in metres";
  // Attained quaternions scalar-last under qw..qz: named, not reported as AP_a = -180 deg.
  {
    std::istringstream in(test::ReadAll(kSource / "examples" / "iso9283" / "poses.csv"));
    std::string line, out;
    std::vector<std::string> head;
    std::getline(in, line);
    out = line + "\n";
    {
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) head.push_back(c);
    }
    const auto col = [&](const std::string& n) { return std::find(head.begin(), head.end(), n) - head.begin(); };
    const long w = col("qw"), x = col("qx"), y = col("qy"), z = col("qz");
    ASSERT_LT(z, static_cast<long>(head.size()));
    while (std::getline(in, line)) {
      std::vector<std::string> f;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) f.push_back(c);
      const std::vector<std::string> q = {f[w], f[x], f[y], f[z]};
      f[w] = q[1], f[x] = q[2], f[y] = q[3], f[z] = q[0];  // x, y, z, w
      for (size_t k = 0; k < f.size(); ++k) out += f[k] + (k + 1 < f.size() ? "," : "\n");
    }
    test::WriteText(d / "xyzw.csv", out);
  }
  ExpectRefused(d, "iso9283 xyzw.csv", {"xyzw.csv", "read scalar-last", "x, y, z, w under qw, qx, qy, qz?"});
  // Two camera folders swapped: the audit names the folders, not a short recording ('0
  // tracked frames, expected at least 10').
  ASSERT_EQ(test::Mcms(d, "render --frames 12 -q -o swapped").code, 0);
  fs::rename(d / "swapped" / "images" / "cam0", d / "swapped" / "images" / "tmp");
  fs::rename(d / "swapped" / "images" / "cam1", d / "swapped" / "images" / "cam0");
  fs::rename(d / "swapped" / "images" / "tmp", d / "swapped" / "images" / "cam1");
  ExpectRefused(d, "audit cameras swapped -q", {"never found in any of the 12 frames", "two folders swapped?"});
  // An output that is a symbolic link to nothing, named before the work.
  const auto l = test::ScratchDir("attack_limits_third_link");
  fs::create_directory_symlink(l / "gone", l / "out");
  const CliRun r = test::Mcms(l, "render --frames 3 -q -o out");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("is a symbolic link to"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("which does not exist"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(l / "gone"));
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// Issue 53: a disk that fills up (here a file-size limit, which fails the writes as a full
// disk does) is named by the system's reason at the file it was writing, never through a
// temporary name, and nothing is left behind.
// The sixth attack's findings (issue 53): answers from garbage, each now refused or right.
TEST(AttackLimits, SixthAttackFindings) {
  const auto d = test::ScratchDir("attack_limits_sixth");
  const auto times1000 = [](const std::vector<std::string>& h, std::vector<std::string>& c,
                            const std::vector<std::string>& cols) {
    for (const auto& name : cols) c[Col(h, name)] = std::to_string(1000.0 * std::stod(c[Col(h, name)]));
  };
  // ISO 9283 with every position column in mm (commanded and attained): AP 890 mm before.
  test::WriteText(d / "all_mm.csv", ChangedCsv(kSource / "examples" / "iso9283" / "poses.csv", [&](const auto& h, auto& c, int) {
                    times1000(h, c, {"x_m", "y_m", "z_m", "cmd_x_m", "cmd_y_m", "cmd_z_m"});
                  }));
  ExpectRefused(d, "iso9283 all_mm.csv", {"all_mm.csv: the commanded positions lie up to", "in mm under metre headers?"});
  test::WriteText(d / "far.csv", ChangedCsv(kSource / "examples" / "iso9283" / "poses.csv", [&](const auto& h, auto& c, int) {
                    for (const char* n : {"x_m", "cmd_x_m"}) c[Col(h, n)] = std::to_string(1e30 + std::stod(c[Col(h, n)]));
                  }));
  ExpectRefused(d, "iso9283 far.csv", {"far.csv: pose", "from the origin, beyond 1e+05 m"});
  // A scenario whose path reaches 1e300 m: truth files of NaN before.
  std::string scenario = test::Mcms(d, "render --print-default").out;
  const size_t at = scenario.find("amplitude_m: [0.3, 0.2, 0.3]");
  ASSERT_NE(at, std::string::npos);
  scenario.replace(at, 28, "amplitude_m: [1e300, 0.2, 0.3]");
  test::WriteText(d / "huge.yaml", scenario);
  ExpectRefused(d, "render huge.yaml -o rec --frames 2 -q", {"huge.yaml", "motion.amplitude_m", "within 100 m"});
  // A demo of one point: reductions shown, no verdict from a bootstrap of one.
  const CliRun one = test::Mcms(d, "demo -o one --points 1 --no-iso9283 --no-html -q");
  EXPECT_EQ(one.code, 0) << one.err;
  EXPECT_NE(one.out.find("no verdict from 1 points"), std::string::npos) << one.out;
  EXPECT_EQ(one.out.find("within 2 sd"), std::string::npos) << one.out;
  // Unix-epoch frame times keep their milliseconds in the tracker's output (all 1700000000
  // before, which fuse then refused as not increasing).
  ASSERT_EQ(test::Mcms(d, "render --frames 4 --quiet --threads 2 -o rec").code, 0);
  test::WriteText(d / "rec" / "frames.csv",
                  "frame,time_s\n0,1700000000.004\n1,1700000000.104\n2,1700000000.204\n3,1700000000.304\n");
  const CliRun tr = test::Mcms(d, "track rec -q -o poses.csv");
  ASSERT_EQ(tr.code, 0) << tr.err;
  const std::string poses = test::ReadAll(d / "poses.csv");
  for (const char* t : {"\n0,1700000000.004000,", "\n3,1700000000.304000,"})
    EXPECT_NE(poses.find(t), std::string::npos) << t << "\n" << poses.substr(0, 600);
  // A Kalman process noise beyond what the filter's arithmetic holds: named at the option or
  // the setup's field before any work ("innovation covariance is not positive definite"
  // after the rendering before).
  ExpectRefused(d, "demo -o psd --points 2 --no-iso9283 --no-html --kf-angular-psd 1e300 -q",
                {"--kf-angular-psd 1e+300", "angular_acceleration_psd must be positive and at most 1e+06"});
  for (const char* f : {"tracker_poses.csv", "robot_joints.csv", "fusion_setup.yaml"})
    fs::copy_file(kSource / "examples" / "fusion" / f, d / f, fs::copy_options::overwrite_existing);
  std::string setup = test::ReadAll(d / "fusion_setup.yaml");
  const size_t psd = setup.find("angular_acceleration_psd: 9.9999999999999998e-17");
  ASSERT_NE(psd, std::string::npos);
  setup.replace(psd, 48, "angular_acceleration_psd: 1e300");
  test::WriteText(d / "psd_setup.yaml", setup);
  ExpectRefused(d, "fuse --tracker tracker_poses.csv --robot robot_joints.csv --setup psd_setup.yaml -o fused.csv",
                {"psd_setup.yaml", "angular_acceleration_psd must be positive and at most 1e+06"});
  // A quaternion typed to five digits (norm 0.99999) is a rotation; 0.9 is not.
  for (const auto& [q, ok] : {std::pair<const char*, bool>{"[0.99999, 0, 0, 0]", true}, {"[0.9, 0, 0, 0]", false}}) {
    std::string typed = test::ReadAll(d / "fusion_setup.yaml");
    const size_t at = typed.find("quaternion_wxyz: [1, 0, 0, 0]\n  bias_rad");
    ASSERT_NE(at, std::string::npos);
    typed.replace(at, 29, std::string("quaternion_wxyz: ") + q);
    test::WriteText(d / "typed_setup.yaml", typed);
    const std::string cmd = "fuse --tracker tracker_poses.csv --robot robot_joints.csv --setup typed_setup.yaml -q -o typed.csv";
    if (ok) {
      const CliRun r = test::Mcms(d, cmd);
      EXPECT_EQ(r.code, 0) << r.err;
      fs::remove(d / "typed.csv");
    } else {
      ExpectRefused(d, cmd, {"typed_setup.yaml line 9", "inclinometer.quaternion_wxyz must have unit norm, has norm 0.9"});
    }
  }
  // A DH table in degrees under radian keys, or in millimetres under metre keys: converted
  // silently before (612 m links).
  std::string deg = Kr5Yaml(), mm = Kr5Yaml();
  deg.replace(deg.find("alpha_rad: 1.5707963267948966, theta_offset_rad: 0.0, limits_deg: [-15"), 29,
              "alpha_rad: 90.0");
  for (const auto& [from, to] : {std::pair<std::string, std::string>{"d_m: 0.400, a_m: 0.180", "d_m: 400, a_m: 180"},
                                 {"a_m: 0.600", "a_m: 600"}, {"d_m: -0.620", "d_m: -620"}})
    mm.replace(mm.find(from), from.size(), to);
  test::WriteText(d / "kr5_deg.yaml", deg);
  test::WriteText(d / "kr5_mm.yaml", mm);
  ExpectRefused(d, "convert-robot kr5_deg.yaml -o deg.urdf", {"kr5_deg.yaml", "alpha_rad is 90", "degrees? give alpha_deg"});
  ExpectRefused(d, "convert-robot kr5_mm.yaml -o mm.urdf", {"link lengths add up to", "millimetres read as metres?"});
  // A gain no camera has, a threshold at the 8-bit images' top, a read noise spanning their
  // range: named at the option before the sequence ("target never found" after it before).
  ExpectRefused(d, "track rec -q -o g.csv --gain 1e-300", {"--gain (gain_e_per_dn) 1e-300", "0.001 to 10000 e-/DN"});
  ExpectRefused(d, "track rec -q -o g.csv --threshold 255",
                {"--threshold 255 DN is at or beyond the largest level of the images (255: 8-bit", "rec/images/cam"});
  ExpectRefused(d, "track rec -q -o g.csv --read-noise 100", {"--read-noise 100 DN: three times it spans", "8-bit"});
  // A truth file whose quaternions are x, y, z, w under qw..qz: named, not "the covariance is
  // optimistic" with 154 deg of rotation error.
  ASSERT_EQ(test::Mcms(d, "render --frames 4 --quiet --threads 2 -o rec2").code, 0);
  test::WriteText(d / "rec2" / "truth" / "poses.csv",
                  ChangedCsv(d / "rec2" / "truth" / "poses.csv", [](const auto& h, auto& c, int) {
                    const std::string w = c[Col(h, "qw")];
                    c[Col(h, "qw")] = c[Col(h, "qx")], c[Col(h, "qx")] = c[Col(h, "qy")], c[Col(h, "qy")] = c[Col(h, "qz")];
                    c[Col(h, "qz")] = w;
                  }));
  ExpectRefused(d, "track rec2 -q -o tq.csv --truth auto",
                {"truth file rec2/truth/poses.csv", "quaternions in x, y, z, w order? expected qw, qx, qy, qz"});
  // A grid of 8e6 points (8 GB and 30 min of prediction): refused with its size and memory.
  ExpectRefused(d, "fov-map -o v --quiet --grid=-0.5:0.5:200,-0.4:0.4:200,0:1:200",
                {"8000000 grid points, more than 2000000", "GB"});
  // A scenario nested 100000 lists deep: named as nesting, not yaml-cpp's "bad file".
  test::WriteText(d / "deep.yaml", std::string(100000, '[') + std::string(100000, ']') + "\n");
  ExpectRefused(d, "render deep.yaml -o deep -q", {"deep.yaml", "levels deep"});
  // A URDF whose joints close a loop: named as a loop, not "give --base-link".
  const auto rev = [](const std::string& name, const std::string& parent, const std::string& child) {
    return "<joint name='" + name + "' type='revolute'><parent link='" + parent + "'/><child link='" + child +
           "'/><axis xyz='0 0 1'/><limit lower='-1' upper='1' effort='1' velocity='1'/></joint>";
  };
  test::WriteText(d / "loop.urdf", "<robot name='loop'><link name='base_link'/><link name='l1'/><link name='l2'/>"
                                   "<link name='l3'/><link name='l4'/>" + rev("j1", "base_link", "l1") +
                                       rev("j2", "l4", "l2") + rev("j3", "l2", "l3") + rev("j4", "l3", "l4") + "</robot>");
  ExpectRefused(d, "convert-robot loop.urdf -o loop.yaml", {"loop.urdf", "form a closed loop", "j2", "j3", "j4"});
  // An image that is a link to itself degrades its frame, named with the system's reason
  // (it aborted the whole run as an internal error).
  const fs::path loop = d / "rec" / "images" / "cam2" / "000001.png";
  fs::remove(loop);
  fs::create_symlink("000001.png", loop);
  const CliRun lr = test::Mcms(d, "track rec -q -o looped.csv");
  EXPECT_EQ(lr.code, 0) << lr.err;
  const std::string looped = test::ReadAll(d / "looped.csv");
  EXPECT_NE(looped.find("cannot read rec/images/cam2/000001.png: Too many levels of symbolic links"), std::string::npos)
      << looped.substr(0, 800);
}

// The last of the sixth attack's fusion findings: a tracker file of x, y, z, w quaternions
// under qw..qz (audit fusion named a 33 mrad joint offset, or blamed the inclinometer's
// unit), and an inclinometer whose mount in the setup turns it 90 deg (fuse left it out of
// every row without a word). Each named before any fusion, the file or key said.
TEST(AttackLimits, SixthAttackLogsCheckedAgainstEachOther) {
  const auto d = test::ScratchDir("attack_limits_cross_checks");
  for (const char* f : {"tracker_poses.csv", "robot_joints.csv", "fusion_setup.yaml", "inclinometer.csv"})
    fs::copy_file(kSource / "examples" / "fusion" / f, d / f, fs::copy_options::overwrite_existing);
  test::WriteText(d / "xyzw.csv", ChangedCsv(d / "tracker_poses.csv", [](const auto& h, auto& c, int) {
                    if (c[Col(h, "status")] != "ok") return;
                    const std::string w = c[Col(h, "qw")];
                    c[Col(h, "qw")] = c[Col(h, "qx")], c[Col(h, "qx")] = c[Col(h, "qy")], c[Col(h, "qy")] = c[Col(h, "qz")];
                    c[Col(h, "qz")] = w;
                  }));
  const std::vector<std::string> order = {"xyzw.csv: the tracked flange orientations differ from the robot's",
                                          "read scalar last: quaternions x, y, z, w under qw, qx, qy, qz?"};
  ExpectRefused(d, "audit fusion --tracker xyzw.csv --robot robot_joints.csv --setup fusion_setup.yaml -q", order);
  const CliRun both = ExpectRefused(
      d, "audit fusion --tracker xyzw.csv --robot robot_joints.csv --inclinometer inclinometer.csv --setup fusion_setup.yaml -q",
      order);
  EXPECT_EQ(both.err.find("another unit"), std::string::npos) << both.err;
  ExpectRefused(d, "fuse --tracker xyzw.csv --robot robot_joints.csv --setup fusion_setup.yaml -o fused.csv -q", order);
  // The mount 90 deg about x.
  std::string setup = test::ReadAll(d / "fusion_setup.yaml");
  const size_t at = setup.find("quaternion_wxyz: [1, 0, 0, 0]\n  bias_rad");
  ASSERT_NE(at, std::string::npos);
  setup.replace(at, 29, "quaternion_wxyz: [0.70710678, 0.70710678, 0, 0]");
  test::WriteText(d / "mount.yaml", setup);
  ExpectRefused(d,
                "fuse --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer inclinometer.csv "
                "--setup mount.yaml -o fused.csv -q",
                {"mount.yaml: the inclinometer's mount (inclinometer.quaternion_wxyz", "deg (median) from level",
                 "beyond its range", "inclinometer.csv reads within its range: is the mount right?"});
  // As given, both pass, and every fused row has used the inclinometer or said why not.
  const CliRun ok = test::Mcms(d, "fuse --tracker tracker_poses.csv --robot robot_joints.csv --inclinometer "
                                  "inclinometer.csv --setup fusion_setup.yaml -o fused.csv -q");
  ASSERT_EQ(ok.code, 0) << ok.err;
  fs::remove_all(d);
}

TEST(AttackLimits, AWriteThatFailsSaysWhy) {
  const auto d = test::ScratchDir("attack_write_fails");
  const CliRun r = test::Shell(d, std::string("bash -c 'trap \"\" XFSZ; ulimit -f 20; exec ") + MCMS_CLI +
                                      " demo --points 3 -o out -q'");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("error while writing output file"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("File too large"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("/out/"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("partial"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(d / "out"));
  for (const auto& e : std::filesystem::directory_iterator(d))
    EXPECT_EQ(e.path().filename().string().find("partial"), std::string::npos) << e.path();
  std::filesystem::remove_all(d);
}

}  // namespace
}  // namespace mcms
