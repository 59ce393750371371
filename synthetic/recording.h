// A scenario rendered: the truth of its frames, its images, and the recording folder that
// `mcms render` writes (images, rig, target, ground truth). Over the renderer
// (synthetic/renderer.h: one camera image of the balls) and the scenario
// (synthetic/scenario.h: what is where, when).
#pragma once

#include <filesystem>
#include <memory>
#include <vector>

#include "synthetic/renderer.h"
#include "synthetic/scenario.h"
#include "vision/image_file.h"

namespace mcms {

// The truth of a frame without rendering pixels (same events as the rendered frame).
FrameTruth FrameTruthOf(const Scenario& scenario, size_t frame);

// Renders frames of one scenario; holds one RayTable per camera (built once, the
// slow part). Render() is const and safe to call from several threads.
class ScenarioRenderer {
 public:
  // Keeps its own copy of the scenario; builds the tables on `threads` threads.
  explicit ScenarioRenderer(const Scenario& scenario, int threads = 1);
  ~ScenarioRenderer();
  const Scenario& scenario() const { return *scenario_; }
  RenderedFrame Render(size_t frame) const;
  const RayTable& Table(size_t camera) const { return tables_.at(camera); }

 private:
  std::unique_ptr<const Scenario> scenario_;
  std::vector<RayTable> tables_;
};

// One frame (builds the ray tables: use ScenarioRenderer for many frames).
RenderedFrame RenderFrame(const Scenario& scenario, size_t frame);

// Renders every frame of the scenario into out_dir:
//   scenario.yaml                  the effective scenario (Scenario::Write)
//   rig.yaml, cameras/<name>.cameramodel, target.yaml
//   frames.csv                     frame,time_s
//   images/<camera>/<frame %06d>.png   8- or 16-bit grey (or .pgm, .tif: `format`, written by
//                                  WriteImageFile); absent when that camera dropped out
//   truth/poses.csv                frame,time_s,x_m,y_m,z_m,qw,qx,qy,qz       (T_rig_target)
//   truth/balls.csv                frame,ball,x_m,y_m,z_m                      (rig frame)
//   truth/observations.csv         frame,camera,ball,visible,occluded,u_centre_px,v_centre_px,
//                                  u_centroid_px,v_centroid_px,ellipse_a_px,ellipse_b_px,
//                                  ellipse_angle_rad (the BallTruth rows; occluded = hidden or
//                                  overlapped; only balls entirely in front of the camera)
//   truth/spurious.csv             frame,camera,u_px,v_px,radius_px
//   truth/dropouts.csv             frame,camera
// `camera` columns hold the camera's name (as in rig.yaml and images/), frames count from 0.
// Everything is written into a temporary folder beside out_dir and renamed into
// place at the end; a previous render in out_dir is replaced, any other non-empty
// out_dir is refused. Frames render on `threads` threads; output does not depend on it.
void RenderSequence(const Scenario& scenario, const std::filesystem::path& out_dir, bool quiet, int threads = 2,
                    ImageFileFormat format = ImageFileFormat::kPng);

}  // namespace mcms
