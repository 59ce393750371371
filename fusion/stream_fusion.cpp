#include "fusion/stream_fusion.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <tuple>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include "core/error.h"
#include "core/statistics.h"

namespace mcms {

namespace {

std::string Range(const std::filesystem::path& file, double first, double last) {
  char b[96];
  std::snprintf(b, sizeof b, " covers [%.6g, %.6g] s", first, last);
  return file.string() + b;
}

// Index range [first, last) of the samples with lo <= time_s < hi (hi_inclusive: <= hi).
template <typename Sample>
std::pair<size_t, size_t> InTime(const std::vector<Sample>& v, double lo, double hi, bool hi_inclusive) {
  const auto a = std::lower_bound(v.begin(), v.end(), lo, [](const Sample& s, double x) { return s.time_s < x; });
  auto b = a;
  while (b != v.end() && (b->time_s < hi || (hi_inclusive && b->time_s == hi))) ++b;
  return {static_cast<size_t>(a - v.begin()), static_cast<size_t>(b - v.begin())};
}

// Rejected readings of one row: count and the largest |reading - bias| among them.
struct RangeRejects {
  int count = 0;
  double worst_rad = 0.0;
  void Add(const Vec2& reading, const Inclinometer& model) {
    ++count;
    worst_rad = std::max(worst_rad, (reading - model.bias).cwiseAbs().maxCoeff());
  }
  std::string Text(const Inclinometer& model) const {
    char b[160];
    std::snprintf(b, sizeof b, "inclinometer: %d reading%s beyond its range rejected (%.2f deg > %.2f deg)", count,
                  count == 1 ? "" : "s", worst_rad * 180.0 / kPi, model.range * 180.0 / kPi);
    return b;
  }
  static constexpr double kPi = std::numbers::pi;
};

// Readings left out because the other sensors' orientation tilts the inclinometer beyond its
// range (by up to `worst_rad`), where it cannot read and its model cannot be linearized.
std::string OutOfViewText(int count, double worst_rad, const Inclinometer& model) {
  constexpr double kPi = std::numbers::pi;
  char b[256];
  std::snprintf(b, sizeof b,
                "inclinometer: %d reading%s not used: the other sensors' orientation tilts it %.2f deg, beyond its "
                "range %.2f deg (is the setup's inclinometer mount right?)",
                count, count == 1 ? "" : "s", worst_rad * 180.0 / kPi, model.range * 180.0 / kPi);
  return b;
}

// The mean of the inclinometer readings in [lo, hi] (or [lo, hi)) that are not beyond the
// sensor's range, and the model with the noise of that mean (sigma / sqrt(n)). nullopt when
// there is none.
std::optional<TiltReading> MeanTilt(const InclinometerLog& log, double lo, double hi, bool hi_inclusive,
                                    const Inclinometer& model, int* count, RangeRejects* rejects) {
  const auto [a, b] = InTime(log.samples, lo, hi, hi_inclusive);
  Vec2 sum = Vec2::Zero();
  int n = 0;
  for (size_t i = a; i < b; ++i) {
    if (rejects && BeyondRange(log.samples[i].reading, model)) {
      rejects->Add(log.samples[i].reading, model);
      continue;
    }
    sum += log.samples[i].reading;
    ++n;
  }
  *count = n;
  if (n == 0) return std::nullopt;
  TiltReading r;
  r.reading = sum / static_cast<double>(n);
  r.model = model;
  r.model.sigma = model.sigma / std::sqrt(static_cast<double>(n));
  return r;
}

std::string Joined(const std::string& a, const std::string& b) {
  return a.empty() ? b : b.empty() ? a : a + "; " + b;
}

FusedSample MoifaSample(int frame, double time_s, const EpochFusion& e) {
  FusedSample r;
  r.frame = frame;
  r.time_s = time_s;
  r.method = FusionMethod::kMoifa;
  r.T_base_flange = e.fused.T;
  r.covariance = e.fused.covariance;
  for (const auto& m : e.measurements) r.sensors.push_back(m.name);
  r.dof = e.consistency.dof;
  r.p_value = e.consistency.p_value;
  for (const auto& sc : e.consistency.sensors) {
    if (sc.flagged) r.flagged.push_back(sc.name);
    if (std::find(r.sensors.begin(), r.sensors.end(), sc.name) != r.sensors.end())
      r.statistics.push_back({sc.name, sc.nis, sc.dof});
  }
  r.excluded = e.excluded;
  r.fault = e.fault;
  return r;
}

// Notes inclinometer readings rejected as beyond range in a MOIFA row.
void NoteRangeRejects(const RangeRejects& rejects, bool none_left, const Inclinometer& model, FusedSample* r) {
  if (rejects.count == 0) return;
  if (none_left && std::find(r->excluded.begin(), r->excluded.end(), "inclinometer") == r->excluded.end())
    r->excluded.push_back("inclinometer");
  r->fault = Joined(rejects.Text(model), r->fault);
}

std::string Num(double v, int digits = 3) {
  char b[40];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

// The time-merged sample stream: robot, inclinometer, camera at equal stamps.
struct Event {
  double t;
  StreamSensor kind;
  size_t index;
};

std::vector<Event> MergedEvents(const SensorLogs& logs, double t_end) {
  std::vector<Event> events;
  for (size_t i = 0; i < logs.tracker.samples.size(); ++i)
    events.push_back({logs.tracker.samples[i].time_s, StreamSensor::kCamera, i});
  if (logs.robot)
    for (size_t i = 0; i < logs.robot->samples.size(); ++i)
      if (logs.robot->samples[i].time_s <= t_end)
        events.push_back({logs.robot->samples[i].time_s, StreamSensor::kRobot, i});
  if (logs.inclinometer)
    for (size_t i = 0; i < logs.inclinometer->samples.size(); ++i)
      if (logs.inclinometer->samples[i].time_s <= t_end)
        events.push_back({logs.inclinometer->samples[i].time_s, StreamSensor::kInclinometer, i});
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.t < b.t || (a.t == b.t && a.kind < b.kind); });
  return events;
}

// The KF's per-update gate probability: the setup's, or 1 - significance / updates_per_row.
PoseKalmanOptions GatedOptions(const FusionSetup& setup, double updates_per_row) {
  PoseKalmanOptions o = setup.kalman;
  if (o.nis_gate_probability <= 0 && setup.exclude_faults)
    o.nis_gate_probability = 1.0 - setup.consistency_significance / std::max(1.0, updates_per_row);
  if (!(o.nis_gate_probability < 1.0)) o.nis_gate_probability = 0.0;  // a significance too small to gate
  return o;
}

// One Kalman filter over a run of events, with the per-sensor innovation statistics since
// the last reported sample, the gated (rejected) updates and the restarts.
class KalmanRun {
 public:
  KalmanRun(const SensorLogs& logs, const FusionSetup& setup, double robot_accuracy_scale, double updates_per_row)
      : logs_(logs), setup_(setup), kf_(GatedOptions(setup, updates_per_row)), accuracy_scale_(robot_accuracy_scale) {}

  void Process(const Event& e) {
    const int k = static_cast<int>(e.kind);
    if (e.kind == StreamSensor::kInclinometer) {
      const Vec2& reading = logs_.inclinometer->samples[e.index].reading;
      if (setup_.exclude_faults && BeyondRange(reading, setup_.inclinometer)) {
        range_.Add(reading, setup_.inclinometer);
        return;
      }
      // Needs an orientation to linearize at, and one the sensor can read.
      if (!kf_.Initialized()) return;
      const Mat3 R = kf_.Predict(e.t).T.R;
      if (!setup_.inclinometer.InRange(R)) {
        ++out_of_view_.count;
        out_of_view_.worst_rad = std::max(out_of_view_.worst_rad, setup_.inclinometer.Tilt(R).cwiseAbs().maxCoeff());
        return;
      }
      Note(k, kf_.UpdateInclinometer(e.t, reading, setup_.inclinometer));
      return;
    }
    PoseWithCovariance m;
    if (e.kind == StreamSensor::kRobot) {
      m = RobotFlangePose(logs_.robot->samples[e.index].q, setup_, 1.0, accuracy_scale_);
    } else {
      const TrackerSample& s = logs_.tracker.samples[e.index];
      m = CameraFlangePose(s.T_rig_target, s.covariance, setup_);
    }
    if (!kf_.Initialized()) {
      kf_.Initialize(e.t, m.T, m.covariance);
      used_[k] = true;
      start_ = {k, e.t, true};
      return;
    }
    if (left_out_[k] && start_.alone) {
      // A sensor left out at a restart is not let back in while the restarted state rests on
      // one sample alone: its unknown velocity would let the odd one in and pull the state back.
      const PoseKalmanFilter::Prediction p = kf_.Predict(e.t);
      const Vec6 b = BoxMinus(m.T, p.T);
      PoseKalmanFilter::UpdateResult held;
      held.accepted = false;
      held.dof = 6;
      held.nis = b.dot((p.covariance + m.covariance).ldlt().solve(b));
      Note(k, held);
      return;
    }
    const PoseKalmanFilter::UpdateResult u = kf_.UpdatePose(e.t, m.T, m.covariance);
    Note(k, u);
    if (!u.accepted && setup_.exclude_faults && !left_out_[k] && StateIsTheOutlier()) {
      // Two sensors keep disagreeing with the state, not necessarily with each other:
      // start again from this measurement.
      std::string who;
      for (int j = 0; j < 3; ++j)
        if (streak_[j] >= 2 && !left_out_[j]) who += (who.empty() ? "" : " and ") + std::string(ToString(static_cast<StreamSensor>(j)));
      std::string text = "filter restarted at " + Num(e.t, 9) + " s: " + who + " kept contradicting its state";
      if (start_.alone && start_.kind != k) {
        // The state was that one sample and nothing since vouched for it: it was the fault.
        // (Contradicted by the next sample of its own sensor, it is as likely the motion since.)
        const std::string name = ToString(static_cast<StreamSensor>(start_.kind));
        text += " (which came from one " + name + " sample at " + Num(start_.t, 9) + " s alone: left out)";
        restart_culprits_.push_back(name);
        left_out_[start_.kind] = true;
        used_[start_.kind] = false;
      } else {
        // A full-pose sensor that kept agreeing with the state while two others contradicted
        // it is the one the state followed: it is the odd one out (a frozen joint log).
        for (const StreamSensor kind : {StreamSensor::kRobot, StreamSensor::kCamera}) {
          const int j = static_cast<int>(kind);
          if (streak_[j] > 0 || agreed_while_contradicted_[j] == 0) continue;
          const std::string name = ToString(kind);
          text += " (which followed the " + name + " alone, " + std::to_string(agreed_while_contradicted_[j]) +
                  " of its updates agreeing meanwhile: left out)";
          restart_culprits_.push_back(name);
          left_out_[j] = true;
          used_[j] = false;
        }
      }
      restart_text_ = Joined(restart_text_, text);
      kf_.Initialize(e.t, m.T, m.covariance);
      used_[k] = true;
      start_ = {k, e.t, true};
      for (int& c : streak_) c = 0;
      for (int& c : agreed_while_contradicted_) c = 0;
    }
  }

  bool Initialized() const { return kf_.Initialized(); }
  const PoseKalmanFilter& Filter() const { return kf_; }

  // A sample with the given estimate and the statistics since the last one (then reset).
  FusedSample Report(int frame, double time_s, const Pose& T, const Mat6& covariance) {
    FusedSample r;
    r.frame = frame;
    r.time_s = time_s;
    r.method = FusionMethod::kKalman;
    r.T_base_flange = T;
    r.covariance = covariance;
    double total = 0.0;
    // Camera first, as in the MOIFA rows.
    for (const StreamSensor kind : {StreamSensor::kCamera, StreamSensor::kRobot, StreamSensor::kInclinometer}) {
      const int k = static_cast<int>(kind);
      if (used_[k]) {
        r.sensors.push_back(ToString(kind));
        r.statistics.push_back({ToString(kind), nis_[k], dof_[k]});
      }
    }
    for (const StreamSensor kind : {StreamSensor::kRobot, StreamSensor::kInclinometer, StreamSensor::kCamera}) {
      const int k = static_cast<int>(kind);
      total += nis_[k];
      r.dof += dof_[k];
      if ((dof_[k] > 0 && ChiSquareSurvival(nis_[k], dof_[k]) < setup_.consistency_significance) ||
          rejected_[k].count > 0)
        r.flagged.push_back(ToString(kind));
    }
    r.p_value = r.dof > 0 ? ChiSquareSurvival(total, r.dof) : 1.0;
    for (const StreamSensor kind : {StreamSensor::kCamera, StreamSensor::kRobot, StreamSensor::kInclinometer}) {
      const Rejected& x = rejected_[static_cast<int>(kind)];
      if (x.count == 0) continue;
      r.excluded.push_back(ToString(kind));
      const double gate = ChiSquareQuantile(kf_.Options().nis_gate_probability, x.dof);
      r.fault = Joined(r.fault, std::string(ToString(kind)) + ": " + std::to_string(x.count) + " of " +
                                    std::to_string(x.count + x.accepted) + " update" +
                                    (x.count + x.accepted == 1 ? "" : "s") + " rejected (NIS up to " + Num(x.max_nis) +
                                    " > gate " + Num(gate) + " on " + std::to_string(x.dof) + " dof)");
    }
    if (range_.count > 0) {
      if (std::find(r.excluded.begin(), r.excluded.end(), "inclinometer") == r.excluded.end())
        r.excluded.push_back("inclinometer");
      r.fault = Joined(r.fault, range_.Text(setup_.inclinometer));
    }
    if (out_of_view_.count > 0) {
      if (std::find(r.excluded.begin(), r.excluded.end(), "inclinometer") == r.excluded.end())
        r.excluded.push_back("inclinometer");
      r.fault = Joined(r.fault, OutOfViewText(out_of_view_.count, out_of_view_.worst_rad, setup_.inclinometer));
    }
    for (const std::string& name : restart_culprits_)
      if (std::find(r.excluded.begin(), r.excluded.end(), name) == r.excluded.end()) r.excluded.push_back(name);
    r.fault = Joined(r.fault, restart_text_);
    for (int k = 0; k < 3; ++k) {
      nis_[k] = 0;
      dof_[k] = 0;
      used_[k] = false;
      rejected_[k] = Rejected{};
    }
    range_ = RangeRejects{};
    out_of_view_ = RangeRejects{};
    restart_text_.clear();
    restart_culprits_.clear();
    return r;
  }

 private:
  struct Rejected {
    int count = 0, accepted = 0, dof = 0;
    double max_nis = 0.0;
  };

  void Note(int k, const PoseKalmanFilter::UpdateResult& u) {
    if (u.accepted) {
      used_[k] = true;
      nis_[k] += u.nis;
      dof_[k] += u.dof;
      ++rejected_[k].accepted;
      // A sensor's streak ends when it agrees again; another sensor agreeing does not end it
      // (the state may be following that one). An accepted full pose vouches for the state's
      // start; a tilt alone does not (no position).
      streak_[k] = 0;
      left_out_[k] = false;
      if (std::any_of(std::begin(streak_), std::end(streak_), [](int c) { return c > 0; }))
        ++agreed_while_contradicted_[k];
      else
        for (int& c : agreed_while_contradicted_) c = 0;
      if (k != static_cast<int>(StreamSensor::kInclinometer)) start_.alone = false;
    } else {
      Rejected& x = rejected_[k];
      ++x.count;
      x.dof = u.dof;
      x.max_nis = std::max(x.max_nis, u.nis);
      ++streak_[k];
    }
  }

  // Two sensors keep contradicting the state, each at least twice running (one chance
  // rejection beside a faulty sensor is not enough); a sensor left out at a restart (and not
  // agreeing since) is no witness: its disagreement is expected.
  bool StateIsTheOutlier() const {
    int sensors = 0;
    for (int j = 0; j < 3; ++j) sensors += !left_out_[j] && streak_[j] >= 2 ? 1 : 0;
    return sensors >= 2;
  }

  const SensorLogs& logs_;
  const FusionSetup& setup_;
  PoseKalmanFilter kf_;
  double accuracy_scale_;
  double nis_[3] = {0, 0, 0};
  int dof_[3] = {0, 0, 0};
  bool used_[3] = {false, false, false};
  Rejected rejected_[3];
  int streak_[3] = {0, 0, 0};  // rejections per sensor since its last accepted update
  int agreed_while_contradicted_[3] = {0, 0, 0};  // accepted while another's streak ran
  bool left_out_[3] = {false, false, false};       // named at a restart, not accepted since
  RangeRejects range_;
  RangeRejects out_of_view_;  // readings at orientations that tilt the sensor beyond its range
  struct Start {
    int kind = 0;
    double t = 0.0;
    bool alone = false;  // no full-pose update accepted since
  } start_;
  std::string restart_text_;
  std::vector<std::string> restart_culprits_;
};

// The time span of every log together: its first and last sample.
std::pair<double, double> LogsSpan(const SensorLogs& logs) {
  double a = logs.tracker.samples.front().time_s, b = logs.tracker.samples.back().time_s;
  if (logs.robot)
    a = std::min(a, logs.robot->samples.front().time_s), b = std::max(b, logs.robot->samples.back().time_s);
  if (logs.inclinometer)
    a = std::min(a, logs.inclinometer->samples.front().time_s),
    b = std::max(b, logs.inclinometer->samples.back().time_s);
  return {a, b};
}

void CheckInputs(const SensorLogs& logs, const std::vector<FusionWindow>& windows) {
  CheckTimeOverlap(logs);
  CheckWindows(windows);
  // A window that holds no sample of any log is a window for other logs (or in other
  // units): it must not quietly vanish from the output.
  const auto [a, b] = LogsSpan(logs);
  const auto holds = [](const auto& samples, const FusionWindow& w) {
    const auto it = std::lower_bound(samples.begin(), samples.end(), w.start_s,
                                     [](const auto& s, double t) { return s.time_s < t; });
    return it != samples.end() && it->time_s < w.end_s;
  };
  for (size_t i = 0; i < windows.size(); ++i) {
    const FusionWindow& w = windows[i];
    if (!holds(logs.tracker.samples, w) && !(logs.robot && holds(logs.robot->samples, w)) &&
        !(logs.inclinometer && holds(logs.inclinometer->samples, w)))
      Throw("fusion window ", i, " [", w.start_s, ", ", w.end_s, ") s holds no sample of any log: the logs span ", a,
            " to ", b, " s (check the windows' clock and units)");
    // A window reaching beyond the logs by more than their whole span is on another clock
    // or in other units (the filter would predict to its end, 1e308 s say).
    const double span = b - a;
    if (w.start_s < a - span || w.end_s > b + span)
      Throw("fusion window ", i, " [", w.start_s, ", ", w.end_s, ") s reaches far beyond the logs: the logs span ", a,
            " to ", b, " s (check the windows' clock and units)");
  }
}

}  // namespace

const char* ToString(StreamSensor k) {
  switch (k) {
    case StreamSensor::kRobot:
      return "robot";
    case StreamSensor::kInclinometer:
      return "inclinometer";
    case StreamSensor::kCamera:
      return "camera";
  }
  return "?";
}

const char* ToString(FusionMethod m) {
  return m == FusionMethod::kMoifa ? "moifa" : "kf";
}

void CheckTimeOverlap(const SensorLogs& logs) {
  if (!logs.robot && !logs.inclinometer)
    Throw("fusion needs the tracker log and at least one other sensor log (robot joints or inclinometer)");
  const TrackerLog& tr = logs.tracker;
  if (tr.samples.empty()) Throw("fusion: the tracker log ", tr.source.string(), " has no tracked frame");
  const double a0 = tr.samples.front().time_s, a1 = tr.samples.back().time_s;
  const auto check = [&](const std::filesystem::path& file, const auto& samples) {
    const double b0 = samples.front().time_s, b1 = samples.back().time_s;
    if (std::max(a0, b0) > std::min(a1, b1))
      Throw("no time overlap between the sensors: ", Range(tr.source, a0, a1), " (tracked frames), ",
            Range(file, b0, b1), " (are the logs on the same clock, in seconds?)");
    // Times in ms in one log: it spans about 1000 times as long as the other, which then
    // holds all its samples within two of the longer one's (a robot logged longer than the
    // cameras ran still has many samples while they ran).
    const auto within = [](const auto& in, double t0, double t1) {
      int n = 0;
      for (const auto& x : in) n += x.time_s >= t0 && x.time_s <= t1;
      return n;
    };
    const double span = (b1 - b0) / (a1 - a0);
    const bool file_longer = span > 300 && span < 3000 && tr.samples.size() >= 10 && within(samples, a0, a1) <= 2;
    const bool tracker_longer = 1 / span > 300 && 1 / span < 3000 && samples.size() >= 10 &&
                                within(tr.samples, b0, b1) <= 2;
    if (file_longer || tracker_longer)
      Throw(file_longer ? file.string() : tr.source.string(), ": its times span ",
            std::lround(file_longer ? span : 1 / span), " times as long as those of ",
            file_longer ? tr.source.string() : file.string(),
            ", which all fall between two of its samples: are its times in ms? expected time_s in seconds on the "
            "same clock");
  };
  if (logs.robot) {
    if (logs.robot->samples.empty()) Throw("fusion: the joint log ", logs.robot->source.string(), " is empty");
    check(logs.robot->source, logs.robot->samples);
  }
  if (logs.inclinometer) {
    if (logs.inclinometer->samples.empty())
      Throw("fusion: the inclinometer log ", logs.inclinometer->source.string(), " is empty");
    check(logs.inclinometer->source, logs.inclinometer->samples);
  }
}

void CheckWindows(const std::vector<FusionWindow>& windows) {
  for (size_t i = 0; i < windows.size(); ++i) {
    const FusionWindow& w = windows[i];
    if (!std::isfinite(w.start_s) || !std::isfinite(w.end_s) || !(w.end_s > w.start_s))
      Throw("fusion window ", i, ": expected finite start_s < end_s, got [", w.start_s, ", ", w.end_s, ")");
    if (i > 0 && w.start_s < windows[i - 1].end_s)
      Throw("fusion window ", i, " [", w.start_s, ", ", w.end_s, ") starts before window ", i - 1, " ends (",
            windows[i - 1].end_s, " s); windows must be in time order and must not overlap");
  }
}

PoseWithCovariance CameraFlangePose(const Pose& T_rig_target, const Mat6& covariance_rig, const FusionSetup& setup) {
  return CameraFlangePose(CellGeometry{setup.T_base_rig, setup.T_base_rig_covariance, setup.T_flange_target},
                          T_rig_target, covariance_rig);
}

PoseWithCovariance RobotFlangePose(const Eigen::VectorXd& q, const FusionSetup& setup, double encoder_scale,
                                   double accuracy_scale) {
  // The setup's robot ends at the fusion's flange (fusion/sensor_logs.h: its tool frame).
  const PoseWithCovariance out =
      RobotFlangePose(setup.robot, q, encoder_scale * setup.robot.EncoderCovariance(),
                      accuracy_scale * setup.robot_accuracy_covariance, RobotModel::EndFrame::kTool);
  if (out.covariance.llt().info() != Eigen::Success || !(out.covariance.diagonal().minCoeff() > 0))
    Throw("robot '", setup.robot.Name(),
          "': its pose covariance is singular; give encoder sigmas in the robot file or ",
          "robot_accuracy in the setup file ", setup.source.string());
  return out;
}

namespace {

EpochFusion FusePlain(const std::vector<PoseMeasurement>& poses, const std::optional<TiltReading>& tilt,
                      const ConsistencyOptions& options) {
  EpochFusion e;
  e.measurements = poses;
  e.fused = FusePoses(poses);
  if (tilt) {
    // Linearize at the other sensors' fused orientation, then once more at the result:
    // the constraint is first order in the orientation error.
    for (int pass = 0; pass < 2; ++pass) {
      if (!tilt->model.InRange(e.fused.T.R)) break;
      e.measurements = poses;
      e.measurements.push_back(
          PoseMeasurement::FromOrientation("inclinometer", tilt->model.Constraint(tilt->reading, e.fused.T.R)));
      e.fused = FusePoses(e.measurements);
    }
  }
  e.consistency = CheckConsistency(e.measurements, options);
  return e;
}

}  // namespace

Mat6 CovarianceUnion(const Mat6& A, const Mat6& B) {
  // B v = l A v with V^T A V = I: A = V^-T V^-1, B = V^-T diag(l) V^-1.
  const Eigen::GeneralizedSelfAdjointEigenSolver<Mat6> g(0.5 * (B + B.transpose()), 0.5 * (A + A.transpose()));
  if (g.info() != Eigen::Success) Throw("CovarianceUnion: the covariances must be symmetric positive definite");
  const Mat6 Vinv = g.eigenvectors().inverse();
  const Vec6 l = g.eigenvalues().cwiseMax(1.0);
  const Mat6 U = Vinv.transpose() * l.asDiagonal() * Vinv;
  return 0.5 * (U + U.transpose());
}

bool BeyondRange(const Vec2& reading, const Inclinometer& model) {
  const Vec2 d = reading - model.bias;
  const double limit = model.range + 5.0 * model.sigma;
  return !(std::abs(d.x()) <= limit && std::abs(d.y()) <= limit);  // NaN is beyond too
}

namespace {

EpochFusion FuseEpochAll(const std::vector<PoseMeasurement>& poses, const std::optional<TiltReading>& tilt,
                         const ConsistencyOptions& options, bool exclude_faults) {
  EpochFusion e = FusePlain(poses, tilt, options);
  if (e.consistency.consistent || !exclude_faults) return e;

  // Leave one out: which sensor's removal makes the rest consistent?
  struct Suspect {
    size_t index;
    EpochFusion rest;
  };
  std::vector<Suspect> suspects;
  const size_t n = e.measurements.size();
  for (size_t i = 0; i < n; ++i) {
    if (e.consistency.sensors[i].dof == 0) continue;  // nothing to compare it with
    EpochFusion rest;
    if (i < poses.size()) {
      if (poses.size() == 1) continue;  // the inclinometer alone cannot be fused
      std::vector<PoseMeasurement> others = poses;
      others.erase(others.begin() + static_cast<std::ptrdiff_t>(i));
      rest = FusePlain(others, tilt, options);
    } else {
      rest = FusePlain(poses, std::nullopt, options);
    }
    if (rest.consistency.consistent) suspects.push_back({i, std::move(rest)});
  }
  // Prefer those whose own residual against the others fails too.
  std::vector<const Suspect*> chosen;
  for (const Suspect& s : suspects)
    if (e.consistency.sensors[s.index].flagged) chosen.push_back(&s);
  if (chosen.empty())
    for (const Suspect& s : suspects) chosen.push_back(&s);

  const auto own = [&](size_t i) {
    const SensorConsistency& c = e.consistency.sensors[i];
    return "NIS " + Num(c.nis) + " on " + std::to_string(c.dof) + " dof against the others (p " + Num(c.p_value) + ")";
  };
  const std::string failed =
      "consistency test failed (p " + Num(e.consistency.p_value) + " < " + Num(options.significance) + ")";
  if (chosen.size() == 1) {
    const Suspect& s = *chosen.front();
    const std::string name = e.measurements[s.index].name;
    EpochFusion out = s.rest;
    out.consistency = e.consistency;
    out.excluded = {name};
    out.fault = name + " excluded: " + own(s.index) + "; the rest agree (p " + Num(s.rest.consistency.p_value) + ")";
    return out;
  }
  if (chosen.size() >= 2) {
    // Either suspect may be the wrong one: keep the fusion of all and widen its covariance
    // to cover each hypothesis.
    Mat6 U = e.fused.covariance;
    std::string names;
    for (const Suspect* s : chosen) {
      const Vec6 d = BoxMinus(s->rest.fused.T, e.fused.T);
      U = CovarianceUnion(U, Mat6(s->rest.fused.covariance + d * d.transpose()));
      names += (names.empty() ? "" : " or ") + e.measurements[s->index].name;
    }
    e.fused.covariance = U;
    e.fault = failed + ": " + names +
              " may be wrong (leaving out either makes the rest agree); kept all and "
              "widened the covariance to cover each";
    return e;
  }
  const double scale = e.consistency.chi2 / std::max(1, e.consistency.dof);
  e.fused.covariance *= std::max(1.0, scale);
  e.fault = failed + ": no single sensor explains it; covariance scaled by chi2/dof " + Num(scale);
  return e;
}

}  // namespace

EpochFusion FuseEpoch(const std::vector<PoseMeasurement>& poses, const std::optional<TiltReading>& tilt,
                      const ConsistencyOptions& options, bool exclude_faults) {
  if (poses.empty()) Throw("FuseEpoch: expected at least one full-pose measurement (camera or robot), got none");
  EpochFusion e = FuseEpochAll(poses, tilt, options, exclude_faults);
  const auto named = [](const std::vector<std::string>& v) {
    return std::find(v.begin(), v.end(), "inclinometer") != v.end();
  };
  std::vector<std::string> used;
  for (const PoseMeasurement& m : e.measurements) used.push_back(m.name);
  if (tilt && !named(used) && !named(e.excluded)) {
    // Never a sensor silently gone: the others put it where it cannot read.
    e.excluded.push_back("inclinometer");
    e.fault = Joined(OutOfViewText(1, tilt->model.Tilt(e.fused.T.R).cwiseAbs().maxCoeff(), tilt->model), e.fault);
  }
  return e;
}

WindowMeasurements MeasureWindow(const SensorLogs& logs, const FusionSetup& setup, const FusionWindow& window) {
  WindowMeasurements m;
  const auto [c0, c1] = InTime(logs.tracker.samples, window.start_s, window.end_s, false);
  m.camera_frames = static_cast<int>(c1 - c0);
  if (c1 > c0) {
    std::vector<PoseMeasurement> frames;
    for (size_t i = c0; i < c1; ++i) {
      const TrackerSample& s = logs.tracker.samples[i];
      const PoseWithCovariance c = CameraFlangePose(s.T_rig_target, s.covariance, setup);
      frames.push_back(PoseMeasurement::FromCovariance("camera frame " + std::to_string(s.frame), c.T, c.covariance));
    }
    const FusedPose f = FusePoses(frames);
    m.camera = PoseWithCovariance{f.T, f.covariance};
  }
  if (logs.robot) {
    const auto [r0, r1] = InTime(logs.robot->samples, window.start_s, window.end_s, false);
    m.robot_readings = static_cast<int>(r1 - r0);
    if (r1 > r0) {
      Eigen::VectorXd sum = Eigen::VectorXd::Zero(setup.robot.NumJoints());
      for (size_t i = r0; i < r1; ++i) sum += logs.robot->samples[i].q;
      const double n = static_cast<double>(r1 - r0);
      m.robot = RobotFlangePose(Eigen::VectorXd(sum / n), setup, 1.0 / n, 1.0);
    }
  }
  if (logs.inclinometer) {
    RangeRejects rejects;
    m.inclinometer = MeanTilt(*logs.inclinometer, window.start_s, window.end_s, false, setup.inclinometer,
                              &m.inclinometer_readings, setup.exclude_faults ? &rejects : nullptr);
    m.inclinometer_beyond_range = rejects.count;
    m.inclinometer_worst_rad = rejects.worst_rad;
  }
  return m;
}

std::vector<FusedSample> FuseMoifa(const SensorLogs& logs, const FusionSetup& setup,
                                   const std::vector<FusionWindow>& windows) {
  CheckInputs(logs, windows);
  ConsistencyOptions copt;
  copt.significance = setup.consistency_significance;
  std::vector<FusedSample> out;
  if (!windows.empty()) {
    for (size_t w = 0; w < windows.size(); ++w) {
      const WindowMeasurements m = MeasureWindow(logs, setup, windows[w]);
      std::vector<PoseMeasurement> poses;
      if (m.camera) poses.push_back(PoseMeasurement::FromCovariance("camera", m.camera->T, m.camera->covariance));
      if (m.robot) poses.push_back(PoseMeasurement::FromCovariance("robot", m.robot->T, m.robot->covariance));
      if (poses.empty()) continue;
      out.push_back(MoifaSample(static_cast<int>(w), windows[w].end_s,
                                FuseEpoch(poses, m.inclinometer, copt, setup.exclude_faults)));
      RangeRejects rejects;
      rejects.count = m.inclinometer_beyond_range;
      rejects.worst_rad = m.inclinometer_worst_rad;
      NoteRangeRejects(rejects, !m.inclinometer, setup.inclinometer, &out.back());
    }
    return out;
  }
  for (const TrackerSample& s : logs.tracker.samples) {
    std::vector<PoseMeasurement> poses;
    const PoseWithCovariance cam = CameraFlangePose(s.T_rig_target, s.covariance, setup);
    poses.push_back(PoseMeasurement::FromCovariance("camera", cam.T, cam.covariance));
    Eigen::VectorXd q;
    if (logs.robot && logs.robot->Interpolate(s.time_s, &q)) {
      const PoseWithCovariance rob = RobotFlangePose(q, setup);
      poses.push_back(PoseMeasurement::FromCovariance("robot", rob.T, rob.covariance));
    }
    std::optional<TiltReading> tilt;
    RangeRejects rejects;
    if (logs.inclinometer) {
      const double half = 0.5 * setup.inclinometer.period;
      int n = 0;
      tilt = MeanTilt(*logs.inclinometer, s.time_s - half, s.time_s + half, true, setup.inclinometer, &n,
                      setup.exclude_faults ? &rejects : nullptr);
    }
    out.push_back(MoifaSample(s.frame, s.time_s, FuseEpoch(poses, tilt, copt, setup.exclude_faults)));
    NoteRangeRejects(rejects, !tilt, setup.inclinometer, &out.back());
  }
  return out;
}

std::vector<FusedSample> FuseKalman(const SensorLogs& logs, const FusionSetup& setup,
                                    const std::vector<FusionWindow>& windows) {
  CheckInputs(logs, windows);
  std::vector<FusedSample> out;
  if (windows.empty()) {
    const std::vector<Event> events = MergedEvents(logs, logs.tracker.samples.back().time_s);
    KalmanRun run(logs, setup, 1.0,
                  static_cast<double>(events.size()) / static_cast<double>(logs.tracker.samples.size()));
    for (const Event& e : events) {
      run.Process(e);
      if (e.kind != StreamSensor::kCamera) continue;
      const TrackerSample& s = logs.tracker.samples[e.index];
      out.push_back(run.Report(s.frame, s.time_s, run.Filter().PoseEstimate(), run.Filter().PoseCovariance()));
    }
    return out;
  }
  const std::vector<Event> events = MergedEvents(logs, std::numeric_limits<double>::infinity());
  size_t e0 = 0;
  for (size_t w = 0; w < windows.size(); ++w) {
    const double t0 = windows[w].start_s, t1 = windows[w].end_s;
    while (e0 < events.size() && events[e0].t < t0) ++e0;
    size_t e1 = e0;
    int robot_readings = 0;
    for (; e1 < events.size() && events[e1].t < t1; ++e1) robot_readings += events[e1].kind == StreamSensor::kRobot;
    // The filter starts at the window's first camera frame: a single joint reading, whose
    // covariance carries the window's systematic error inflated, is no prior on its own.
    // Samples before that frame are dropped; those at its time stamp follow it.
    size_t first = e0;
    while (first < e1 && events[first].kind != StreamSensor::kCamera) ++first;
    if (first == e1) {
      e0 = e1;
      continue;
    }
    KalmanRun run(logs, setup, std::max(1, robot_readings), static_cast<double>(e1 - first));
    run.Process(events[first]);
    for (size_t k = e0; k < e1; ++k)
      if (k != first && events[k].t >= events[first].t) run.Process(events[k]);
    e0 = e1;
    const auto pred = run.Filter().Predict(std::max(run.Filter().Time(), t1));
    out.push_back(run.Report(static_cast<int>(w), t1, pred.T, pred.covariance));
  }
  return out;
}

bool StreamFusionOptions::IsValid(std::string* why) const {
  if (moifa || kalman) return true;
  if (why) *why = "no fusion method asked for (MOIFA, the KF or both)";
  return false;
}

std::vector<FusedSample> FuseStream(const SensorLogs& logs, const FusionSetup& setup,
                                    const StreamFusionOptions& options) {
  if (std::string why; !options.IsValid(&why)) Throw("fusion options: ", why);
  std::vector<FusedSample> rows;
  if (options.moifa) rows = FuseMoifa(logs, setup, options.windows);
  if (options.kalman) {
    const auto kf = FuseKalman(logs, setup, options.windows);
    rows.insert(rows.end(), kf.begin(), kf.end());
  }
  // Time order; MOIFA before KF at equal times.
  std::stable_sort(rows.begin(), rows.end(), [](const FusedSample& x, const FusedSample& y) {
    return x.time_s < y.time_s || (x.time_s == y.time_s && x.method < y.method);
  });
  return rows;
}

}  // namespace mcms
