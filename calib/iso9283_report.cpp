#include "calib/iso9283_report.h"

#include <numbers>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <vector>

#include "calib/iso9283.h"
#include "core/format.h"
#include "core/pose_math.h"
#include "core/error.h"
#include "core/limits.h"
#include "core/io.h"
#include "core/statistics.h"

namespace mcms {

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

struct PoseRows {
  Pose commanded;
  std::map<std::string, Pose> by_cycle;
  std::vector<std::string> cycles;  // in file order
};

Pose RowPose(const CsvTable& t, size_t row, const std::string& prefix) {
  const double qw = t.Number(row, t.Column(prefix + "qw")), qx = t.Number(row, t.Column(prefix + "qx")),
               qy = t.Number(row, t.Column(prefix + "qy")), qz = t.Number(row, t.Column(prefix + "qz"));
  const Eigen::Quaterniond q(qw, qx, qy, qz);
  if (!IsUnitQuaternion(q))
    Throw(t.source.string(), " line ", t.line_of_row[row], ": quaternion ", prefix, "qw..qz has norm ", q.norm(),
          ", expected 1");
  return Pose::FromQuaternion(q.normalized(), Vec3(t.Number(row, t.Column(prefix + "x_m")),
                                                   t.Number(row, t.Column(prefix + "y_m")),
                                                   t.Number(row, t.Column(prefix + "z_m"))));
}

}  // namespace

Iso9283Report EvaluateIso9283Files(const std::filesystem::path& poses_file, const std::filesystem::path& path_file) {
  const CsvTable t = ReadCsv(poses_file);
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
      Throw(poses_file.string(), " line ", t.line_of_row[i], ": pose '", id, "' has a different commanded pose than on its first row");
    }
    if (!it->second.by_cycle.emplace(cycle, att).second)
      Throw(poses_file.string(), " line ", t.line_of_row[i], ": pose '", id, "' cycle '", cycle, "' appears twice");
    it->second.cycles.push_back(cycle);
  }
  if (poses.empty()) Throw(poses_file.string(), ": no rows; expected one row per attained pose");
  {
    // Attained (or commanded) positions in another unit than metres: the attained ones lie
    // 100s of times as far from the commanded ones' centre as those do (a robot misses its
    // commanded pose by mm, not by 100 times the size of its workspace).
    Vec3 centre = Vec3::Zero();
    for (const auto& id : order) centre += poses.at(id).commanded.t / order.size();
    // Both in another unit (every position column in mm): the commanded poses span more
    // than any robot's working volume; and positions far beyond any measuring range lose
    // the micrometres ISO 9283 reports in double precision.
    double span = 0;
    for (const auto& id : order) {
      const PoseRows& p = poses.at(id);
      span = std::max(span, (p.commanded.t - centre).norm());
      for (const auto& [cycle, a] : p.by_cycle)
        for (const Vec3& x : {p.commanded.t, a.t})
          if (!(x.cwiseAbs().maxCoeff() <= kMaxRigRangeM * 1000))
            Throw(poses_file.string(), ": pose '", id, "' cycle '", cycle, "' has a position ", Num4(x.norm()),
                  " m from the origin, beyond ", Num4(kMaxRigRangeM * 1000),
                  " m; expected metres in the robot's or the instrument's frame");
    }
    if (span > kMaxRigRangeM)
      Throw(poses_file.string(), ": the commanded positions lie up to ", Num4(span),
            " m from their centre, more than any robot reaches (", Num4(kMaxRigRangeM),
            " m): positions in mm under metre headers? expected metres");
    double cmd = 0, att = 0;
    for (const auto& id : order) {
      const PoseRows& p = poses.at(id);
      for (const auto& [cycle, a] : p.by_cycle) cmd += (p.commanded.t - centre).norm(), att += (a.t - centre).norm();
    }
    if (cmd > 0 && att > 0) {
      const double ratio = att / cmd;
      const char* unit = ratio > 100    ? "the attained positions x_m, y_m, z_m in mm?"
                         : ratio < 0.01 ? "the commanded positions cmd_x_m.. in mm?"
                                        : nullptr;
      if (unit)
        Throw(poses_file.string(), ": the attained positions lie ", Num4(ratio > 1 ? ratio : 1 / ratio),
              " times as ", ratio > 1 ? "far from" : "close to", " the commanded poses' centre as the commanded ones: ",
              unit, " expected metres");
    }
    // Attained orientations in another quaternion order: a robot misses its commanded
    // orientation by a fraction of a degree, not by tens of degrees; read scalar-last
    // (x, y, z, w under qw..qz) they would agree.
    std::vector<double> angle, angle_xyzw;
    for (const auto& id : order) {
      const PoseRows& p = poses.at(id);
      for (const auto& [cycle, a] : p.by_cycle) {
        angle.push_back(Eigen::AngleAxisd(p.commanded.R.transpose() * a.R).angle());
        angle_xyzw.push_back(
            Eigen::AngleAxisd(p.commanded.R.transpose() * RotationReadScalarLast(Eigen::Quaterniond(a.R))).angle());
      }
    }
    const double deg = 180 / std::numbers::pi;
    const double median = SelectedMedian(angle) * deg, median_xyzw = SelectedMedian(angle_xyzw) * deg;
    if (median > 10)
      Throw(poses_file.string(), ": the attained orientations differ from the commanded ones by ", Num4(median),
            " deg (median)", median_xyzw < 1 ? ", and by " + Num4(median_xyzw) +
                                                   " deg read scalar-last: quaternions x, y, z, w under qw, qx, qy, qz?"
                                             : std::string("; are the attained poses those of these commanded poses?"),
            " expected qw, qx, qy, qz (scalar first)");
  }

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
    if (att.size() < 2) Throw(poses_file.string(), ": pose '", id, "' has ", att.size(), " cycle; at least 2 are needed (ISO 9283 uses 30)");
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
  if (!path_file.empty()) {
    const CsvTable pt = ReadCsv(path_file);
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
    if (cmd.empty()) Throw(path_file.string(), ": no rows with run = commanded; the commanded path is needed");
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
  return {out.str(), csv.str()};
}

}  // namespace mcms
