// Internal to fusion/: checks and solves shared by MOIFA, the consistency test and the
// Kalman filters, on fixed-size information matrices.
#pragma once

#include <cmath>
#include <sstream>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include "core/error.h"

namespace mcms::internal {

// Eigenvalues below this fraction of the largest count as zero when deciding ranks and
// singularity. Information matrices here span at most ~1e4 in their nonzero eigenvalues
// (rad vs m, camera vs inclinometer), rounding leaves ~1e-16 in the null ones.
inline constexpr double kRelativeRankTolerance = 1e-10;

template <int N>
using Mat = Eigen::Matrix<double, N, N>;
template <int N>
using Vec = Eigen::Matrix<double, N, 1>;

template <int N>
bool IsSymmetric(const Mat<N>& A) {
  const double scale = A.cwiseAbs().maxCoeff();
  return (A - A.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * scale;
}

// Inverse of a symmetric positive definite covariance; InputError naming `who`.
template <int N>
Mat<N> CovarianceToInformation(const Mat<N>& C, const std::string& who) {
  if (!C.allFinite()) Throw(who, ": covariance is not finite");
  if (!IsSymmetric<N>(C)) Throw(who, ": covariance is not symmetric");
  const Mat<N> Cs = 0.5 * (C + C.transpose());
  const Eigen::SelfAdjointEigenSolver<Mat<N>> es(Cs);
  const double lo = es.eigenvalues()[0], hi = es.eigenvalues()[N - 1];
  if (!(hi > 0) || lo <= kRelativeRankTolerance * hi)
    Throw(who, ": covariance is not positive definite (eigenvalues ", lo, " .. ", hi,
          "); give a partial measurement in information form instead");
  const Mat<N> L = es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
  return 0.5 * (L + L.transpose());
}

// Pseudo-inverse and rank of a symmetric positive semi-definite matrix.
template <int N>
Mat<N> PseudoInverse(const Mat<N>& A, int* rank = nullptr) {
  const Eigen::SelfAdjointEigenSolver<Mat<N>> es(A);
  const double hi = es.eigenvalues().cwiseAbs().maxCoeff();
  Vec<N> inv = Vec<N>::Zero();
  int r = 0;
  for (int i = 0; i < N; ++i)
    if (hi > 0 && es.eigenvalues()[i] > kRelativeRankTolerance * hi) {
      inv[i] = 1.0 / es.eigenvalues()[i];
      ++r;
    }
  if (rank) *rank = r;
  return es.eigenvectors() * inv.asDiagonal() * es.eigenvectors().transpose();
}

template <int N>
int Rank(const Mat<N>& A) {
  int r = 0;
  PseudoInverse<N>(A, &r);
  return r;
}

// Checks a measurement given in information form; InputError naming `who`.
template <int N>
void ValidateInformation(const Mat<N>& L, const Vec<N>& eta, const std::string& who) {
  if (!L.allFinite() || !eta.allFinite()) Throw(who, ": information is not finite");
  if (!IsSymmetric<N>(L)) Throw(who, ": information matrix is not symmetric");
  const Eigen::SelfAdjointEigenSolver<Mat<N>> es(0.5 * (L + L.transpose()));
  const double hi = es.eigenvalues().cwiseAbs().maxCoeff();
  if (es.eigenvalues()[0] < -kRelativeRankTolerance * hi)
    Throw(who, ": information matrix is not positive semi-definite (eigenvalue ", es.eigenvalues()[0], ")");
  // eta must lie in the range of L: project it on the null space.
  double null_part = 0.0;
  for (int i = 0; i < N; ++i)
    if (!(es.eigenvalues()[i] > kRelativeRankTolerance * hi)) null_part += std::pow(es.eigenvectors().col(i).dot(eta), 2);
  if (std::sqrt(null_part) > 1e-9 * eta.norm() + 1e-300)
    Throw(who, ": information vector has a component along a direction without information");
}

// Solves the total information H x = g with the singularity test shared by the fusers:
// InputError naming the unobserved direction (rank < N).
template <int N>
void SolveTotalInformation(const Mat<N>& H, const Vec<N>& g, const char* what, Mat<N>* P, Vec<N>* x) {
  const Eigen::SelfAdjointEigenSolver<Mat<N>> es(0.5 * (H + H.transpose()));
  const double hi = es.eigenvalues().cwiseAbs().maxCoeff();
  if (!(hi > 0) || !(es.eigenvalues()[0] > kRelativeRankTolerance * hi)) {
    int rank = 0;
    for (int i = 0; i < N; ++i) rank += es.eigenvalues()[i] > kRelativeRankTolerance * hi ? 1 : 0;
    // The direction with the least information, signed so its largest component is
    // positive and with rounding dust cleared, so the message reads e.g. "0 0 1 0 0 0".
    Vec<N> d = es.eigenvectors().col(0);
    int big = 0;
    d.cwiseAbs().maxCoeff(&big);
    if (d[big] < 0) d = -d;
    for (int i = 0; i < N; ++i)
      if (std::abs(d[i]) < 1e-9) d[i] = 0.0;
    std::ostringstream dir;
    dir.precision(4);
    dir << d.transpose();
    Throw("cannot fuse ", what, ": the total information of the measurements is singular (rank ", rank, " of ", N,
          "); no measurement constrains the direction [", dir.str(), "]");
  }
  const Mat<N> Pm = es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
  *P = 0.5 * (Pm + Pm.transpose());
  *x = *P * g;
}

}  // namespace mcms::internal
