#include "audit/robot_audit.h"

#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>

#include "audit/robot_audit.h"
#include "audit/tilt_sensor_audit.h"
#include "audit/robot_audit_problem.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "core/svg_plot.h"
#include "model/urdf.h"

namespace mcms {

using robot_audit::PositionRms;

void WriteNextPoses(const std::filesystem::path& path, const RobotAuditResult& result, const RobotModel& robot) {
  WriteFileAtomically(path, [&](std::ostream& os) {
    os << "pair";
    const auto& act = robot.ActuatedJoints();
    for (int j = 0; j < robot.NumActuated(); ++j) {
      const char* unit = act[j].type == JointType::kRevolute ? "_rad" : "_m";
      if (robot.HasMimicJoints())
        os << "," << act[j].name << unit;
      else
        os << ",q" << j + 1 << unit;
    }
    os << ",x_a_m,y_a_m,z_a_m,x_b_m,y_b_m,z_b_m,difference_mm,separation_sigma,readings_each\n";
    char b[64];
    for (const auto& np : result.next_poses)
      for (const auto& p : np.poses) {
        os << '"' << np.a << " | " << np.b << '"';
        const Eigen::VectorXd qa = robot.ActuatedValues(p.q);
        for (int j = 0; j < qa.size(); ++j) {
          std::snprintf(b, sizeof b, ",%.9g", qa[j]);
          os << b;
        }
        for (const Vec3* v : {&p.p_meas_a, &p.p_meas_b})
          for (int k = 0; k < 3; ++k) {
            std::snprintf(b, sizeof b, ",%.9g", (*v)[k]);
            os << b;
          }
        std::snprintf(b, sizeof b, ",%.6f,%.3f,%d\n", (p.p_meas_a - p.p_meas_b).norm() * 1e3, p.separation_sigma,
                      np.readings);
        os << b;
      }
  });
}


std::string RobotAuditText(const RobotAuditResult& r, const RobotLog& log, const RobotModel& robot,
                           const std::vector<TiltSensorAuditResult>& tilt) {
  std::ostringstream text;
  text << "robot log " << log.source.string() << ": " << log.rows.size() << " measurements ("
       << (log.NumPoints() >= 3 ? std::to_string(log.NumPoints()) + " points of a rigid body: its pose"
                                : log.six_dof() ? std::string("6-D")
                                                : std::string("3-D"))
       << "), robot '" << robot.Name() << "'";
  if (const UrdfSource* u = robot.Urdf()) text << " (URDF chain " << u->base_link << " -> " << u->tip_link << ", " << robot.NumJoints() << " joints)";
  text << "\n";
  if (!log.ignored_columns.empty()) {
    text << "columns not used:";
    for (const auto& c : log.ignored_columns) text << " " << c;
    text << "\n";
  }
  const Eigen::MatrixXd& S = r.nominal.noise;
  char buf[768];
  std::snprintf(buf, sizeof buf,
                "nominal model: position residual RMS %.4f mm; noise sigma x y z %.4f %.4f %.4f mm (fitted)\n",
                PositionRms(r.nominal.residuals) * 1e3, std::sqrt(S(0, 0)) * 1e3, std::sqrt(S(1, 1)) * 1e3,
                std::sqrt(S(2, 2)) * 1e3);
  text << buf;
  text << r.report.Text();
  std::snprintf(buf, sizeof buf, "extended model: position residual RMS %.4f mm\n",
                PositionRms(r.extended.residuals) * 1e3);
  text << buf;
  text << TiltSensorAuditText(tilt, robot);
  for (const auto& np : r.next_poses)
    if (!np.poses.empty()) {
      if (np.readings > 0)
        std::snprintf(buf, sizeof buf,
                      "to tell [%s] from [%s]: measure each of the %zu poses of next_poses.csv (-o) %d times; "
                      "with the registration, the tool and every other parameter refitted they then separate the "
                      "two by a noncentrality of %.1f (%.1f needed to decide at the selection's tie band with 90 %% "
                      "power; the logged rows alone: %.1f)\n",
                      np.a.c_str(), np.b.c_str(), np.poses.size(), np.readings, np.noncentrality,
                      np.noncentrality_needed, np.noncentrality_logged);
      else
        std::snprintf(buf, sizeof buf,
                      "to tell [%s] from [%s]: the best %zu poses found (next_poses.csv, -o) would not decide within "
                      "1000 readings each once the registration, the tool and every other parameter are refitted "
                      "(noncentrality %.1f of %.1f needed): the two are not separable by poses within the joint "
                      "limits\n",
                      np.a.c_str(), np.b.c_str(), np.poses.size(), np.noncentrality, np.noncentrality_needed);
      text << buf;
    }
  return text.str();
}

void WriteRobotAuditJson(const std::filesystem::path& path, const RobotAuditResult& r,
                         const std::vector<TiltSensorAuditResult>& tilt) {
  if (tilt.empty()) return r.report.WriteJson(path);
  nlohmann::json j = nlohmann::json::parse(r.report.ToJson());
  j["tilt_sensors"] = TiltSensorAuditJson(tilt);
  WriteFileAtomically(path, [&](std::ostream& os) { os << j.dump(2) << "\n"; });
}

void WriteRobotAuditFolder(const std::filesystem::path& dir, const RobotAuditResult& r, const RobotLog& log,
                           const RobotModel& robot, const std::vector<TiltSensorAuditResult>& tilt,
                           const std::string& report) {
  WriteFileAtomically(dir / "report.txt", [&](std::ostream& os) { os << report; });
  r.extended_robot.Write(dir / "robot.yaml");
  if (robot.Urdf()) {
    // The geometry (error motion has no place in a URDF; robot.yaml holds it).
    std::vector<Joint> joints = r.extended_robot.Joints();
    for (Joint& j : joints) j.error_motion_sin.clear(), j.error_motion_cos.clear();
    WriteUrdf(dir / "robot.urdf", r.extended_robot.WithJoints(joints));
  }
  if (!r.report.validation.empty())
    WriteFileAtomically(dir / "validation.csv", [&](std::ostream& os) {
      os << "log,row,group,model,point,dx_mm,dy_mm,dz_mm,distance_mm\n";
      char b[320];
      for (const SessionScore& sc : r.report.validation)
        for (const ModelScore& m : sc.models)
          for (size_t i = 0; i < m.errors.size(); ++i)
            for (size_t k = 0; k < m.errors[i].size(); ++k) {
              const Vec3& e = m.errors[i][k];
              std::snprintf(b, sizeof b, "%s,%zu,%s,%s,%zu,%.6f,%.6f,%.6f,%.6f\n",
                            CsvQuoted(sc.log).c_str(), i + 1, Name(sc.group_of_row[i]),
                            m.model.c_str(), k + 1, e.x() * 1e3, e.y() * 1e3, e.z() * 1e3,
                            e.norm() * 1e3);
              os << b;
            }
    });
  WriteFileAtomically(dir / "residuals.csv", [&](std::ostream& os) {
    os << "time_s,nominal_dx_mm,nominal_dy_mm,nominal_dz_mm,extended_dx_mm,extended_dy_mm,"
          "extended_dz_mm\n";
    char b[256];
    for (size_t i = 0; i < log.rows.size(); ++i) {
      std::snprintf(b, sizeof b, "%.9g,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f\n", log.rows[i].time_s,
                    r.nominal.residuals(i, 0) * 1e3, r.nominal.residuals(i, 1) * 1e3,
                    r.nominal.residuals(i, 2) * 1e3, r.extended.residuals(i, 0) * 1e3,
                    r.extended.residuals(i, 1) * 1e3, r.extended.residuals(i, 2) * 1e3);
      os << b;
    }
  });
  std::filesystem::create_directories(dir / "plots");
  int k = 0;
  for (const auto& pl : r.plots) {
    Plot p;
    p.title = pl.effect + ": residual of the model without it, along its direction";
    p.x_label = pl.covariate;
    p.y_label = "mm";
    PlotSeries a{"residual without the effect", pl.x, pl.residual_before, "#1f77b4", true};
    PlotSeries b{"the fitted effect", pl.x, pl.effect_size, "#d62728", true};
    for (auto& v : a.y) v *= 1e3;
    for (auto& v : b.y) v *= 1e3;
    p.series = {a, b};
    p.WriteSvg(dir / "plots" / ("effect" + std::to_string(++k) + ".svg"));
  }
  k = 0;
  const char* colors[] = {"#7f7f7f", "#d62728", "#1f77b4", "#2ca02c"};
  for (const auto& vp : r.validation_plots) {
    Plot p;
    p.title = vp.title;
    p.x_label = vp.covariate;
    p.y_label = "mm";
    for (size_t s = 0; s < vp.series.size(); ++s)
      p.series.push_back(
          {vp.series[s].first, vp.x, vp.series[s].second, colors[s % 4], true});
    p.WriteSvg(dir / "plots" / ("validation" + std::to_string(++k) + ".svg"));
  }
  if (!r.next_poses.empty()) WriteNextPoses(dir / "next_poses.csv", r, robot);
  if (!tilt.empty()) WriteTiltSensorResiduals(dir / "tilt_residuals.csv", tilt);
  WriteRobotAuditJson(dir / "report.json", r, tilt);
}

}  // namespace mcms
