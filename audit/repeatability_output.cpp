// The files of the measured-repeatability analysis (audit/repeatability.h): the report
// folder (WriteMeasuredReport) and its JSON (WriteMeasuredJson).
#include "audit/repeatability.h"

#include <numbers>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "core/error.h"
#include "core/nelder_mead.h"
#include "core/limits.h"
#include "core/io.h"
#include "core/statistics.h"
#include "core/svg_plot.h"

namespace mcms {

namespace fs = std::filesystem;

void WriteMeasuredReport(const MeasuredReport& R, const fs::path& dir) {
  fs::create_directories(dir);
  auto f = [](double v) {
    char b[32];
    std::snprintf(b, sizeof(b), "%.6g", v);
    return std::string(std::isfinite(v) ? b : "");
  };
  WriteFileAtomically(dir / "measured.csv", [&](std::ostream& o) {
    o << "plane,point,x_m,y_m,z_m,repeats,sigma_x_mm,sigma_y_mm,sigma_z_mm,sigma_d_mm,nominal_sigma_x_mm,nominal_sigma_y_mm,"
         "nominal_sigma_z_mm,nominal_trackable,fit_sigma_x_mm,fit_sigma_y_mm,fit_sigma_z_mm,outlier_probability,"
         "heldout_loglik_extended,heldout_loglik_nominal,err_x_mm,err_y_mm,err_z_mm,nominal_border_px\n";
    for (size_t i = 0; i < R.measured.points.size(); ++i) {
      const auto& p = R.measured.points[i];
      const Vec3 ms = p.variance.cwiseSqrt() * 1e3, ns = R.data.nominal[i].cwiseSqrt() * 1e3,
                 fs = R.fit.InlierVariance(R.data.nominal[i]).cwiseSqrt() * 1e3;
      o << p.plane << "," << p.id << "," << f(R.positions_rig[i].x()) << "," << f(R.positions_rig[i].y()) << ","
        << f(R.positions_rig[i].z()) << "," << p.repeats << "," << f(ms.x()) << "," << f(ms.y()) << "," << f(ms.z()) << ","
        << f(ms.norm()) << "," << f(ns.x()) << "," << f(ns.y()) << "," << f(ns.z()) << "," << (R.nominal_trackable[i] ? 1 : 0)
        << "," << f(fs.x()) << "," << f(fs.y()) << "," << f(fs.z()) << ","
        << f(R.fit.outlier_posterior.empty() ? 0.0 : R.fit.outlier_posterior[i]) << "," << f(R.heldout_extended[i]) << ","
        << f(R.heldout_nominal[i]);
      if (p.reference && p.mean_rig) {
        const Vec3 e = (*p.mean_rig - *p.reference) * 1e3;
        o << "," << f(e.x()) << "," << f(e.y()) << "," << f(e.z());
      } else {
        o << ",,,";
      }
      o << "," << f(R.nominal_border_px[i]) << "\n";
    }
  });
  WriteFileAtomically(dir / "measured_fit.txt", [&](std::ostream& o) { o << R.text; });
  Plot p;
  p.title = "Measured repeatability against the nominal and the fitted model";
  p.x_label = "point (input order)";
  p.y_label = "sigma_d (mm)";
  p.log_y = true;
  PlotSeries meas{"measured", {}, {}, "#d62728", true}, nomi{"nominal model", {}, {}, "#1f77b4", false},
      fit{"extended model (inliers)", {}, {}, "#2ca02c", false};
  for (size_t i = 0; i < R.measured.points.size(); ++i) {
    meas.x.push_back(i), meas.y.push_back(std::sqrt(R.measured.points[i].variance.sum()) * 1e3);
    nomi.x.push_back(i), nomi.y.push_back(std::sqrt(R.data.nominal[i].sum()) * 1e3);
    fit.x.push_back(i), fit.y.push_back(std::sqrt(R.fit.InlierVariance(R.data.nominal[i]).sum()) * 1e3);
  }
  p.series = {meas, nomi, fit};
  p.WriteSvg(dir / "measured_sigma.svg");
  if (R.table2.lines.empty()) return;
  WriteFileAtomically(dir / "lines.csv", [&](std::ostream& o) {
    o << "plane,line,d_reference_mm,d_measured_mm,delta_mm,direction_x,direction_y,direction_z,predicted_sd_mm,z,"
         "outlier_probability\n";
    for (const auto& l : R.table2.lines)
      o << l.line.plane << "," << l.line.id << "," << f(l.line.d_reference_m * 1e3) << "," << f(l.line.d_measured_m * 1e3) << ","
        << f((l.line.d_reference_m - l.line.d_measured_m) * 1e3) << "," << f(l.direction.x()) << "," << f(l.direction.y()) << ","
        << f(l.direction.z()) << "," << f(l.predicted_sd_m * 1e3) << "," << f(l.z) << "," << f(l.outlier_probability) << ","
        << (l.gross ? 1 : 0) << "\n";
  });
}

namespace {
using Json = nlohmann::ordered_json;
// 9 significant digits, as the text report; JSON has no NaN or infinity: null.
Json JsonNum(double v) {
  if (!std::isfinite(v)) return nullptr;
  char b[40];
  std::snprintf(b, sizeof(b), "%.9g", v);
  return std::strtod(b, nullptr);
}

Json Table2Json(const Table2Prediction& t, bool per_line) {
  Json j = {{"variant", t.variant},
            {"lines", t.lines.size()},
            {"inlier_lines", t.inliers},
            {"gross_threshold_mm", JsonNum(t.gross_threshold_m * 1e3)},
            {"measured_mean_abs_delta_mm", JsonNum(t.measured_mean_abs_m * 1e3)},
            {"predicted_mean_abs_delta_mm", JsonNum(t.predicted_mean_abs_m * 1e3)},
            {"predicted_mean_abs_delta_sd_mm", JsonNum(t.predicted_mean_abs_sd_m * 1e3)},
            {"loglik",
             {{"extended", JsonNum(t.loglik_extended)},
              {"nominal", JsonNum(t.loglik_nominal)},
              {"isotropic", JsonNum(t.loglik_isotropic)}}}};
  if (per_line) {
    Json lines = Json::array();
    for (const auto& l : t.lines)
      lines.push_back({{"plane", l.line.plane},
                       {"line", l.line.id},
                       {"delta_mm", JsonNum((l.line.d_reference_m - l.line.d_measured_m) * 1e3)},
                       {"predicted_sd_mm", JsonNum(l.predicted_sd_m * 1e3)},
                       {"outlier_probability", JsonNum(l.outlier_probability)},
                       {"gross", l.gross}});
    j["per_line"] = lines;
  }
  return j;
}
}  // namespace

void WriteMeasuredJson(const MeasuredReport& R, const fs::path& path) {
  // A new top-level key must also join the keys ReadCameraErrorModel accepts
  // (synthetic/camera_error_model.cpp), which refuses other commands' JSON by them.
  Json j;
  j["source"] = R.measured.source.string();
  j["layout"] = R.layout_text;
  // Parameters of each effect, by the effect's name.
  Json effects = Json::array();
  size_t k = 0;
  for (const std::string& name : R.fit.effects) {
    const size_t np = name == "misidentification" ? 2 : 1;
    Json p = Json::object(), sg = Json::object();
    for (size_t q = 0; q < np; ++q) {
      p[R.fit.parameters[k + q].first] = JsonNum(R.fit.parameters[k + q].second);
      sg[R.fit.standard_errors[k + q].first] = JsonNum(R.fit.standard_errors[k + q].second);
    }
    effects.push_back({{"name", name}, {"parameters", p}, {"sigma", sg}});
    k += np;
  }
  j["effects"] = effects;
  j["heldout_loglik_gain"] = JsonNum(R.heldout_gain);
  j["heldout_loglik_gain_vs_isotropic"] = JsonNum(R.heldout_gain_vs_isotropic);
  j["loglik"] = {{"nominal", JsonNum(R.loglik_nominal)},
                 {"isotropic", JsonNum(R.loglik_isotropic)},
                 {"extended", JsonNum(R.fit.loglik)}};
  Json outliers = Json::array();
  for (size_t i = 0; i < R.measured.points.size(); ++i)
    if (!R.fit.outlier_posterior.empty() && R.fit.outlier_posterior[i] > 0.5) outliers.push_back(R.measured.points[i].id);
  j["outlier_points"] = outliers;
  Json sens = Json::array();
  for (const auto& sv : R.sensitivity)
    sens.push_back({{"layout", sv.layout},
                    {"effects", sv.effects},
                    {"heldout_loglik_gain", JsonNum(sv.heldout_gain)},
                    {"parameters", sv.parameters}});
  j["layout_sensitivity"] = sens;
  Json lab = Json::array();
  for (const auto& l : R.lab)
    lab.push_back({{"camera_model", l.camera_model},
                   {"draws", l.seeds},
                   {"camera_3sigma_mm", JsonNum(l.camera_3sigma_m * 1e3)},
                   {"robot_3sigma_mm", JsonNum(l.robot_3sigma_m * 1e3)},
                   {"moifa_3sigma_mm", JsonNum(l.moifa_3sigma_m * 1e3)},
                   {"kf_3sigma_mm", JsonNum(l.kf_3sigma_m * 1e3)},
                   {"moifa_reduction_pct", JsonNum(100 * l.moifa_reduction)},
                   {"moifa_reduction_sd_pct", JsonNum(100 * l.moifa_reduction_sd)},
                   {"kf_reduction_pct", JsonNum(100 * l.kf_reduction)},
                   {"kf_reduction_sd_pct", JsonNum(100 * l.kf_reduction_sd)},
                   {"paper_moifa_reduction_pct", JsonNum(100 * PaperLabResult::moifa_reduction)},
                   {"paper_kf_reduction_pct", JsonNum(100 * PaperLabResult::kf_reduction)}});
  j["lab_prediction"] = lab;
  if (R.table2.lines.empty()) {
    j["table2_prediction"] = nullptr;
  } else {
    j["table2_prediction"] = Table2Json(R.table2, true);
    Json alt = Json::array();
    for (const auto& t : R.table2_variants) alt.push_back(Table2Json(t, false));
    j["table2_alternatives"] = alt;
  }
  const std::string text = j.dump(2) + "\n";
  WriteFileAtomically(path, [&](std::ostream& out) { out << text; });
}

}  // namespace mcms
