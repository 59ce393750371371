#include "model/identifiability.h"

#include <Eigen/Dense>
#include <cmath>
#include <sstream>

namespace mcms {

void AnalyzeIdentifiability(const Eigen::MatrixXd& J, const std::vector<std::string>& names, double tol,
                            std::vector<ParameterStatus>* params, const std::vector<double>& largest_sigma) {
  const int n = static_cast<int>(J.cols());
  Eigen::MatrixXd Q(J.rows(), 0);
  std::vector<int> kept;
  for (int j = 0; j < n; ++j) {
    ParameterStatus& p = (*params)[j];
    if (p.fixed) continue;
    const double norm = J.col(j).norm();
    if (!(norm > 1e-12 * std::sqrt(static_cast<double>(J.rows())))) {
      p.fixed = true;
      p.reason = "does not affect the measurements at these poses (zero Jacobian column)";
      continue;
    }
    Eigen::VectorXd c = J.col(j) / norm;
    Eigen::VectorXd res = c;
    for (int pass = 0; pass < 2 && Q.cols() > 0; ++pass) res -= Q * (Q.transpose() * res);
    const double dist = res.norm();
    if (dist < tol) {
      // Which kept parameters it is a combination of: least squares on the kept columns.
      Eigen::MatrixXd A(J.rows(), kept.size());
      for (size_t k = 0; k < kept.size(); ++k) A.col(k) = J.col(kept[k]) / J.col(kept[k]).norm();
      const Eigen::VectorXd coef = A.colPivHouseholderQr().solve(c);
      const double big = coef.cwiseAbs().maxCoeff();
      std::ostringstream s;
      s << "not identifiable: a combination of";
      int listed = 0;
      for (size_t k = 0; k < kept.size(); ++k)
        if (std::abs(coef[k]) > 0.1 * big) s << (listed++ ? ", " : " ") << names[kept[k]];
      s << " (distance from their span " << dist << " < " << tol << ")";
      p.fixed = true;
      p.reason = s.str();
      continue;
    }
    Q.conservativeResize(Eigen::NoChange, Q.cols() + 1);
    Q.col(Q.cols() - 1) = res / dist;
    kept.push_back(j);
  }
  if (largest_sigma.empty()) return;
  // Weakly identifiable: a standard deviation beyond what the parameter could physically be.
  while (!kept.empty()) {
    Eigen::MatrixXd A(J.rows(), kept.size());
    for (size_t k = 0; k < kept.size(); ++k) A.col(k) = J.col(kept[k]);
    const Eigen::VectorXd d = A.colwise().norm().transpose().cwiseMax(1e-300);
    const Eigen::MatrixXd An = A * d.cwiseInverse().asDiagonal();
    const Eigen::MatrixXd C = (An.transpose() * An).completeOrthogonalDecomposition().pseudoInverse();
    int worst = -1;
    double ratio = 1.0, sigma = 0.0;
    for (size_t k = 0; k < kept.size(); ++k) {
      const double limit = largest_sigma[kept[k]];
      if (!(limit > 0)) continue;
      const double s = std::sqrt(std::max(0.0, C(k, k))) / d[k];
      if (s / limit > ratio) ratio = s / limit, worst = static_cast<int>(k), sigma = s;
    }
    if (worst < 0) break;
    ParameterStatus& p = (*params)[kept[worst]];
    std::ostringstream s;
    s << "weakly identifiable: these poses give it a standard deviation of " << sigma
      << ", more than a robot's placement could be off (" << largest_sigma[kept[worst]] << ")";
    p.fixed = true;
    p.reason = s.str();
    kept.erase(kept.begin() + worst);
  }
}

}  // namespace mcms
