// A synthetic scenario: the rig, the target, its motion, the image formation and
// the seed, from one YAML file (JSON parses too: yaml-cpp reads JSON).
//
// File format (all lengths in metres, angles as named; relative paths are relative
// to the scenario file). `mcms render --print-default` prints a complete example.
//
//   seed: 1                        # unsigned 64-bit; optional, default 1
//   rig:                           # one of three forms:
//     # (a) a rig file:            rig: my_rig.yaml   (CameraRig::Read format)
//     # (b) inline, as a rig file: rig: {cameras: [{name, lensmodel, intrinsics,
//     #                                  imagersize, rt_cam_rig} or {name, model: file}]}
//     # (c) a generator: cameras looking at one point, sharing one lens:
//     type: look_at                # or ring
//     lensmodel: LENSMODEL_OPENCV8
//     intrinsics: [fx, fy, cx, cy, k1, ...]
//     imagersize: [1280, 1024]
//     look_at_m: [0, 0, 0.5]       # every camera's optical axis passes through it
//     up: [0, 0, 1]                # rig direction that points "up" in the images (-y); default +z
//     positions_m: [[0.8, 0.7, 2.2], ...]     # look_at: the camera centres
//     # ring: count, radius_m, height_m, start_deg (azimuth of camera 0 about +z, default 0):
//     #   camera i at (R cos(start + i*360/count), R sin(...), height)
//     names: [cam0, cam1, ...]     # optional; default cam0, cam1, ...
//   target: default                # Target::Default(), a target file, or inline
//                                  # {name, ball_radius_m, balls_m: [[x,y,z], ...]}
//   motion:                        # T_rig_target over time, one of two forms:
//     # (a) explicit poses (what Write() produces):
//     #   rate_hz: 10                # needed when a pose has no time_s (time = i / rate)
//     #   poses: [{time_s: 0.0, t_m: [x, y, z], q_wxyz: [w, x, y, z]}, ...]
//     # (b) a Lissajous path with a smoothly wobbling orientation:
//     type: lissajous
//     frames: 120
//     rate_hz: 10                  # time of frame i = start_s + i / rate_hz
//     start_s: 0                   # optional
//     centre_m: [0, 0, 0.5]
//     amplitude_m: [0.3, 0.2, 0.3]
//     period_s: [12, 8, 9.6]       # position_k = centre_k + amp_k sin(2 pi t / period_k + phase_k)
//     phase_rad: [0, 0, 0]         # optional
//     rotation_amplitude_deg: 30   # bound on the angle from the base orientation
//     rotation_period_s: [7, 11, 13]
//     rotation_phase_rad: [0, 0, 0]   # optional
//     base_q_wxyz: [1, 0, 0, 0]    # optional
//     #   R(t) = Exp(a / sqrt(3) * (sin(2 pi t / P_k + psi_k))_k) * R_base, |angle| <= a
//   render:                        # optional; every key optional (RenderOptions defaults)
//     bit_depth: 8, exposure: 1, ball_dn: 200, background_dn: 12,
//     background_gradient_dn: [4, 3], blur_sigma_px: 0.6, gain_e_per_dn: 4,
//     read_noise_dn: 1.5, supersampling: 16, spurious_per_image: 0,
//     spurious_radius_px: [1, 4], spurious_dn: 150, occlusion_probability: 0,
//     dropout_probability: 0, noise_free: false
//
// Unknown keys are errors (a typo must not silently fall back to a default). Every
// error is an InputError naming the file, the line and the field, e.g.
// "s.yaml line 12: field 'motion.frames': expected an integer >= 1, found 'abc'".
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "synthetic/renderer.h"
#include "tracking/target.h"
#include "vision/camera_model.h"

namespace mcms {

struct Scenario {
  CameraRig rig;
  Target target;
  std::vector<double> times;        // frame time stamps, s, strictly increasing
  std::vector<Pose> T_rig_target;   // one per frame
  RenderOptions render;
  uint64_t seed = 1;

  size_t NumFrames() const { return times.size(); }

  // The scenario file at `path`; InputError naming the file, line and field.
  static Scenario Read(const std::filesystem::path& path);
  // The same from text; `source` names it in errors, relative paths resolve in `base_dir`.
  static Scenario Parse(const std::string& text, const std::string& source, const std::filesystem::path& base_dir);
  // The paper's set-up (see DefaultText()).
  static Scenario Default();
  // The default scenario's file text, with comments (mcms render --print-default).
  static const std::string& DefaultText();

  // The effective scenario: cameras, target and every pose written out in full at
  // round-trip precision, so Read() gives back this scenario.
  void Write(const std::filesystem::path& path) const;
  std::string ToYaml() const;

  bool IsValid(std::string* why) const;
};

}  // namespace mcms
