// The camera audit (issue 11) must find an effect hidden in a recording: a seed picks the
// effect from the catalog, its size (detectable, not obvious) and where (which camera,
// which ball); the audit must name it there, estimate its size within 3 of its own sigmas
// and report a positive held-out gain. On clean recordings it must name nothing at the
// rate it was designed for.
//
// The recordings are tracked observations, not images: every ball image is the project's
// forward model of the "world" (the rig with the hidden effect) plus Gaussian pixel noise
// of the sigma the blobs claim (times the hidden noise factor), so the test runs in
// seconds; the rendered path is covered by tests/test_app_audit.cpp and test_app_noise.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <boost/math/distributions/binomial.hpp>
#include <boost/math/distributions/normal.hpp>
#include <cstdio>
#include <cstdlib>
#include <set>
#include <limits>
#include <random>

#include "synthetic/scenario.h"
#include "audit/camera_audit.h"
#include "vision/sphere_projection.h"

namespace mcms {
namespace {

// Frames per recording (at 5 Hz); MCMS_AUDIT_FRAMES overrides it (the speed benchmark).
int Frames() {
  const char* e = std::getenv("MCMS_AUDIT_FRAMES");
  return e ? std::atoi(e) : 40;
}
constexpr double kSigmaPx = 0.1;  // the blobs' claimed noise (px)
// Seeds per effect; MCMS_AUDIT_SEEDS overrides it (to measure detection rates).
uint64_t SeedsPerEffect() {
  const char* e = std::getenv("MCMS_AUDIT_SEEDS");
  return e ? std::strtoull(e, nullptr, 10) : 6;
}

// `frames` 0: Frames().
Scenario Motion(double start_s, int frames = 0) {
  std::string text = Scenario::DefaultText();
  auto replace = [&](const std::string& a, const std::string& b) {
    const size_t at = text.find(a);
    ASSERT_NE(at, std::string::npos) << a;
    text.replace(at, a.size(), b);
  };
  replace("frames: 120", "frames: " + std::to_string(frames > 0 ? frames : Frames()));
  char s[64];
  std::snprintf(s, sizeof s, "  rate_hz: 5\n  start_s: %.6f\n", start_s);
  replace("  rate_hz: 10\n", s);
  return Scenario::Parse(text, "<audit test>", {});
}

// The hidden effect: name, camera (or ball) index, parameters in the catalog's units.
struct Hidden {
  std::string name;  // empty: clean
  int index = 0;
  std::vector<double> p;
  double from_time_s = -1e30;  // camera_moved from this time on
};

struct Recording {
  CameraRig rig;  // the model the audit is given
  Target target;
  std::vector<FrameResult> results;
};

// `cameras` < 4: the default rig's first `cameras` cameras only (a smaller rig).
Recording Make(const std::vector<Hidden>& hs, uint64_t seed, size_t cameras = 4, int frames = 0) {
  Scenario sc = Motion(0.0, frames);
  if (cameras < sc.rig.size()) {
    sc.rig.cameras.resize(cameras);
    sc.rig.names.resize(cameras);
  }
  CameraRig world = sc.rig;
  CameraRig moved = sc.rig;  // camera_moved from from_time_s on
  double from_time_s = std::numeric_limits<double>::infinity();
  Target wt = sc.target;
  std::vector<double> noise(sc.rig.size(), 1.0), late_s(sc.rig.size(), 0.0);
  for (const Hidden& h : hs) {
    const int c = h.index;
    if (h.name == "camera_moved") {
      const Pose T_rig_cam = sc.rig.cameras[c].T_cam_rig().Inverse();
      const Pose M{ExpSO3(Vec3(h.p[0], h.p[1], h.p[2])), Vec3(h.p[3], h.p[4], h.p[5])};
      if (h.from_time_s > -1e29) from_time_s = h.from_time_s;
      (h.from_time_s > -1e29 ? moved : world).cameras[c].SetT_cam_rig((M * T_rig_cam).Inverse());
    } else if (h.name == "focal_length") {
      world.cameras[c].MutableIntrinsics()[0] *= 1 + h.p[0];
      world.cameras[c].MutableIntrinsics()[1] *= 1 + h.p[0];
    } else if (h.name == "principal_point") {
      world.cameras[c].MutableIntrinsics()[2] += h.p[0];
      world.cameras[c].MutableIntrinsics()[3] += h.p[1];
    } else if (h.name == "radial_distortion") {
      world.cameras[c].MutableIntrinsics()[4] += h.p[0];
    } else if (h.name == "pixel_noise_scale") {
      noise[c] = h.p[0];
    } else if (h.name == "camera_time_offset") {
      late_s[c] = h.p[0];
    } else if (h.name == "target_geometry") {
      wt.balls_target[c] += Vec3(h.p[0], h.p[1], h.p[2]);
    }
  }
  // A camera moved part-way: after the move it has the world's other effects and the move.
  for (size_t k = 0; k < world.size(); ++k)
    if (moved.cameras[k].T_cam_rig().t == sc.rig.cameras[k].T_cam_rig().t) moved.cameras[k] = world.cameras[k];
    else moved.cameras[k].MutableIntrinsics() = world.cameras[k].Intrinsics();
  std::vector<Scenario> late;
  for (double dt : late_s) late.push_back(Motion(dt, frames));
  for (Scenario& l : late) l.rig = sc.rig;
  // Outside the catalog: cameras not triggered together, each view exposed at the frame's
  // time + j * step (j in -2..2, drawn per frame and camera), its time in camera_time_s.
  double sync_step = 0;
  for (const Hidden& h : hs)
    if (h.name == "unsynchronised") sync_step = h.p[0];
  std::vector<Scenario> shifted;
  if (sync_step > 0)
    for (int j = -2; j <= 2; ++j) shifted.push_back(Motion(j * sync_step, frames));
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01;
  Recording r{sc.rig, sc.target, {}};
  for (size_t f = 0; f < sc.NumFrames(); ++f) {
    FrameResult fr;
    fr.frame = f;
    fr.time_s = sc.times[f];
    fr.status = FrameStatus::kOk;
    fr.T_rig_target = sc.T_rig_target[f];
    fr.image_points.resize(world.size());
    for (size_t k = 0; k < world.size(); ++k) {
      Pose T = late[k].T_rig_target[f];
      if (sync_step > 0) {
        const int j = static_cast<int>(rng() % 5);
        T = shifted[j].T_rig_target[f];
        fr.camera_time_s.resize(world.size());
        fr.camera_time_s[k] = sc.times[f] + (j - 2) * sync_step;
      }
      const CameraModel& cam = sc.times[f] >= from_time_s ? moved.cameras[k] : world.cameras[k];
      for (size_t b = 0; b < wt.balls_target.size(); ++b) {
        const Vec3 p_cam = cam.T_cam_rig() * (T * wt.balls_target[b]);
        if (!cam.Sees(p_cam, 12)) continue;
        Vec2 q = cam.Project(p_cam) + SphereProjectionBias(cam, p_cam, wt.ball_radius, 32);
        q += noise[k] * kSigmaPx * Vec2(n01(rng), n01(rng));
        for (const Hidden& h : hs)  // outside the catalog: the image drifts linearly over the recording
          if (h.name == "image_drift" && h.index == static_cast<int>(k))
            q += (2 * sc.times[f] / sc.times.back() - 1) * Vec2(h.p[0], h.p[1]);
        const Mat2 cov = Mat2::Identity() * kSigmaPx * kSigmaPx;
        fr.image_points[k].push_back({q, cov});
        fr.ball_observations.push_back({static_cast<int>(k), static_cast<int>(b), q, cov});
      }
    }
    r.results.push_back(fr);
  }
  return r;
}

// A seed picks the size (uniform in [lo, hi] with a random sign per component) and the
// camera (or ball); the effect is given. `camera` >= 0 puts it on that camera.
Hidden Pick(const std::string& name, uint64_t seed, int camera = -1) {
  std::mt19937_64 rng(seed * 7919 + 17);
  std::uniform_real_distribution<double> u(0, 1);
  auto size = [&](double lo, double hi) { return (lo + (hi - lo) * u(rng)) * (u(rng) < 0.5 ? -1 : 1); };
  Hidden h{name, static_cast<int>(rng() % 4), {}};
  if (camera >= 0) h.index = camera;
  if (name == "camera_moved") {
    // A bump in the camera's own frame: a roll of 0.5 to 1.5 mrad about the optical axis
    // (what no change of the intrinsics mimics: a tilt alone is, at these sizes, the same
    // image shift as a principal-point change, and the audit then names the simpler
    // principal_point or reports both as undecided), tilts of 0.05 to 0.15 mrad and a shift
    // of 0.1 to 0.3 mm along each axis; the catalog's parameters are the same move in the
    // rig frame, T_rig_cam' = M T_rig_cam with M = T_rig_cam D T_rig_cam^-1.
    const Pose D{ExpSO3(Vec3(size(0.05e-3, 0.15e-3), size(0.05e-3, 0.15e-3), size(0.5e-3, 1.5e-3))),
                 Vec3(size(0.1e-3, 0.3e-3), size(0.1e-3, 0.3e-3), size(0.1e-3, 0.3e-3))};
    const Pose T_rig_cam = Motion(0).rig.cameras[h.index].T_cam_rig().Inverse();
    const Pose M = T_rig_cam * D * T_rig_cam.Inverse();
    const Vec3 r = LogSO3(M.R);
    h.p = {r.x(), r.y(), r.z(), M.t.x(), M.t.y(), M.t.z()};
  } else if (name == "focal_length") {
    h.p = {size(0.0008, 0.002)};
  } else if (name == "principal_point") {
    h.p = {size(0.04, 0.1), size(0.04, 0.1)};
  } else if (name == "radial_distortion") {
    h.p = {size(0.015, 0.03)};
  } else if (name == "camera_time_offset") {
    h.p = {size(0.001, 0.003)};
  } else if (name == "pixel_noise_scale") {
    h.p = {1.4 + 0.4 * u(rng)};
  } else if (name == "target_geometry") {
    h.index = static_cast<int>(rng() % 5);
    h.p = {size(0.15e-3, 0.3e-3), size(0.15e-3, 0.3e-3), size(0.15e-3, 0.3e-3)};
  }
  return h;
}

std::string Where(const Hidden& h, const CameraRig& rig) {
  return h.name == "target_geometry" ? "ball " + std::to_string(h.index + 1) : rig.names[h.index];
}

// The size must be within 3 of its own sigmas: for an effect of k parameters, each within
// the bound that gives the whole effect the confidence of 3 sigmas for one (99.73 %,
// Bonferroni over k): 3 for k = 1, 3.20 for 2, 3.26 for 3, 3.46 for 6.
double SigmaBound(size_t k) {
  const double tail = (1 - 0.9973002) / (2.0 * static_cast<double>(k));
  return boost::math::quantile(boost::math::complement(boost::math::normal(), tail));
}

CameraAuditResult Audit(const Recording& r) {
  return AuditCameraModel(r.rig, r.target, r.results, {}, [](const std::string& s) { std::printf("  %s\n", s.c_str()); });
}

// Cameras that are not triggered together (each view exposed 0, 8 or 16 ms before or after
// the frame's time, drawn per frame and camera; the target moving as in every test here):
// given each view's exposure time (FrameResult::camera_time_s), the audit predicts each
// camera's images at its own time along the frame's motion and names nothing; given one
// time per frame, the same recordings contradict the model.
TEST(AuditCameras, UnsynchronisedCamerasAreCleanWithTheirExposureTimes) {
  for (uint64_t seed = 1; seed <= 3; ++seed) {
    Recording r = Make({{"unsynchronised", 0, {0.008}}}, seed);
    const CameraAuditResult a = Audit(r);
    EXPECT_TRUE(a.report.effects.empty()) << "seed " << seed << ": " << a.report.effects.front().name << " at "
                                          << a.report.effects.front().where;
    EXPECT_TRUE(a.report.undecided.empty()) << "seed " << seed;
    for (FrameResult& f : r.results) f.camera_time_s.clear();
    const CameraAuditResult b = Audit(r);
    bool failed = !b.report.effects.empty();
    for (const AuditTest& t : b.report.tests) failed |= t.failed;
    EXPECT_TRUE(failed) << "seed " << seed << ": one time per frame passed every test";
  }
}

class HiddenEffect : public ::testing::TestWithParam<std::string> {};

TEST_P(HiddenEffect, IsNamedWhereItIsWithItsSizeAndAHeldOutGain) {
  for (uint64_t seed = 1; seed <= SeedsPerEffect(); ++seed) {
    const Hidden h = Pick(GetParam(), seed);
    const Recording rec = Make({h}, seed);
    const CameraAuditResult a = Audit(rec);
    std::printf("seed %llu, hidden %s at %s:", static_cast<unsigned long long>(seed), h.name.c_str(),
                Where(h, rec.rig).c_str());
    for (double v : h.p) std::printf(" %.4g", v);
    std::printf("\n%s", a.report.Text().c_str());
    EXPECT_FALSE(a.report.effects.empty());
    EXPECT_EQ(a.report.nested.failed, 0) << "issue 51: a fit below the model it extends";
    if (a.report.effects.empty()) continue;
    const AuditEffect& e = a.report.effects[0];
    EXPECT_EQ(e.name, h.name);
    EXPECT_EQ(e.where, Where(h, rec.rig));
    EXPECT_GT(e.heldout_loglik_gain, 0);
    EXPECT_GT(e.bic_gain, 0);
    EXPECT_EQ(a.report.effects.size(), 1u) << "only the hidden effect";
    if (e.name != h.name) continue;
    std::printf("z-scores of %s:", h.name.c_str());
    for (size_t k = 0; k < h.p.size(); ++k) std::printf(" %+.2f", (e.parameters[k].second - h.p[k]) / e.sigma[k].second);
    std::printf("\n");
    const double z = SigmaBound(h.p.size());
    for (size_t k = 0; k < h.p.size(); ++k)
      EXPECT_NEAR(e.parameters[k].second, h.p[k], z * e.sigma[k].second) << e.parameters[k].first;
    if (h.name != "pixel_noise_scale") {
      EXPECT_LT(e.heldout_rms_after, e.heldout_rms_before);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Catalog, HiddenEffect,
                         ::testing::Values("pixel_noise_scale", "camera_moved", "focal_length", "principal_point",
                                           "radial_distortion", "camera_time_offset", "target_geometry"));

// Clean recordings: the audit is designed to name something on at most
// CameraAuditOptions::false_alarm (1 %) of them; the observed count must be consistent
// with that (one-sided binomial, p > 0.001).
TEST(AuditCameras, CleanRecordingsAtTheDesignedFalseAlarmRate) {
  constexpr int kSets = 200;
  int alarms = 0;
  for (int seed = 100; seed < 100 + kSets; ++seed) {
    const Recording rec = Make({}, seed);
    const CameraAuditResult a = AuditCameraModel(rec.rig, rec.target, rec.results);
    // Issue 51: no candidate's fit ends below the model it extends.
    EXPECT_EQ(a.report.nested.failed, 0) << "seed " << seed;
    EXPECT_GE(a.report.nested.worst_relative_lr, -NestedFits::kTolerance) << "seed " << seed;
    if (!a.report.clean) {
      ++alarms;
      std::printf("seed %d: false alarm\n%s", seed, a.report.Text().c_str());
    }
    for (double s : a.noise_scale) EXPECT_NEAR(s, 1.0, 0.15);
  }
  const double p = alarms == 0 ? 1.0
                               : boost::math::cdf(boost::math::complement(
                                     boost::math::binomial(kSets, CameraAuditOptions{}.false_alarm), alarms - 1));
  std::printf("%d false alarm(s) in %d clean recordings (designed rate %.3g): P(>= observed) = %.3g\n", alarms, kSets,
              CameraAuditOptions{}.false_alarm, p);
  EXPECT_GT(p, 1e-3);
}

// An effect outside the catalog (one camera's image drifts linearly in time, e.g. a
// warming camera: +-0.1 to 0.2 px at the ends, the camera's noise is 0.1 px) must show in
// the residual tests: the strongest failed trend against time is at that camera (the
// other cameras' leave-one-out poses still hold the drifting camera, so they may show it
// too, weaker).
TEST(AuditCameras, ResidualTestsShowADriftOutsideTheCatalog) {
  for (uint64_t seed = 1; seed <= 3; ++seed) {
    std::mt19937_64 rng(seed * 31 + 5);
    std::uniform_real_distribution<double> u(0.1, 0.2);
    Hidden h{"image_drift", static_cast<int>(rng() % 4), {u(rng), -u(rng)}};
    const Recording rec = Make({h}, seed);
    const CameraAuditResult a = AuditCameraModel(rec.rig, rec.target, rec.results);
    const AuditTest* strongest = nullptr;
    for (const auto& t : a.report.tests)
      if (t.failed && t.name.find("trend vs time") != std::string::npos && (!strongest || t.p_value < strongest->p_value))
        strongest = &t;
    ASSERT_NE(strongest, nullptr) << "seed " << seed << "\n" << a.report.Text();
    EXPECT_EQ(strongest->name.rfind(rec.rig.names[h.index] + ":", 0), 0u)
        << "seed " << seed << ", drift at " << rec.rig.names[h.index] << ", strongest trend: " << strongest->name;
    EXPECT_FALSE(a.report.clean);
    ASSERT_EQ(a.residuals.size(), rec.rig.size());
    EXPECT_FALSE(a.residuals[h.index].empty());
  }
}

// A camera bumped half-way through: named as a move from a change time on, not as one
// constant move, with its size.
TEST(AuditCameras, FindsACameraBumpedHalfWay) {
  Hidden h = Pick("camera_moved", 5);
  h.from_time_s = 4.0;
  const Recording rec = Make({h}, 5);
  const CameraAuditResult a = Audit(rec);
  std::printf("%s", a.report.Text().c_str());
  ASSERT_EQ(a.report.effects.size(), 1u);
  const AuditEffect& e = a.report.effects[0];
  EXPECT_EQ(e.name, "camera_moved");
  EXPECT_EQ(e.where, Where(h, rec.rig));
  ASSERT_EQ(e.parameters.size(), 7u);
  EXPECT_EQ(e.parameters[6].first, "from_time_s");
  EXPECT_NEAR(e.parameters[6].second, h.from_time_s, 0.5);
  for (size_t k = 0; k < 6; ++k) EXPECT_NEAR(e.parameters[k].second, h.p[k], SigmaBound(6) * e.sigma[k].second);
}

// Two effects at once are both named.
TEST(AuditCameras, NamesTwoEffectsAtOnce) {
  Hidden f = Pick("focal_length", 3), b = Pick("target_geometry", 4);
  const Recording rec = Make({f, b}, 3);
  const CameraAuditResult a = Audit(rec);
  std::printf("%s", a.report.Text().c_str());
  std::set<std::string> named;
  for (const auto& e : a.report.effects) named.insert(e.name + " at " + e.where);
  EXPECT_TRUE(named.count("focal_length at " + Where(f, rec.rig)));
  EXPECT_TRUE(named.count("target_geometry at " + Where(b, rec.rig)));
  EXPECT_EQ(named.size(), 2u);
}

}  // namespace
}  // namespace mcms

namespace mcms {
namespace {

// Two effects at once (issue 35, open): every pair of the catalog's camera effects on two
// different cameras of the default rig (4 cameras) and of a 3-camera rig (its first three),
// and every pair of different effects on one camera.
//
// What is always required (TwoEffects.NeverAWrongCause, every pair): nothing named that was
// not hidden, and each hidden effect named at its camera, or undecided in a group that holds
// it, or missed only where the audit of that effect alone, on the same recording's noise,
// misses it too, or (a principal point or focal length of a camera whose move is named) taken
// up by the move, as the report's note on moves says.
//
// What the issue asks (DISABLED_BothNamedAtTheirCamerasNothingElse, run it with
// --gtest_also_run_disabled_tests): both named at the right cameras, nothing else. Not met
// for all pairs, and for some it cannot be: two moved cameras, or two time offsets, in a
// 3-camera rig are not identifiable from the images at all (the target's poses are free, so
// camera 0 moved by M0 and camera 2 by M2 give the same images as camera 1 moved by M0^-1
// and camera 2 by M0^-1 M2; offsets (0, a, b) the same as (-a, 0, b - a)): there the right
// answer is undecided, and that is what is checked. What else falls short, and why:
//  - a move and an intrinsic of one camera: a tilt is the same image shift as a principal
//    point and a shift along the axis nearly a focal length at these sizes, so the move
//    alone explains both;
//  - a principal point (0.04-0.1 px) beside another effect in a small rig: the joint fit
//    (every term and every frame's pose) explains the images as well with it at another
//    camera, so the audit reports the cameras undecided;
//  - a weak second effect (a radial term where the camera sees the target near its centre):
//    below what the audit detects alone.
struct Pair {
  std::string a, b;
  size_t cameras;
  bool same;
  uint64_t seed;
};
std::vector<Pair> AllPairs() {
  const std::vector<std::string> E = {"pixel_noise_scale", "camera_moved",      "focal_length",
                                      "principal_point",   "radial_distortion", "camera_time_offset"};
  std::vector<Pair> out;
  for (size_t cameras : {4u, 3u})
    for (size_t i = 0; i < E.size(); ++i)
      for (size_t j = i; j < E.size(); ++j) out.push_back({E[i], E[j], cameras, false, 200 + out.size()});
  for (size_t i = 0; i < E.size(); ++i)
    for (size_t j = i + 1; j < E.size(); ++j) out.push_back({E[i], E[j], 4, true, 200 + out.size()});
  return out;
}

std::string PairName(const Pair& p) {
  return p.a + "_" + p.b + (p.same ? "_one_camera" : "") + "_" + std::to_string(p.cameras) + "cams";
}

struct PairOutcome {
  std::string what;  // the pair, for messages
  Hidden ha, hb;
  CameraAuditResult r;
  std::string la, lb;  // "effect at camera" of each
  std::set<std::string> named;
};

PairOutcome AuditPair(const Pair& p) {
  const uint64_t seed = p.seed;
  const int ca = static_cast<int>(seed % p.cameras);
  const int cb = p.same ? ca : static_cast<int>((ca + 1 + seed / 7 % (p.cameras - 1)) % p.cameras);
  PairOutcome o{"", Pick(p.a, seed, ca), Pick(p.b, seed + 1, cb), {}, "", "", {}};
  const Recording rec = Make({o.ha, o.hb}, seed, p.cameras);
  o.r = Audit(rec);
  o.la = p.a + " at " + Where(o.ha, rec.rig);
  o.lb = p.b + " at " + Where(o.hb, rec.rig);
  o.what = o.la + " + " + o.lb + " (" + std::to_string(p.cameras) + " cameras, seed " + std::to_string(seed) + ")";
  std::printf("%s\n%s", o.what.c_str(), o.r.report.Text().c_str());
  for (const auto& e : o.r.report.effects) o.named.insert(e.name + " at " + e.where);
  return o;
}

// Two moves, or two time offsets, in a 3-camera rig: not identifiable.
bool Unidentifiable(const Pair& p) {
  return p.a == p.b && p.cameras == 3 && (p.a == "camera_moved" || p.a == "camera_time_offset");
}

// Is "effect at camera" in an undecided group, alone or in a pair ("a + b at camera")?
bool InUndecidedGroup(const CameraAuditResult& r, const std::string& label) {
  const size_t at = label.find(" at ");
  const std::string effect = label.substr(0, at), where = label.substr(at);
  for (const auto& g : r.report.undecided)
    for (const std::string& m : g) {
      if (m == label) return true;
      const size_t plus = m.find(" + "), mat = m.find(" at ");
      if (plus == std::string::npos || mat == std::string::npos || m.substr(mat) != where) continue;
      if (m.substr(0, plus) == effect || m.substr(plus + 3, mat - plus - 3) == effect) return true;
    }
  return false;
}

void CheckUnidentifiable(const PairOutcome& o) {
  EXPECT_TRUE(o.named.empty()) << o.what;
  ASSERT_EQ(o.r.report.undecided.size(), 1u) << o.what;
  const auto& g = o.r.report.undecided[0];
  for (const std::string& l : {o.la, o.lb}) EXPECT_TRUE(std::find(g.begin(), g.end(), l) != g.end()) << o.what;
}

void CheckBothNamed(const Pair& p) {
  const PairOutcome o = AuditPair(p);
  if (Unidentifiable(p)) return CheckUnidentifiable(o);
  EXPECT_TRUE(o.named.count(o.la)) << o.what;
  EXPECT_TRUE(o.named.count(o.lb)) << o.what;
  EXPECT_EQ(o.named.size(), 2u) << o.what << ": only the two hidden effects";
  EXPECT_TRUE(o.r.report.undecided.empty()) << o.what;
}

struct PairVerdict {
  bool both = false;     // both named at their cameras, nothing else (or, not identifiable: undecided)
  std::string broken;    // the weaker promise broken: how; empty when kept
};

// The weaker promise (see above), judged without failing the test.
PairVerdict JudgeNoWrongCause(const Pair& p) {
  const PairOutcome o = AuditPair(p);
  PairVerdict v;
  // What the final model leaves unexplained is in the text whenever it holds a term, also
  // when that is only an undecided group's.
  if (!o.r.report.effects.empty() || !o.r.report.undecided.empty()) {
    EXPECT_NE(o.r.report.Text().find("with the final model"), std::string::npos) << o.what;
  }
  // A principal point undecided between cameras: the note says why (the target's free poses).
  for (const auto& g : o.r.report.undecided)
    if (g.size() > 1 && g[0].rfind("principal_point at ", 0) == 0 && g[1].rfind("principal_point at ", 0) == 0) {
      bool said = false;
      for (const auto& n : o.r.report.notes)
        said = said || n.find("trade against each other through the target's free poses") != std::string::npos;
      EXPECT_TRUE(said) << o.what << ": why principal points of different cameras are undecided";
    }
  if (Unidentifiable(p)) {
    const auto& u = o.r.report.undecided;
    v.both = o.named.empty() && u.size() == 1 && std::find(u[0].begin(), u[0].end(), o.la) != u[0].end() &&
             std::find(u[0].begin(), u[0].end(), o.lb) != u[0].end();
    if (!v.both) v.broken = "not reported as one undecided group";
    return v;
  }
  v.both = o.named.count(o.la) && o.named.count(o.lb) && o.named.size() == 2 && o.r.report.undecided.empty();
  for (const std::string& n : o.named)
    if (n != o.la && n != o.lb) v.broken += "named " + n + ", not hidden; ";
  for (const Hidden* h : {&o.ha, &o.hb}) {
    const std::string& l = h == &o.ha ? o.la : o.lb;
    if (o.named.count(l) || InUndecidedGroup(o.r, l)) continue;
    // Taken up by a named move of its camera: the report must say so.
    const std::string where = l.substr(l.find(" at ") + 4);
    if ((h->name == "principal_point" || h->name == "focal_length") && o.named.count("camera_moved at " + where)) {
      bool said = false;
      for (const auto& n : o.r.report.notes) said = said || n.find("camera_moved at " + where + " also accounts") == 0;
      if (!said) v.broken += l + " taken up by the move, not said; ";
      continue;
    }
    // Missed: only where the audit of it alone, on the same noise, misses it too.
    const CameraAuditResult ra = Audit(Make({*h}, p.seed, p.cameras));
    for (const auto& e : ra.report.effects)
      if (e.name + " at " + e.where == l) v.broken += l + " missed beside the other effect, named alone; ";
  }
  if (!v.broken.empty()) v.broken = o.what + ": " + v.broken;
  return v;
}

class TwoEffects : public ::testing::TestWithParam<Pair> {};

TEST_P(TwoEffects, DISABLED_BothNamedAtTheirCamerasNothingElse) { CheckBothNamed(GetParam()); }
TEST_P(TwoEffects, DISABLED_NoWrongCause) {
  const PairVerdict v = JudgeNoWrongCause(GetParam());
  EXPECT_TRUE(v.broken.empty()) << v.broken;
}

// The weaker promise over every pair (see above): measured kept on 55 of 57 (the two
// broken: a k1 of a moved camera, its likelihood ratio beside the move 6.5; a principal
// point of 0.06 px in a 3-camera rig with a k1 elsewhere, undecided at the wrong camera).
// How many had both named is printed (issue 35 asks for all). On 120 frames
// (MCMS_AUDIT_FRAMES=120, 4 min): 57 of 57 kept, both named on 50 (docs/audits.md).
TEST(AuditCameras, TwoEffectsNeverAWrongCause) {
  int both = 0, kept = 0;
  const std::vector<Pair> pairs = AllPairs();
  std::string broken;
  for (const Pair& p : pairs) {
    const PairVerdict v = JudgeNoWrongCause(p);
    both += v.both ? 1 : 0;
    kept += v.broken.empty() ? 1 : 0;
    broken += v.broken.empty() ? "" : "  " + v.broken + "\n";
  }
  std::printf("no wrong cause: %d of %zu pairs; both named at their cameras, nothing else (or, not identifiable, "
              "undecided): %d\n%s",
              kept, pairs.size(), both, broken.c_str());
  EXPECT_GE(kept, 55) << broken;
}

// A move named while another camera's fault is still unmodelled gives way, once that fault is
// in, to its camera's simpler intrinsic explanation. Found on the pairs at 120 frames
// (MCMS_AUDIT_FRAMES=120): a focal length of cam0 beside a k1 of cam2 in a 3-camera rig was
// named camera_moved at cam0 (in round 1 the move's six parameters also took part of cam2's
// k1 through the shared poses: held-out gain 292.6 against the focal length's 279.2).
TEST(AuditCameras, AMoveNamedEarlyGivesWayToTheFocalLengthItStoodFor) {
  const uint64_t seed = 234;
  const Hidden f = Pick("focal_length", seed, 0), k1 = Pick("radial_distortion", seed + 1, 2);
  const Recording rec = Make({f, k1}, seed, 3, 120);
  const CameraAuditResult r = Audit(rec);
  std::printf("%s", r.report.Text().c_str());
  std::set<std::string> named;
  for (const auto& e : r.report.effects) named.insert(e.name + " at " + e.where);
  EXPECT_EQ(named, (std::set<std::string>{"focal_length at cam0", "radial_distortion at cam2"}));
  EXPECT_TRUE(r.report.undecided.empty());
  bool said = false;
  for (const auto& n : r.report.notes)
    said = said || (n.rfind("camera_moved at cam0 was selected", 0) == 0 &&
                    n.find("focal_length at cam0 explains the images as well") != std::string::npos);
  EXPECT_TRUE(said) << "the note on the move given way";
  for (const auto& e : r.report.effects)
    if (e.name == "focal_length") {
      ASSERT_EQ(e.parameters.size(), 1u);
      EXPECT_TRUE(std::isfinite(e.sigma[0].second));
      EXPECT_NEAR(e.parameters[0].second, f.p[0], SigmaBound(1) * e.sigma[0].second);
      EXPECT_GT(e.heldout_loglik_gain, 0);
      EXPECT_GT(e.bic_gain, 0);
    }
}

INSTANTIATE_TEST_SUITE_P(Catalog, TwoEffects, ::testing::ValuesIn(AllPairs()),
                         [](const ::testing::TestParamInfo<Pair>& i) { return PairName(i.param); });

}  // namespace
}  // namespace mcms
