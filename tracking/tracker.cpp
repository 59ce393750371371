#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "core/error.h"
#include "vision/sphere_projection.h"

namespace mcms {

const char* ToString(FrameStatus s) {
  switch (s) {
    case FrameStatus::kOk:
      return "ok";
    case FrameStatus::kDegraded:
      return "degraded";
    case FrameStatus::kLost:
      return "lost";
  }
  return "?";
}

bool TrackerOptions::IsValid(std::string* why) const {
  if (!detector.IsValid(why) || !matching.IsValid(why) || !identification.IsValid(why) || !refinement.IsValid(why))
    return false;
  if (!(association_gate_px > 0)) return (*why = "association_gate_px must be positive", false);
  if (!(max_chi2_per_dof > 0)) return (*why = "max_chi2_per_dof must be positive", false);
  if (!(min_margin >= 0)) return (*why = "min_margin must be >= 0", false);
  if (full_scan_every < 1) return (*why = "full_scan_every must be >= 1", false);
  return true;
}

Tracker::Tracker(CameraRig rig, Target target, TrackerOptions options)
    : rig_(std::move(rig)), target_(std::move(target)), options_(std::move(options)) {
  std::string why;
  if (!options_.IsValid(&why)) Throw("tracker options: ", why);
  target_.MinDistanceGap();
  if (rig_.size() < 2) Throw("the rig needs at least 2 cameras to triangulate, it has ", rig_.size());
  if (!options_.camera_gain_e_per_dn.empty()) {
    if (options_.camera_gain_e_per_dn.size() != rig_.size())
      Throw("tracker options: camera_gain_e_per_dn has ", options_.camera_gain_e_per_dn.size(),
            " entries, the rig has ", rig_.size(), " cameras");
    for (double g : options_.camera_gain_e_per_dn)
      if (!(std::isfinite(g) && g >= 0))
        Throw("tracker options: camera_gain_e_per_dn must be finite and >= 0, got ", g);
  }
  options_.matching.triangulation.sphere_radius_m = target_.ball_radius;
}

std::optional<Pose> Tracker::Predict(double t) const {
  if (history_.empty()) return std::nullopt;
  const auto& [t1, T1] = history_.back();
  if (std::abs(t - t1) > options_.max_prediction_age_s) return std::nullopt;
  if (history_.size() < 2) return T1;
  const auto& [t0, T0] = history_[history_.size() - 2];
  if (!(t1 > t0)) return T1;
  Vec6 v = BoxMinus(T1, T0) / (t1 - t0);  // [omega; velocity], world side
  return BoxPlus(T1, v * (t - t1));
}

BlobDetectorOptions Tracker::DetectorFor(size_t camera) const {
  BlobDetectorOptions o = options_.detector;
  if (camera < options_.camera_gain_e_per_dn.size()) o.gain_e_per_dn = options_.camera_gain_e_per_dn[camera];
  return o;
}

bool Tracker::Usable(size_t c, const std::vector<cv::Mat>& images, std::vector<std::string>* problems) const {
  if (c >= images.size() || images[c].empty()) return false;
  const cv::Mat& im = images[c];
  if (im.cols != rig_.cameras[c].Width() || im.rows != rig_.cameras[c].Height()) {
    std::ostringstream s;
    s << "image is " << im.cols << "x" << im.rows << ", the rig says " << rig_.cameras[c].Width() << "x"
      << rig_.cameras[c].Height();
    (*problems)[c] = s.str();
    return false;
  }
  return true;
}

std::vector<ImagePoint> Tracker::Usable(const std::vector<Blob>& blobs) const {
  std::vector<ImagePoint> v;
  for (const Blob& b : blobs) {
    if (b.touches_border || b.crowded) continue;  // a cut or pulled centre would bias the pose
    v.push_back({b.centre, b.cov});
  }
  return v;
}

std::vector<std::optional<std::vector<ImagePoint>>> Tracker::DetectPoints(const std::vector<cv::Mat>& images,
                                                                          std::vector<std::string>* problems) const {
  std::vector<std::optional<std::vector<ImagePoint>>> pts(rig_.size());
  problems->resize(rig_.size());
  for (size_t c = 0; c < rig_.size(); ++c)
    if (Usable(c, images, problems)) pts[c] = Usable(DetectBlobs(images[c], DetectorFor(c)));
  return pts;
}

std::vector<std::optional<std::vector<ImagePoint>>> Tracker::DetectPointsPredicted(double time_s,
                                                                                   const std::vector<cv::Mat>& images,
                                                                                   std::vector<std::string>* problems,
                                                                                   const PrepareRows& prepare) {
  const std::optional<Pose> predicted = Predict(time_s);
  if (!predicted || ++frames_since_full_scan_ >= static_cast<size_t>(options_.full_scan_every)) {
    frames_since_full_scan_ = 0;
    whole_detections_ += rig_.size();
    if (prepare)
      for (size_t c = 0; c < rig_.size() && c < images.size(); ++c)
        if (!images[c].empty()) prepare(c, nullptr);
    return DetectPoints(images, problems);
  }
  const Pose& last = history_.back().second;
  std::vector<std::optional<std::vector<ImagePoint>>> pts(rig_.size());
  problems->resize(rig_.size());
  const BlobDetectorOptions& d = options_.detector;
  for (size_t c = 0; c < rig_.size(); ++c) {
    if (!Usable(c, images, problems)) continue;
    const CameraModel& cam = rig_.cameras[c];
    std::vector<cv::Rect> windows;
    std::vector<std::pair<Vec2, double>> expected;  // predicted ball image, how far its blob may be
    for (size_t b = 0; b < target_.balls_target.size(); ++b) {
      const Vec3& ball = target_.balls_target[b];
      const Vec3 p = cam.T_cam_rig() * (*predicted * ball);
      const Vec3 p_last = cam.T_cam_rig() * (last * ball);
      if (!(p.z() > 0 && p_last.z() > 0)) continue;
      const Vec2 q = cam.Project(p), q_last = cam.Project(p_last);
      if (!q.allFinite() || !q_last.allFinite() || q.x() < 0 || q.y() < 0 || q.x() > cam.Width() - 1 ||
          q.y() > cam.Height() - 1)
        continue;
      // The window holds the ball's image (radius fx R / z, with room for an oblique view),
      // the detector's widest measurement window and ring, the association gate and the
      // frame's image motion again (the prediction's error at a change of velocity).
      const double radius_px = 1.5 * cam.Intrinsics()[0] * target_.ball_radius / p.z();
      const double tolerance = options_.association_gate_px + (q - q_last).norm() + 2;
      const double half = radius_px + d.max_window_margin_px + d.ring_width_px + tolerance;
      if (!(half < 0.25 * std::max(cam.Width(), cam.Height()))) {  // too close or too fast: the whole image
        windows.clear();
        expected.clear();
        break;
      }
      const int x0 = static_cast<int>(std::floor(q.x() - half)), y0 = static_cast<int>(std::floor(q.y() - half));
      const int side = static_cast<int>(std::ceil(2 * half)) + 1;
      windows.emplace_back(x0, y0, side, side);
      // A usable blob is required of the balls this camera observed in the last posed frame
      // (not of those it could not: two ball images that touch are unusable in any window).
      if (c < last_observed_.size() && last_observed_[c][b]) expected.emplace_back(q, tolerance);
    }
    if (!windows.empty() && !expected.empty()) {
      if (prepare) {
        const std::vector<cv::Range> rows = RowsReadInWindows(images[c].size(), windows);
        prepare(c, &rows);
      }
      std::vector<ImagePoint> v = Usable(DetectBlobsInWindows(images[c], windows, DetectorFor(c)));
      // Every ball predicted in view must have a usable blob in the windows; otherwise
      // (occlusion, a ball near a window's edge, a wrong prediction) the whole image.
      bool complete = true;
      for (const auto& [q, tolerance] : expected)
        complete =
            complete && std::any_of(v.begin(), v.end(), [&, &q = q, &tolerance = tolerance](const ImagePoint& ip) {
              return (ip.q - q).norm() < tolerance;
            });
      if (complete) {
        ++window_detections_;
        pts[c] = std::move(v);
        continue;
      }
    }
    ++whole_detections_;
    if (prepare) prepare(c, nullptr);
    pts[c] = Usable(DetectBlobs(images[c], DetectorFor(c)));
  }
  return pts;
}

void Tracker::CheckTime(size_t frame, double time_s) {
  if (!std::isfinite(time_s)) Throw("frame ", frame, ": time_s ", time_s, " is not a finite number of seconds");
  if (last_time_s_ && time_s < *last_time_s_)
    Throw("frame ", frame, ": time_s ", time_s, " is before the previous frame's ", *last_time_s_,
          " s; give frames in time order (the tracker predicts each frame from the ones before)");
  last_time_s_ = time_s;
}

FrameResult Tracker::ProcessFrame(size_t frame, double time_s, const std::vector<cv::Mat>& images,
                                  const std::vector<std::string>& problems) {
  return ProcessFrame(frame, time_s, images, problems, {});
}

FrameResult Tracker::ProcessFrame(size_t frame, double time_s, const std::vector<cv::Mat>& images,
                                  const std::vector<std::string>& problems, const PrepareRows& prepare) {
  CheckTime(frame, time_s);
  std::vector<std::string> why(problems);
  if (options_.predicted_windows) return Track(frame, time_s, DetectPointsPredicted(time_s, images, &why, prepare), why);
  if (prepare)
    for (size_t c = 0; c < images.size(); ++c)
      if (!images[c].empty()) prepare(c, nullptr);
  return Track(frame, time_s, DetectPoints(images, &why), why);
}

namespace {
std::string Join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : "; ") + x;
  return s;
}
}  // namespace

// Says what was rejected and where, per camera: the outliers dropped by the refinement,
// blobs that no ball explains (spurious reflections), and isolated ball images the final
// pose puts well inside a camera's view that were not observed (occlusion, a lost blob).
void Tracker::DescribeRejections(const std::vector<std::vector<ImagePoint>>& pts,
                                 const std::vector<std::optional<std::vector<ImagePoint>>>& in,
                                 const PoseRefinement& ref, const std::vector<int>& views,
                                 std::vector<std::string>* notes) const {
  const int ncam = static_cast<int>(rig_.size());
  const int nb = static_cast<int>(target_.balls_target.size());
  std::vector<int> dropped(ncam, 0), spurious(ncam, 0);
  std::set<std::pair<int, int>> seen;  // (camera, ball) kept or dropped
  for (const auto& o : ref.kept) seen.insert({o.camera, o.ball});
  for (const auto& o : ref.dropped) {
    seen.insert({o.camera, o.ball});
    ++dropped[o.camera];
  }
  std::ostringstream out, spur, miss;
  for (int c = 0; c < ncam; ++c) {
    for (const ImagePoint& p : pts[c]) {
      bool explained = false;
      for (const auto* list : {&ref.kept, &ref.dropped})
        for (const auto& o : *list) explained = explained || (o.camera == c && o.q == p.q);
      spurious[c] += explained ? 0 : 1;
    }
    if (dropped[c]) out << (out.tellp() > 0 ? " / " : "") << rig_.names[c] << " " << dropped[c];
    if (spurious[c]) spur << (spur.tellp() > 0 ? " / " : "") << rig_.names[c] << " " << spurious[c];
    if (c >= static_cast<int>(in.size()) || !in[c]) continue;  // no image: already said
    const CameraModel& cam = rig_.cameras[c];
    // Images within two diameters of another ball's image may merge into one blob (a limit
    // of the detector, not a fault): only isolated ball images count as missing.
    const std::vector<bool> crowded = CrowdedBallImages(cam, target_, ref.T_rig_target, 0.0, 1.0);
    std::string balls;
    int nmiss = 0;
    for (int b = 0; b < nb; ++b) {
      if (views[b] == 0 || seen.count({c, b}) || crowded[b]) continue;
      const Vec3 p_cam = cam.T_cam_rig() * (ref.T_rig_target * target_.balls_target[b]);
      if (!(p_cam.z() > 0.0)) continue;
      const double radius = cam.Intrinsics()[0] * target_.ball_radius / p_cam.z();
      // Fully inside the image with a margin of the ball's apparent radius plus 2 px.
      if (cam.Sees(p_cam, radius + 2.0)) {
        balls += ' ';
        balls += std::to_string(b);
        ++nmiss;
      }
    }
    if (nmiss) miss << (miss.tellp() > 0 ? " / " : "") << rig_.names[c] << (nmiss > 1 ? " balls" : " ball") << balls;
  }
  std::ostringstream s;
  if (!ref.dropped.empty()) {
    s << ref.dropped.size() << " outlier observation(s) dropped (" << out.str() << ")";
    notes->push_back(s.str());
  }
  if (spur.tellp() > 0) {
    s.str("");
    s << "blobs matching no ball (spurious reflections?) rejected (" << spur.str() << ")";
    notes->push_back(s.str());
  }
  if (miss.tellp() > 0) {
    s.str("");
    s << "ball images expected but not observed (" << miss.str() << ")";
    notes->push_back(s.str());
  }
}

FrameResult Tracker::ProcessPoints(size_t frame, double time_s,
                                   const std::vector<std::optional<std::vector<ImagePoint>>>& in,
                                   const std::vector<std::string>& problems) {
  CheckTime(frame, time_s);
  return Track(frame, time_s, in, problems);
}

FrameResult Tracker::Track(size_t frame, double time_s, const std::vector<std::optional<std::vector<ImagePoint>>>& in,
                           const std::vector<std::string>& problems) {
  FrameResult res;
  res.frame = frame;
  res.time_s = time_s;
  const int ncam = static_cast<int>(rig_.size());
  const int nb = static_cast<int>(target_.balls_target.size());
  std::vector<std::string> notes;
  std::vector<std::vector<ImagePoint>> pts(ncam);
  for (int c = 0; c < ncam; ++c) {
    if (c < static_cast<int>(in.size()) && in[c]) {
      pts[c] = *in[c];
      ++res.cameras_used;
    } else {
      const std::string p = c < static_cast<int>(problems.size()) && !problems[c].empty() ? problems[c] : "no image";
      notes.push_back("camera " + rig_.names[c] + ": " + p);
    }
  }

  res.image_points = pts;
  res.points = MatchAndTriangulate(rig_, pts, options_.matching);
  res.points_triangulated = static_cast<int>(res.points.size());
  const std::optional<Pose> predicted = Predict(time_s);

  std::optional<Pose> initial;
  std::vector<int> point_of_ball(nb, -1);
  bool from_prediction = false;
  const auto id = IdentifyTarget(target_, res.points, options_.identification);
  const bool fit_ok = id && id->fit_rms_m <= options_.max_fit_rms_m;
  if (fit_ok) res.identification_margin = id->margin;
  if (fit_ok && id->margin >= options_.min_margin) {
    initial = id->T_rig_target;
    point_of_ball = id->point_of_ball;
  } else if (predicted) {
    initial = predicted;
    from_prediction = true;
    std::ostringstream s;
    if (fit_ok)
      s << "identification ambiguous (margin " << id->margin << "); used the prediction from earlier frames";
    else
      s << "target not identified among " << res.points.size() << " triangulated points; used the prediction";
    notes.push_back(s.str());
  } else if (fit_ok) {
    initial = id->T_rig_target;
    point_of_ball = id->point_of_ball;
    std::ostringstream s;
    s << "identification ambiguous (margin " << id->margin << ") and no prediction";
    notes.push_back(s.str());
  } else {
    std::ostringstream s;
    s << "target not found: " << res.points.size() << " points triangulated from " << res.cameras_used
      << " cameras, no assignment of at least 3 balls fits the target's distances";
    notes.push_back(s.str());
    res.reason = Join(notes);
    return res;
  }

  // 2-D observations: the identified points' views first, then any ball image the
  // pose predicts near an unused blob.
  std::vector<std::vector<bool>> used(ncam);
  for (int c = 0; c < ncam; ++c) used[c].assign(pts[c].size(), false);
  std::vector<BallObservation> obs;
  for (int b = 0; b < nb; ++b) {
    if (point_of_ball[b] < 0) continue;
    for (const auto& o : res.points[point_of_ball[b]].observations) {
      obs.push_back({o.camera, b, pts[o.camera][o.index].q, pts[o.camera][o.index].cov});
      used[o.camera][o.index] = true;
    }
  }
  auto associate = [&](const Pose& T, double gate, std::vector<BallObservation>* out) {
    std::set<std::pair<int, int>> have;
    for (const auto& o : *out) have.insert({o.camera, o.ball});
    for (int c = 0; c < ncam; ++c)
      for (int b = 0; b < nb; ++b) {
        if (have.count({c, b})) continue;
        const CameraModel& cam = rig_.cameras[c];
        const Vec3 p_cam = cam.T_cam_rig() * (T * target_.balls_target[b]);
        if (!cam.Sees(p_cam)) continue;
        const Vec2 q = SphereImageCentroid(cam, p_cam, target_.ball_radius, options_.refinement.bias_outline_points);
        const int best = ClaimNearest(pts[c], q, gate, &used[c]);
        if (best >= 0) out->push_back({c, b, pts[c][best].q, pts[c][best].cov});
      }
  };
  associate(*initial, from_prediction ? 3 * options_.association_gate_px : options_.association_gate_px, &obs);

  std::set<int> balls;
  for (const auto& o : obs) balls.insert(o.ball);
  if (balls.size() < 3) {
    notes.push_back("fewer than 3 balls observed (" + std::to_string(balls.size()) + ")");
    res.reason = Join(notes);
    return res;
  }
  PoseRefinement ref = RefinePose(rig_, target_, *initial, obs, options_.refinement);
  if (from_prediction) {
    // Re-associate from the refined pose with the tight gate and refine again.
    for (int c = 0; c < ncam; ++c) std::fill(used[c].begin(), used[c].end(), false);
    std::vector<BallObservation> again;
    associate(ref.T_rig_target, options_.association_gate_px, &again);
    std::set<int> b2;
    for (const auto& o : again) b2.insert(o.ball);
    if (b2.size() >= 3) ref = RefinePose(rig_, target_, ref.T_rig_target, again, options_.refinement);
  }

  res.chi2_per_dof = ref.dof > 0 ? ref.chi2 / ref.dof : 0.0;
  res.rms_px = ref.rms_px;
  res.observations = static_cast<int>(ref.kept.size());
  std::set<int> seen;
  std::vector<int> views(nb, 0);
  for (const auto& o : ref.kept) {
    seen.insert(o.ball);
    ++views[o.ball];
  }
  res.balls_identified = static_cast<int>(seen.size());
  res.point_of_ball = point_of_ball;
  res.ball_observations = ref.kept;
  if (!ref.converged) {
    notes.push_back("pose refinement did not converge");
    res.reason = Join(notes);
    return res;
  }
  if (res.chi2_per_dof > options_.max_chi2_per_dof) {
    std::ostringstream s;
    s << "observations do not fit the target (chi2/dof " << res.chi2_per_dof << ")";
    notes.push_back(s.str());
    if (from_prediction) {
      res.reason = Join(notes);
      return res;
    }
  }
  for (int b = 0; b < nb; ++b)
    if (views[b] == 0) notes.push_back("ball " + std::to_string(b) + " not observed");
  DescribeRejections(pts, in, ref, views, &notes);

  res.T_rig_target = ref.T_rig_target;
  res.cov = ref.cov;
  res.status = notes.empty() ? FrameStatus::kOk : FrameStatus::kDegraded;
  res.reason = Join(notes);
  if (res.chi2_per_dof <= options_.max_chi2_per_dof) {
    history_.emplace_back(time_s, ref.T_rig_target);
    if (history_.size() > 2) history_.erase(history_.begin());
    last_observed_.assign(rig_.size(), std::vector<char>(target_.balls_target.size(), 0));
    for (const auto& o : ref.kept) last_observed_[o.camera][o.ball] = 1;
  }
  return res;
}

}  // namespace mcms
