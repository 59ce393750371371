#include "calib/iso9283.h"

#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/limits.h"

namespace mcms {

namespace {

// Mean and the sample standard deviation (n - 1), as ISO 9283 uses.
void MeanStd(const std::vector<double>& v, double* mean, double* std) {
  double s = 0;
  for (double x : v) s += x;
  *mean = s / static_cast<double>(v.size());
  double ss = 0;
  for (double x : v) ss += (x - *mean) * (x - *mean);
  *std = std::sqrt(ss / static_cast<double>(v.size() - 1));
}

}  // namespace

PoseCharacteristics PoseAccuracyRepeatability(const Pose& commanded, const std::vector<Pose>& attained) {
  const int n = static_cast<int>(attained.size());
  if (n < 2) Throw("ISO 9283 pose characteristics: ", n, " attained poses; at least 2 are needed (the standard uses 30)");
  PoseCharacteristics c;
  c.n = n;
  for (const Pose& p : attained) c.barycentre += p.t;
  c.barycentre /= n;
  c.AP_xyz = c.barycentre - commanded.t;
  c.AP_p = c.AP_xyz.norm();
  std::vector<double> l(n), da(n), db(n), dc(n);
  for (int j = 0; j < n; ++j) {
    l[j] = (attained[j].t - c.barycentre).norm();
    const Vec3 d = LogSO3(attained[j].R * commanded.R.transpose());
    da[j] = d.x();
    db[j] = d.y();
    dc[j] = d.z();
  }
  MeanStd(l, &c.l_bar, &c.S_l);
  c.RP_l = c.l_bar + 3.0 * c.S_l;
  double s = 0;
  MeanStd(da, &c.AP_a, &s);
  c.RP_a = 3.0 * s;
  MeanStd(db, &c.AP_b, &s);
  c.RP_b = 3.0 * s;
  MeanStd(dc, &c.AP_c, &s);
  c.RP_c = 3.0 * s;
  return c;
}

DistanceCharacteristics DistanceAccuracyRepeatability(const Pose& commanded1, const Pose& commanded2,
                                                      const std::vector<Pose>& attained1,
                                                      const std::vector<Pose>& attained2) {
  if (attained1.size() != attained2.size())
    Throw("ISO 9283 distance characteristics: ", attained1.size(), " attained poses of P1 but ", attained2.size(),
          " of P2; give both poses for every cycle");
  const int n = static_cast<int>(attained1.size());
  if (n < 2) Throw("ISO 9283 distance characteristics: ", n, " cycles; at least 2 are needed (the standard uses 30)");
  DistanceCharacteristics c;
  c.n = n;
  const Vec3 Dc = commanded1.t - commanded2.t;
  c.D_c = Dc.norm();
  std::vector<double> D(n);
  std::vector<double> Dx[3];
  for (int j = 0; j < n; ++j) {
    const Vec3 d = attained1[j].t - attained2[j].t;
    D[j] = d.norm();
    for (int k = 0; k < 3; ++k) Dx[k].push_back(d[k]);
  }
  MeanStd(D, &c.D_bar, &c.S_D);
  c.AD_p = c.D_bar - c.D_c;
  c.RD_p = 3.0 * c.S_D;
  for (int k = 0; k < 3; ++k) {
    double m = 0, s = 0;
    MeanStd(Dx[k], &m, &s);
    c.AD_xyz[k] = m - Dc[k];
    c.RD_xyz[k] = 3.0 * s;
  }
  return c;
}

PathCharacteristics PathAccuracyRepeatability(const std::vector<Vec3>& commanded,
                                              const std::vector<std::vector<Vec3>>& attained) {
  const int m = static_cast<int>(commanded.size());
  const int n = static_cast<int>(attained.size());
  if (m < 2) Throw("ISO 9283 path characteristics: the commanded path has ", m, " points; at least 2 are needed");
  if (n < 2) Throw("ISO 9283 path characteristics: ", n, " attained runs; at least 2 are needed (the standard uses 10)");
  for (int i = 1; i < m; ++i)
    if ((commanded[i] - commanded[i - 1]).norm() <= 0)
      Throw("ISO 9283 path characteristics: commanded points ", i, " and ", i + 1, " coincide; the path direction is undefined");
  for (int r = 0; r < n; ++r)
    if (attained[r].size() < 2)
      Throw("ISO 9283 path characteristics: attained run ", r + 1, " has ", attained[r].size(), " points; at least 2 are needed");
  // A run in another unit than the commanded path (mm against m) never meets its planes.
  const auto Length = [](const std::vector<Vec3>& p) {
    double L = 0;
    for (size_t k = 1; k < p.size(); ++k) L += (p[k] - p[k - 1]).norm();
    return L;
  };
  const double Lc = Length(commanded);
  for (int r = 0; r < n; ++r) {
    const double ratio = Length(attained[r]) / Lc;
    if (!(ratio > 0.05 && ratio < 20))
      Throw("ISO 9283 path characteristics: attained run ", r + 1, " is ", ratio,
            " times as long as the commanded path", LengthUnitHint(ratio),
            "; give the commanded and the attained paths in the same unit (metres)");
  }

  PathCharacteristics c;
  for (int i = 0; i < m; ++i) {
    // Path direction at the calculation point: central difference inside, one-sided at the ends.
    const Vec3 t = (commanded[std::min(i + 1, m - 1)] - commanded[std::max(i - 1, 0)]).normalized();
    std::vector<Vec3> x(n);
    for (int r = 0; r < n; ++r) {
      const auto& run = attained[r];
      double best = std::numeric_limits<double>::infinity();
      for (size_t k = 0; k + 1 < run.size(); ++k) {
        const double sa = t.dot(run[k] - commanded[i]), sb = t.dot(run[k + 1] - commanded[i]);
        if ((sa > 0 && sb > 0) || (sa < 0 && sb < 0) || sa == sb) continue;
        const Vec3 p = run[k] + (sa / (sa - sb)) * (run[k + 1] - run[k]);
        const double d = (p - commanded[i]).norm();
        if (d < best) {
          best = d;
          x[r] = p;
        }
      }
      if (!std::isfinite(best))
        Throw("ISO 9283 path characteristics: attained run ", r + 1, " never crosses the plane normal to the commanded "
              "path at calculation point ", i + 1, "; measure the whole path (start before and end after it)");
    }
    Vec3 G = Vec3::Zero();
    for (const Vec3& p : x) G += p;
    G /= n;
    std::vector<double> l(n);
    for (int r = 0; r < n; ++r) l[r] = (x[r] - G).norm();
    double lbar = 0, S = 0;
    MeanStd(l, &lbar, &S);
    c.barycentres.push_back(G);
    c.AT_i.push_back((G - commanded[i]).norm());
    c.RT_i.push_back(lbar + 3.0 * S);
    c.AT_p = std::max(c.AT_p, c.AT_i.back());
    c.RT_p = std::max(c.RT_p, c.RT_i.back());
  }
  return c;
}

}  // namespace mcms
