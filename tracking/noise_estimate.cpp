#include "tracking/noise_estimate.h"

#include "core/statistics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>

#include "core/error.h"
#include "core/parallel.h"
#include "vision/image_file.h"

namespace mcms {

bool NoiseEstimateOptions::IsValid(std::string* why) const {
  if (frames < 1) return (*why = "frames must be >= 1", false);
  if (!(homogeneity_p > 0 && homogeneity_p < 1)) return (*why = "homogeneity_p must be in (0, 1)", false);
  return pixel.IsValid(why);
}

SequenceNoiseModel EstimateSequenceNoise(const ImageSequence& seq,
                                         const CameraRig& rig,
                                         const BlobDetectorOptions& detector,
                                         const NoiseEstimateOptions& options,
                                         int threads) {
  std::string why;
  if (!options.IsValid(&why)) Throw("noise estimate options: ", why);
  if (!detector.IsValid(&why)) Throw("noise estimate: invalid detector options: ", why);
  const size_t ncam = rig.size();
  const size_t n = seq.frames.size();
  std::vector<size_t> picks;
  const size_t k = std::min(options.frames, n);
  for (size_t i = 0; i < k; ++i) picks.push_back(k > 1 ? i * (n - 1) / (k - 1) : 0);

  std::vector<std::vector<std::vector<PixelNoiseSample>>> found(picks.size(), std::vector<std::vector<PixelNoiseSample>>(ncam));
  ParallelFor(picks.size(), threads, [&](size_t j) {
    std::vector<std::string> problems;
    const std::vector<cv::Mat> images = LoadFrameImages(seq, picks[j], &problems);
    for (size_t c = 0; c < ncam && c < images.size(); ++c) {
      if (images[c].empty()) continue;
      found[j][c] = MeasurePixelNoise(images[c], DetectBlobs(images[c], detector), options.pixel);
    }
  });

  SequenceNoiseModel m;
  m.cameras = rig.names;
  m.frames_used = picks.size();
  std::vector<PixelNoiseSample> all;
  for (size_t c = 0; c < ncam; ++c) {
    std::vector<PixelNoiseSample> mine;
    for (const auto& f : found) mine.insert(mine.end(), f[c].begin(), f[c].end());
    all.insert(all.end(), mine.begin(), mine.end());
    m.per_camera.push_back(EstimatePixelNoise(mine));
  }
  m.pooled = EstimatePixelNoise(all);
  int valid = 0;
  for (const auto& e : m.per_camera) {
    if (!e.valid()) continue;
    m.homogeneity_chi2 += std::pow((e.inv_gain - m.pooled.inv_gain) / e.inv_gain_sigma, 2);
    ++valid;
  }
  m.homogeneity_dof = std::max(valid - 1, 0);
  m.cameras_differ = m.homogeneity_dof > 0 &&
                     m.homogeneity_chi2 > ChiSquareQuantile(1 - options.homogeneity_p, m.homogeneity_dof);
  for (size_t c = 0; c < ncam; ++c) {
    const PixelNoiseEstimate& e = m.cameras_differ && m.per_camera[c].valid() ? m.per_camera[c] : m.pooled;
    m.gain_e_per_dn.push_back(e.valid() ? e.gain_e_per_dn : 0.0);
  }
  return m;
}

std::vector<std::string> SequenceNoiseModel::Describe() const {
  std::vector<std::string> lines;
  char buf[256];
  for (size_t c = 0; c < cameras.size(); ++c) lines.push_back("noise " + cameras[c] + ": " + per_camera[c].Describe());
  if (!pooled.valid()) {
    lines.push_back("noise model: photon noise LEFT OUT (gain 0): no usable blob in " + std::to_string(frames_used) +
                    " frames; the covariance is optimistic by the photon noise -- give --gain");
    return lines;
  }
  if (cameras_differ) {
    std::string g;
    for (size_t c = 0; c < cameras.size(); ++c) {
      std::snprintf(buf, sizeof(buf), "%s%s %.3g", g.empty() ? "" : ", ", cameras[c].c_str(), gain_e_per_dn[c]);
      g += buf;
    }
    std::snprintf(buf, sizeof(buf), " (the cameras differ: chi2 %.1f for %d dof)", homogeneity_chi2, homogeneity_dof);
    lines.push_back("noise model: per-camera gain e-/DN: " + g + buf);
  } else {
    std::snprintf(buf, sizeof(buf), "noise model: one gain for every camera, %s", pooled.Describe().c_str());
    std::string s = buf;
    if (homogeneity_dof > 0) {
      std::snprintf(buf, sizeof(buf), " (the cameras agree: chi2 %.1f for %d dof)", homogeneity_chi2, homogeneity_dof);
      s += buf;
    }
    lines.push_back(s);
  }
  lines.push_back("noise model: background noise measured around every blob; estimated from " +
                  std::to_string(frames_used) + " frames");
  return lines;
}

void PoseResidualCheck::Add(const FrameResult& f) {
  if (!f.T_rig_target) return;
  const int d = 2 * f.observations - 6;
  if (d <= 0) return;
  ++frames;
  dof += d;
  chi2 += f.chi2_per_dof * d;
}

void PoseResidualCheck::Finish() {
  if (dof > 0) {
    band_lo = ChiSquareQuantile(0.025, dof) / dof;
    band_hi = ChiSquareQuantile(0.975, dof) / dof;
  }
}

PoseResidualCheck CheckPoseResiduals(const std::vector<FrameResult>& results) {
  PoseResidualCheck r;
  for (const FrameResult& f : results) r.Add(f);
  r.Finish();
  return r;
}

std::string PoseResidualCheck::Describe() const {
  if (dof <= 0) return "pose-fit residuals: no frame with redundant observations";
  char buf[320];
  std::snprintf(buf, sizeof(buf), "pose-fit residuals: chi2/dof %.3f over %d dof in %d frames (95 %% band %.3f-%.3f)%s",
                Chi2PerDof(), dof, frames, band_lo, band_hi,
                InBand()        ? ": the noise model explains them"
                : Optimistic()  ? ": LARGER than the noise model predicts, the covariance is optimistic "
                                  "(noise model or camera model; try mcms audit)"
                : Chi2PerDof() > band_hi ? ": the noise model explains them within the model tolerance"
                                : ": smaller than the noise model predicts, the covariance is conservative");
  return buf;
}

}  // namespace mcms

namespace mcms {

void RecordingTrackerSettings::Check() const {
  if (gain_e_per_dn && !(*gain_e_per_dn == 0 || (*gain_e_per_dn >= kMinGainEPerDn && *gain_e_per_dn <= kMaxGainEPerDn)))
    Throw("--gain (gain_e_per_dn) ", *gain_e_per_dn, " e-/DN: expected 0 (no photon noise) or a camera's gain, ",
          kMinGainEPerDn, " to ", kMaxGainEPerDn, " e-/DN");
  if (!(read_noise_dn >= 0 && std::isfinite(read_noise_dn)))
    Throw("read_noise_dn: expected a number >= 0, got ", read_noise_dn);
  if (!(threshold_dn >= 0 && std::isfinite(threshold_dn)))
    Throw("threshold_dn: expected a number >= 0, got ", threshold_dn);
  if (noise_frames < 1) Throw("noise_frames: expected >= 1, got ", noise_frames);
  if (threads < 1) Throw("threads: expected >= 1, got ", threads);
}

TrackerOptions RecordingTrackerSettings::Options(const ImageSequence& seq, const CameraRig& rig,
                                                 std::vector<std::string>* notes) const {
  Check();
  // The levels the images hold (the first image found): a threshold at or beyond the
  // largest, or a read noise whose 3 sigma spans it, leaves no blob to detect. Looked at
  // only when either is given, and in the first frames only (no scan of a long sequence
  // whose images cannot be read: the tracker names those frame by frame).
  const bool given = threshold_dn > 0 || read_noise_dn > 0;
  for (size_t i = 0; given && i < std::min<size_t>(seq.frames.size(), 10); ++i) {
    bool found = false;
    for (size_t c = 0; c < seq.cameras() && !found; ++c) {
      const std::filesystem::path p = seq.ImagePath(i, c);
      if (p.empty()) continue;
      std::string problem;
      const cv::Mat im = ReadImageFile(p, {}, &problem);
      if (im.empty()) continue;
      found = true;
      const double top = im.depth() == CV_8U ? 255.0 : 65535.0;
      const char* bits = im.depth() == CV_8U ? "8-bit" : "16-bit";
      if (threshold_dn >= top)
        Throw("--threshold ", threshold_dn, " DN is at or beyond the largest level of the images (", top, ": ", bits,
              ", e.g. ", p.string(), "): no blob can pass it");
      if (3 * read_noise_dn >= top)
        Throw("--read-noise ", read_noise_dn, " DN: three times it spans the images' whole range (0 to ", top, ": ",
              bits, ", e.g. ", p.string(), "): no blob could be told from the background");
    }
    if (found) break;
  }
  TrackerOptions o;
  o.detector.read_noise_dn = read_noise_dn;
  o.detector.polarity = polarity;
  o.detector.threshold_dn = threshold_dn;
  o.predicted_windows = predicted_windows;
  char buf[160];
  if (gain_e_per_dn) {
    o.detector.gain_e_per_dn = *gain_e_per_dn;
    std::snprintf(buf, sizeof(buf), "noise model: gain %.4g e-/DN for every camera (--gain)%s", *gain_e_per_dn,
                  *gain_e_per_dn > 0 ? "" : ": photon noise left out");
    notes->push_back(buf);
  } else {
    NoiseEstimateOptions no;
    no.frames = noise_frames;
    const SequenceNoiseModel m = EstimateSequenceNoise(seq, rig, o.detector, no, threads);
    o.camera_gain_e_per_dn = m.gain_e_per_dn;
    for (const auto& line : m.Describe()) notes->push_back(line);
  }
  if (read_noise_dn > 0) {
    std::snprintf(buf, sizeof(buf), "noise model: background pixel noise %.4g DN (--read-noise)", read_noise_dn);
    notes->push_back(buf);
  }
  return o;
}

}  // namespace mcms
