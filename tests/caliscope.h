// caliscope's real 4-camera ChArUco recording (../shared/data/caliscope-4cam) for the
// tests: xy.csv as calibration observations (with each view's frame time), and
// camera_array.toml, caliscope's own intrinsics and extrinsics.
#pragma once

#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "calib/camera_calibration.h"
#include "core/io.h"

namespace mcms::test {

// One [cameras.N] section of camera_array.toml (its lines as Python/TOML literals).
struct CaliscopeCamera {
  std::vector<double> matrix, distortions, translation, rotation;  // rotation: R of T_cam_world, row-major
  // caliscope stores R, t of world -> camera (OpenCV's rvec/tvec sense): T_cam_world.
  Pose T_cam_world() const {
    Pose T;
    for (int i = 0; i < 9; ++i) T.R(i / 3, i % 3) = rotation[i];
    T.t = Vec3(translation[0], translation[1], translation[2]);
    return T;
  }
  // fx fy cx cy k1 k2 p1 p2 k3: mrcal's LENSMODEL_OPENCV5 intrinsics.
  std::vector<double> Opencv5Intrinsics() const {
    std::vector<double> v = {matrix[0], matrix[4], matrix[2], matrix[5]};
    v.insert(v.end(), distortions.begin(), distortions.end());
    return v;
  }
};

inline std::map<int, CaliscopeCamera> ReadCaliscopeToml(const std::filesystem::path& p) {
  std::map<int, CaliscopeCamera> out;
  std::ifstream f(p);
  std::string line;
  int cam = -1;
  auto numbers = [](const std::string& s) {
    std::vector<double> v;
    std::string t;
    for (char ch : s) t += (std::isdigit(static_cast<unsigned char>(ch)) || ch == '.' || ch == '-' || ch == 'e') ? ch : ' ';
    std::istringstream is(t);
    double x;
    while (is >> x) v.push_back(x);
    return v;
  };
  while (std::getline(f, line)) {
    if (line.rfind("[cameras.", 0) == 0) cam = std::stoi(line.substr(9));
    const auto eq = line.find('=');
    if (cam < 0 || eq == std::string::npos) continue;
    const std::string key = line.substr(0, line.find(' '));
    const std::string val = line.substr(eq + 1);
    if (key == "matrix") out[cam].matrix = numbers(val);
    if (key == "distortions") out[cam].distortions = numbers(val);
    if (key == "translation") out[cam].translation = numbers(val);
    if (key == "rotation") out[cam].rotation = numbers(val);
  }
  return out;
}

// xy.csv: one observation per (sync index, camera), frame = sync index, the board's
// corners (keypoint ids 0..11, board z = 0) in the views' order; *frame_time_s (optional)
// receives each observation's frame_time (seconds, the recording's clock).
inline CameraCalibrationInput ReadCaliscopeViews(const std::filesystem::path& dir,
                                                 std::vector<double>* frame_time_s = nullptr) {
  const CsvTable t = ReadCsv(dir / "xy.csv");
  const int c_sync = t.Column("sync_index"), c_cam = t.Column("cam_id"), c_x = t.Column("img_loc_x"),
            c_y = t.Column("img_loc_y"), c_ox = t.Column("obj_loc_x"), c_oy = t.Column("obj_loc_y"),
            c_t = t.Column("frame_time");
  std::map<std::pair<int, int>, BoardObservation> by;
  std::map<std::pair<int, int>, double> time;
  for (size_t r = 0; r < t.rows.size(); ++r) {
    const int sync = static_cast<int>(t.Number(r, c_sync)), cam = static_cast<int>(t.Number(r, c_cam));
    auto& o = by[{sync, cam}];
    o.camera = cam;
    o.frame = sync;
    o.pixels.emplace_back(t.Number(r, c_x), t.Number(r, c_y));
    o.points_board.emplace_back(t.Number(r, c_ox), t.Number(r, c_oy), 0.0);
    time[{sync, cam}] = t.Number(r, c_t);
  }
  CameraCalibrationInput in;
  for (int c = 0; c < 4; ++c) {
    in.camera_names.push_back("cam" + std::to_string(c));
    in.widths.push_back(1280);
    in.heights.push_back(720);
  }
  if (frame_time_s) frame_time_s->clear();
  for (auto& [k, o] : by) {
    in.observations.push_back(o);
    if (frame_time_s) frame_time_s->push_back(time[k]);
  }
  return in;
}

}  // namespace mcms::test
