// mcms iso9283: ISO 9283 pose, distance and path characteristics from measured poses
// (calib/iso9283.h).
//
// Input: a pose CSV with a header row and one row per attained pose:
//   pose,cycle,cmd_x_m,cmd_y_m,cmd_z_m,cmd_qw,cmd_qx,cmd_qy,cmd_qz,x_m,y_m,z_m,qw,qx,qy,qz
// `pose` names the commanded pose (P1..P5 in the standard), `cycle` the repetition; the
// commanded columns must be the same on every row of one pose; quaternions are w,x,y,z,
// unit norm; both poses in the base (or measuring) frame, metres.
// Optional path CSV (--path):  run,x_m,y_m,z_m   with run = "commanded" for the commanded
// path (its rows, in order, are the calculation points) and any other label for each
// attained run (rows in time order).
// Output: a table on stdout (and -o CSV): per pose AP, RP with their orientation parts;
// per consecutive pose pair (in order of first appearance) AD, RD over the cycles both
// poses have; AT, RT for the path. Lengths in mm, angles in degrees.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "app/commands.h"
#include "calib/iso9283.h"
#include "core/error.h"
#include "core/io.h"
#include "synthetic/iso9283_experiment.h"

namespace mcms::app {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

struct IsoArgs {
  std::string poses, path, output;
  // --simulate: the experiment on the forward model (synthetic/iso9283_experiment.h)
  // instead of measured input.
  bool simulate = false;
  int cycles = 30;
  uint64_t seed = Iso9283ExperimentOptions{}.seed;
  std::string simulate_dir;
};

// The four conditions of the forward-model experiment: tables on stdout, -o the
// characteristics CSV, --write-measurements the attained poses and paths per condition
// (this command's own input layout, so each can be re-evaluated from its file).
int RunIso9283Simulation(const IsoArgs& a) {
  if (!a.poses.empty() || !a.path.empty())
    Throw("iso9283 --simulate: makes its own measurements; give no POSES file and no --path");
  if (!a.output.empty()) RequireWritableFile(a.output, "iso9283 -o");
  if (!a.simulate_dir.empty()) RequireWritableFolder(a.simulate_dir, "iso9283 --write-measurements");
  Iso9283ExperimentOptions o;
  o.cycles = a.cycles;
  o.seed = a.seed;
  const Iso9283Experiment e = RunIso9283Experiment(o);
  if (!a.output.empty()) WriteIso9283ExperimentCsv(a.output, e);
  if (!a.simulate_dir.empty()) {
    std::filesystem::create_directories(a.simulate_dir);
    for (int k = 0; k < static_cast<int>(e.conditions.size()); ++k) {
      const std::filesystem::path dir = a.simulate_dir;
      WriteIso9283AttainedCsv(dir / ("attained_" + std::to_string(k + 1) + ".csv"), e, k);
      WriteIso9283PathCsv(dir / ("path_" + std::to_string(k + 1) + ".csv"), e, k);
    }
  }
  std::fputs(FormatIso9283Experiment(e).c_str(), stdout);
  return 0;
}

struct PoseRows {
  Pose commanded;
  std::map<std::string, Pose> by_cycle;
  std::vector<std::string> cycles;  // in file order
};

Pose RowPose(const CsvTable& t, size_t row, const std::string& prefix) {
  const double qw = t.Number(row, t.Column(prefix + "qw")), qx = t.Number(row, t.Column(prefix + "qx")),
               qy = t.Number(row, t.Column(prefix + "qy")), qz = t.Number(row, t.Column(prefix + "qz"));
  const Eigen::Quaterniond q(qw, qx, qy, qz);
  if (std::abs(q.norm() - 1.0) > 1e-3)
    Throw(t.source.string(), " line ", t.line_of_row[row], ": quaternion ", prefix, "qw..qz has norm ", q.norm(),
          ", expected 1");
  return Pose::FromQuaternion(q.normalized(), Vec3(t.Number(row, t.Column(prefix + "x_m")),
                                                   t.Number(row, t.Column(prefix + "y_m")),
                                                   t.Number(row, t.Column(prefix + "z_m"))));
}

int RunIso9283(const IsoArgs& a) {
  if (a.simulate) return RunIso9283Simulation(a);
  if (a.poses.empty()) Throw("iso9283: POSES (a pose CSV) is required, or --simulate");
  const CsvTable t = ReadCsv(a.poses);
  const int c_pose = t.Column("pose"), c_cycle = t.Column("cycle");
  std::map<std::string, PoseRows> poses;
  std::vector<std::string> order;
  for (size_t i = 0; i < t.rows.size(); ++i) {
    const std::string id = t.rows[i][c_pose], cycle = t.rows[i][c_cycle];
    const Pose cmd = RowPose(t, i, "cmd_");
    const Pose att = RowPose(t, i, "");
    auto [it, fresh] = poses.try_emplace(id);
    if (fresh) {
      order.push_back(id);
      it->second.commanded = cmd;
    } else if ((it->second.commanded.t - cmd.t).norm() > 1e-9 || RotationAngle(it->second.commanded.R, cmd.R) > 1e-9) {
      Throw(a.poses, " line ", t.line_of_row[i], ": pose '", id, "' has a different commanded pose than on its first row");
    }
    if (!it->second.by_cycle.emplace(cycle, att).second)
      Throw(a.poses, " line ", t.line_of_row[i], ": pose '", id, "' cycle '", cycle, "' appears twice");
    it->second.cycles.push_back(cycle);
  }
  if (poses.empty()) Throw(a.poses, ": no rows; expected one row per attained pose");

  std::ostringstream out, csv;
  char buf[512];
  csv << "kind,name,n,AP_mm,AP_x_mm,AP_y_mm,AP_z_mm,AP_a_deg,AP_b_deg,AP_c_deg,RP_mm,RP_a_deg,RP_b_deg,RP_c_deg,"
         "AD_mm,RD_mm,AT_mm,RT_mm\n";
  out << "ISO 9283 pose accuracy (AP) and repeatability (RP); mm and deg\n";
  out << "pose        n    AP_mm   AP_x    AP_y    AP_z    AP_a_deg  AP_b_deg  AP_c_deg   RP_mm  RP_a_deg  RP_b_deg  RP_c_deg\n";
  for (const auto& id : order) {
    const PoseRows& p = poses.at(id);
    std::vector<Pose> att;
    for (const auto& c : p.cycles) att.push_back(p.by_cycle.at(c));
    if (att.size() < 2) Throw(a.poses, ": pose '", id, "' has ", att.size(), " cycle; at least 2 are needed (ISO 9283 uses 30)");
    const PoseCharacteristics c = PoseAccuracyRepeatability(p.commanded, att);
    std::snprintf(buf, sizeof buf, "%-10s %3d %8.4f %7.4f %7.4f %7.4f %9.5f %9.5f %9.5f %8.4f %9.5f %9.5f %9.5f\n",
                  id.c_str(), c.n, c.AP_p * 1e3, c.AP_xyz.x() * 1e3, c.AP_xyz.y() * 1e3, c.AP_xyz.z() * 1e3,
                  c.AP_a / kDeg, c.AP_b / kDeg, c.AP_c / kDeg, c.RP_l * 1e3, c.RP_a / kDeg, c.RP_b / kDeg,
                  c.RP_c / kDeg);
    out << buf;
    std::snprintf(buf, sizeof buf, "pose,%s,%d,%.6f,%.6f,%.6f,%.6f,%.7f,%.7f,%.7f,%.6f,%.7f,%.7f,%.7f,,,,\n", id.c_str(),
                  c.n, c.AP_p * 1e3, c.AP_xyz.x() * 1e3, c.AP_xyz.y() * 1e3, c.AP_xyz.z() * 1e3, c.AP_a / kDeg,
                  c.AP_b / kDeg, c.AP_c / kDeg, c.RP_l * 1e3, c.RP_a / kDeg, c.RP_b / kDeg, c.RP_c / kDeg);
    csv << buf;
  }
  if (order.size() >= 2) {
    out << "\nISO 9283 distance accuracy (AD) and repeatability (RD) between consecutive poses; mm\n";
    out << "pair             n   D_c_mm      AD_mm    RD_mm\n";
    for (size_t k = 0; k + 1 < order.size(); ++k) {
      const PoseRows &p1 = poses.at(order[k]), &p2 = poses.at(order[k + 1]);
      std::vector<Pose> a1, a2;
      for (const auto& c : p1.cycles)
        if (p2.by_cycle.count(c)) {
          a1.push_back(p1.by_cycle.at(c));
          a2.push_back(p2.by_cycle.at(c));
        }
      if (a1.size() < 2) {
        out << order[k] << "-" << order[k + 1] << ": fewer than 2 common cycles, skipped\n";
        continue;
      }
      const DistanceCharacteristics d = DistanceAccuracyRepeatability(p1.commanded, p2.commanded, a1, a2);
      const std::string name = order[k] + "-" + order[k + 1];
      std::snprintf(buf, sizeof buf, "%-14s %3d %10.3f %8.4f %8.4f\n", name.c_str(), d.n, d.D_c * 1e3, d.AD_p * 1e3,
                    d.RD_p * 1e3);
      out << buf;
      std::snprintf(buf, sizeof buf, "distance,%s,%d,,,,,,,,,,,,,%.6f,%.6f,,\n", name.c_str(), d.n, d.AD_p * 1e3,
                    d.RD_p * 1e3);
      csv << buf;
    }
  }
  if (!a.path.empty()) {
    const CsvTable pt = ReadCsv(a.path);
    const int c_run = pt.Column("run"), cx = pt.Column("x_m"), cy = pt.Column("y_m"), cz = pt.Column("z_m");
    std::vector<Vec3> cmd;
    std::map<std::string, std::vector<Vec3>> runs;
    std::vector<std::string> run_order;
    for (size_t i = 0; i < pt.rows.size(); ++i) {
      const Vec3 p(pt.Number(i, cx), pt.Number(i, cy), pt.Number(i, cz));
      const std::string run = pt.rows[i][c_run];
      if (run == "commanded") {
        cmd.push_back(p);
      } else {
        if (!runs.count(run)) run_order.push_back(run);
        runs[run].push_back(p);
      }
    }
    if (cmd.empty()) Throw(a.path, ": no rows with run = commanded; the commanded path is needed");
    std::vector<std::vector<Vec3>> attained;
    for (const auto& r : run_order) attained.push_back(runs[r]);
    const PathCharacteristics pc = PathAccuracyRepeatability(cmd, attained);
    std::snprintf(buf, sizeof buf, "\nISO 9283 path: %zu runs, %zu calculation points: AT %.4f mm, RT %.4f mm\n",
                  attained.size(), cmd.size(), pc.AT_p * 1e3, pc.RT_p * 1e3);
    out << buf;
    std::snprintf(buf, sizeof buf, "path,path,%zu,,,,,,,,,,,,,,,%.6f,%.6f\n", attained.size(), pc.AT_p * 1e3,
                  pc.RT_p * 1e3);
    csv << buf;
  }
  if (!a.output.empty()) {
    const std::string text = csv.str();
    WriteFileAtomically(a.output, [&](std::ostream& o) { o << text; });
  }
  std::fputs(out.str().c_str(), stdout);
  return 0;
}

const McmsCommand kIso9283([](CLI::App& app) {
  auto args = std::make_shared<IsoArgs>();
  CLI::App* sub = app.add_subcommand("iso9283", "ISO 9283 pose, distance and path accuracy and repeatability");
  sub->description(
      "ISO 9283 accuracy and repeatability from repeated measurements of commanded poses.\n"
      "POSES.csv: header and one row per attained pose:\n"
      "  pose,cycle,cmd_x_m,cmd_y_m,cmd_z_m,cmd_qw,cmd_qx,cmd_qy,cmd_qz,x_m,y_m,z_m,qw,qx,qy,qz\n"
      "  (pose = commanded pose name, cycle = repetition; quaternions w,x,y,z; metres).\n"
      "Reports per pose AP, RP (with AP_a/b/c, RP_a/b/c: rotation deviations about x, y, z), per\n"
      "consecutive pose pair AD, RD (cycles matched by name), and with --path AT, RT from a CSV\n"
      "run,x_m,y_m,z_m where run = commanded marks the commanded path (calculation points).\n"
      "Table on stdout (mm, deg); -o writes it as CSV.\n"
      "--simulate: no input; runs the experiment on the forward model (KR 5 arc with DH, base, tool and gear\n"
      "errors, the 4-camera rig, the inclinometer) before and after calibration and before and after a\n"
      "camera-only and a MOIFA correction, and prints the four conditions' tables.");
  sub->add_option("POSES", args->poses, "Pose CSV (required unless --simulate)")->check(CLI::ExistingFile);
  sub->add_flag("--simulate", args->simulate, "Run the forward-model experiment instead of reading POSES");
  sub->add_option("--cycles", args->cycles, "--simulate: cycles P1..P5 (ISO 9283: 30; at least 2)");
  sub->add_option("--seed", args->seed, "--simulate: random seed");
  sub->add_option("--write-measurements", args->simulate_dir,
                  "--simulate: folder for attained_<k>.csv and path_<k>.csv per condition k = 1..4")
      ->type_name("DIR");
  sub->add_option("--path", args->path, "Path CSV (run,x_m,y_m,z_m)")->check(CLI::ExistingFile);
  sub->add_option("-o,--output", args->output, "Also write the table as CSV")->type_name("FILE");
  return std::make_pair(sub, Runner([args] { return RunIso9283(*args); }));
});

}  // namespace
}  // namespace mcms::app
