#include "synthetic/camera_error_model.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <system_error>

#include <Eigen/Eigenvalues>
#include <yaml-cpp/yaml.h>

#include "core/error.h"
#include "core/io.h"
#include "core/yaml.h"

namespace mcms {

Vec3 CameraErrorModel::VisitSigma() const {
  return (Vec3::Constant(floor_m * floor_m) + anisotropy_m.cwiseAbs2()).cwiseSqrt();
}

Mat3 CameraErrorModel::VisitCovariance() const { return Mat3(VisitSigma().cwiseAbs2().asDiagonal()); }

Vec3 CameraErrorModel::DrawVisit(Rng* rng) const {
  const Vec3 s = VisitSigma();
  Vec3 d;
  for (int a = 0; a < 3; ++a) d[a] = rng->Normal() * s[a];
  return d;
}

Vec6 DrawNormal(const Mat6& C, Rng* rng) {
  Eigen::SelfAdjointEigenSolver<Mat6> es(C);
  Vec6 z;
  for (int i = 0; i < 6; ++i) z[i] = rng->Normal() * std::sqrt(std::max(0.0, es.eigenvalues()[i]));
  return es.eigenvectors() * z;
}

void CameraErrorModel::ScalePixelNoise(Pose* T, Mat6* cov, Rng* rng) const {
  const double k2 = pixel_noise_scale * pixel_noise_scale;
  if (k2 > 1) *T = BoxPlus(*T, DrawNormal((k2 - 1) * *cov, rng));
  *cov *= k2;
}

void CameraErrorModel::AddVisitCovariance(Mat6* cov, int frames_of_visit) const {
  cov->bottomRightCorner<3, 3>() += VisitCovariance() * std::max(1, frames_of_visit);
}

std::string CameraErrorModel::Describe() const {
  const Vec3 s = VisitSigma();
  char buf[256];
  std::snprintf(buf, sizeof buf, "pixel noise x%.2f, per-visit rigid error sigma x %.3f y %.3f z %.3f mm", pixel_noise_scale,
                1e3 * s.x(), 1e3 * s.y(), 1e3 * s.z());
  return name + ": " + buf + " (" + source + ")";
}

bool CameraErrorModel::IsValid(std::string* why) const {
  const auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (!(pixel_noise_scale >= 1) || !std::isfinite(pixel_noise_scale))
    return fail("pixel_noise_scale must be a finite number >= 1 (the rendered images already carry the nominal noise), got " +
                std::to_string(pixel_noise_scale));
  if (pixel_noise_scale > kMaxPixelNoiseScale)
    return fail("pixel_noise_scale " + std::to_string(pixel_noise_scale) + " is beyond the plausible 1 to " +
                std::to_string(static_cast<int>(kMaxPixelNoiseScale)));
  if (!(floor_m >= 0) || !std::isfinite(floor_m)) return fail("floor_m must be a finite number >= 0");
  if (floor_m > kMaxVisitSigmaM)
    return fail("floor_m " + std::to_string(floor_m) + " m is beyond the plausible 0 to 0.1 m");
  if (!anisotropy_m.allFinite()) return fail("anisotropy_m must be finite");
  if (anisotropy_m.cwiseAbs().maxCoeff() > kMaxVisitSigmaM)
    return fail("anisotropy_m is beyond the plausible 0 to 0.1 m per axis");
  return true;
}

CameraErrorModel PaperCameraErrorModel() {
  // mcms fov-map --measured ../shared/data/paper/table1_point_repeatability.csv
  //   --lines ../shared/data/paper/table2_line_lengths.csv --json fit.json -o DIR
  // selects misidentification + anisotropy_y + anisotropy_z + pixel_noise_scale (no floor);
  // test_jobs_camera_error_model refits and compares.
  CameraErrorModel m;
  m.name = "paper";
  m.source = "fitted by `mcms fov-map --measured` to the paper's Table 1 (assumed layout)";
  m.pixel_noise_scale = 11.0824148;
  m.floor_m = 0;
  m.anisotropy_m = Vec3(0, 0.000983296934, 0.000248179961);
  return m;
}

namespace {

double Parameter(const YAML::Node& effect, const std::string& effect_name, const std::string& key,
                 const std::string& file, double lo, double hi, const char* unit) {
  const YAML::Node p = effect["parameters"];
  if (!p || !p.IsMap() || !p[key])
    Throw("--camera-model ", file, ": effect \"", effect_name, "\" has no parameters.", key,
          " (expected the JSON that `mcms fov-map --measured --json` writes)");
  double v = 0;
  try {
    v = p[key].as<double>();
  } catch (const YAML::Exception&) {
    Throw("--camera-model ", file, ": effect \"", effect_name, "\" parameters.", key, " is not a number");
  }
  if (!std::isfinite(v) || v < 0)
    Throw("--camera-model ", file, ": effect \"", effect_name, "\" parameters.", key, " = ", v,
          ", expected a finite number >= 0");
  if (v < lo || v > hi)
    Throw("--camera-model ", file, ": effect \"", effect_name, "\" parameters.", key, " = ", v, unit,
          " is not plausible; expected ", lo, " to ", hi, unit,
          " (a per-visit error beyond 0.1 m moves the target out of the rig's view; a pixel noise beyond ",
          kMaxPixelNoiseScale, " times the nominal drowns the balls)");
  return v;
}

}  // namespace

CameraErrorModel ReadCameraErrorModel(const std::string& spec) {
  if (spec == "ideal") return CameraErrorModel{};
  if (spec == "paper") return PaperCameraErrorModel();
  std::error_code ec;
  if (spec.empty() || !std::filesystem::is_regular_file(spec, ec))
    Throw("--camera-model \"", spec,
          "\": expected ideal, paper, or the JSON file that `mcms fov-map --measured --json FILE` writes (no such file)");
  YAML::Node root;
  try {
    root = LoadYaml(ReadTextFile(spec), "--camera-model " + spec);
  } catch (const YAML::Exception& e) {
    Throw("--camera-model ", spec, ": not valid JSON (", e.what(), ")");
  }
  // The keys `mcms fov-map --measured --json` writes; another command's JSON (an audit
  // report with "mode", ...) is not a camera model even when it holds an "effects" list.
  static const std::vector<std::string> kKeys = {"source",
                                                 "layout",
                                                 "effects",
                                                 "heldout_loglik_gain",
                                                 "heldout_loglik_gain_vs_isotropic",
                                                 "loglik",
                                                 "outlier_points",
                                                 "layout_sensitivity",
                                                 "lab_prediction",
                                                 "table2_prediction",
                                                 "table2_alternatives"};
  if (root.IsMap())
    for (const auto& kv : root) {
      const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : std::string("(not a name)");
      if (std::find(kKeys.begin(), kKeys.end(), key) == kKeys.end()) {
        std::string expected;
        for (const auto& k : kKeys) expected += (expected.empty() ? "" : ", ") + k;
        Throw("--camera-model ", spec, ": key \"", key.substr(0, 60), "\" is not one of the JSON that `mcms fov-map ",
              "--measured --json` writes (",
              root["mode"] && root["mode"].IsScalar()
                  ? "this looks like the report of `mcms audit " + root["mode"].Scalar() + "`; "
                  : std::string(),
              "expected the keys ", expected, ", with \"effects\" a list of {name, parameters})");
      }
    }
  const YAML::Node effects = root.IsMap() ? root["effects"] : YAML::Node();
  if (!effects || !effects.IsSequence())
    Throw("--camera-model ", spec,
          ": no \"effects\" list (expected the JSON that `mcms fov-map --measured --json` writes)");
  CameraErrorModel m;
  m.name = spec;
  m.source = "the fit in " + spec;
  for (const YAML::Node& e : effects) {
    if (!e.IsMap() || !e["name"] || !e["name"].IsScalar())
      Throw("--camera-model ", spec, ": an entry of \"effects\" has no \"name\"");
    const std::string n = e["name"].as<std::string>();
    if (n == "pixel_noise_scale")
      m.pixel_noise_scale = Parameter(e, n, "scale", spec, 0, kMaxPixelNoiseScale, "");
    else if (n == "noise_floor")
      m.floor_m = Parameter(e, n, "floor_m", spec, 0, kMaxVisitSigmaM, " m");
    else if (n == "anisotropy_x")
      m.anisotropy_m.x() = Parameter(e, n, "sigma_x_m", spec, 0, kMaxVisitSigmaM, " m");
    else if (n == "anisotropy_y")
      m.anisotropy_m.y() = Parameter(e, n, "sigma_y_m", spec, 0, kMaxVisitSigmaM, " m");
    else if (n == "anisotropy_z")
      m.anisotropy_m.z() = Parameter(e, n, "sigma_z_m", spec, 0, kMaxVisitSigmaM, " m");
    else if (n == "misidentification") continue;  // not simulated (see the header)
    else
      Throw("--camera-model ", spec, ": unknown effect \"", n,
            "\" (expected pixel_noise_scale, noise_floor, anisotropy_x|y|z, misidentification)");
  }
  std::string why;
  if (!m.IsValid(&why)) Throw("--camera-model ", spec, ": ", why);
  return m;
}

}  // namespace mcms
