#include "ruffini/fusion/covariance.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

namespace ruffini::fusion {

const char* ToString(CovarianceStatus s) noexcept {
  switch (s) {
    case CovarianceStatus::kOk: return "ok";
    case CovarianceStatus::kNotFinite: return "not_finite";
    case CovarianceStatus::kNotCovariance: return "not_covariance";
  }
  return "unknown";
}

namespace {

// P = V diag(lambda) V^T with lambda clamped; also returns the inverse from the same decomposition, so an
// inverse never goes through a near-singular solve.
CovarianceStatus Decompose(const Eigen::Matrix3d& P_in, double min_var, double max_var, Eigen::Matrix3d& P,
                           Eigen::Matrix3d& P_inv) noexcept {
  if (!P_in.allFinite()) return CovarianceStatus::kNotFinite;
  const Eigen::Matrix3d S = 0.5 * (P_in + P_in.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(S);
  if (eig.info() != Eigen::Success) return CovarianceStatus::kNotCovariance;
  Eigen::Vector3d lambda = eig.eigenvalues();
  if (!lambda.allFinite()) return CovarianceStatus::kNotFinite;
  const double scale = lambda.cwiseAbs().maxCoeff();
  if (lambda.minCoeff() < -std::max(1e-9 * scale, min_var)) return CovarianceStatus::kNotCovariance;
  for (int i = 0; i < 3; ++i) lambda[i] = std::clamp(lambda[i], min_var, max_var);
  const Eigen::Matrix3d& V = eig.eigenvectors();
  P = V * lambda.asDiagonal() * V.transpose();
  P_inv = V * lambda.cwiseInverse().asDiagonal() * V.transpose();
  P = (0.5 * (P + P.transpose())).eval();  // eval: P appears on both sides (Eigen aliasing)
  P_inv = (0.5 * (P_inv + P_inv.transpose())).eval();
  return CovarianceStatus::kOk;
}

// tr((w A + (1 - w) B)^-1); +inf when the information matrix is not positive definite.
double TraceOfInverse(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B, double w) noexcept {
  const Eigen::Matrix3d info = w * A + (1.0 - w) * B;
  const Eigen::LLT<Eigen::Matrix3d> llt(info);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  const Eigen::Matrix3d P = llt.solve(Eigen::Matrix3d::Identity());
  const double t = P.trace();
  return std::isfinite(t) ? t : std::numeric_limits<double>::infinity();
}

}  // namespace

CovarianceStatus Regularize(Eigen::Matrix3d& P, double min_var, double max_var) noexcept {
  Eigen::Matrix3d out, inv;
  const auto s = Decompose(P, min_var, max_var, out, inv);
  if (s == CovarianceStatus::kOk) P = out;
  return s;
}

CovarianceStatus CovarianceIntersection(const Estimate& a, const Estimate& b, Estimate& out, double* w_out) noexcept {
  if (!a.x.allFinite() || !b.x.allFinite()) return CovarianceStatus::kNotFinite;
  Eigen::Matrix3d Pa, A, Pb, B;
  if (const auto s = Decompose(a.P, kMinVariance_m2, kMaxVariance_m2, Pa, A); s != CovarianceStatus::kOk) return s;
  if (const auto s = Decompose(b.P, kMinVariance_m2, kMaxVariance_m2, Pb, B); s != CovarianceStatus::kOk) return s;

  if (a.x == b.x && Pa == Pb) {  // any w gives this estimate; return it exactly
    out = {a.x, Pa};
    if (w_out) *w_out = 0.5;
    return CovarianceStatus::kOk;
  }

  // Golden-section search of the convex tr P(w) on [0, 1], a fixed number of steps (deterministic cost).
  constexpr double kInvPhi = 0.6180339887498949;  // (sqrt(5) - 1) / 2
  double lo = 0.0, hi = 1.0;
  double w1 = hi - kInvPhi * (hi - lo), w2 = lo + kInvPhi * (hi - lo);
  double f1 = TraceOfInverse(A, B, w1), f2 = TraceOfInverse(A, B, w2);
  for (int i = 0; i < kCiIterations; ++i) {
    if (f1 <= f2) {
      hi = w2;
      w2 = w1;
      f2 = f1;
      w1 = hi - kInvPhi * (hi - lo);
      f1 = TraceOfInverse(A, B, w1);
    } else {
      lo = w1;
      w1 = w2;
      f1 = f2;
      w2 = lo + kInvPhi * (hi - lo);
      f2 = TraceOfInverse(A, B, w2);
    }
  }
  double w_mid = 0.5 * (lo + hi);
  double f_mid = TraceOfInverse(A, B, w_mid);
  const double f_a = Pa.trace();  // w = 1
  const double f_b = Pb.trace();  // w = 0
  const double tie = 1e-12 * std::min(f_a, f_b);
  if (f_mid >= std::min(f_a, f_b) - tie) {
    // No interior w does clearly better than the better end. If the ends tie as well, the convex tr P(w)
    // is flat on [0, 1] (equal at both ends and nowhere lower): every w is optimal and w = 1/2 treats a
    // and b alike. Otherwise the better end wins and returns its input exactly.
    if (std::abs(f_a - f_b) <= tie) {
      w_mid = 0.5;
      f_mid = TraceOfInverse(A, B, w_mid);
    } else if (f_a < f_b) {
      out = {a.x, Pa};
      if (w_out) *w_out = 1.0;
      return CovarianceStatus::kOk;
    } else {
      out = {b.x, Pb};
      if (w_out) *w_out = 0.0;
      return CovarianceStatus::kOk;
    }
  }
  if (!std::isfinite(f_mid)) return CovarianceStatus::kNotCovariance;  // unreachable: A, B are PD
  const Eigen::Matrix3d info = w_mid * A + (1.0 - w_mid) * B;
  const Eigen::LLT<Eigen::Matrix3d> llt(info);
  if (llt.info() != Eigen::Success) return CovarianceStatus::kNotCovariance;  // unreachable: f_mid was finite
  Eigen::Matrix3d P = llt.solve(Eigen::Matrix3d::Identity());
  // x = P (w A a + (1 - w) B b) = a + (1 - w) P B (b - a): the same, but a correction to a, so two nearly
  // equal estimates do not lose digits to two large, nearly cancelling information-weighted sums.
  const Eigen::Vector3d x = a.x + llt.solve((1.0 - w_mid) * (B * (b.x - a.x)));
  if (Regularize(P) != CovarianceStatus::kOk || !x.allFinite()) return CovarianceStatus::kNotFinite;
  out = {x, P};
  if (w_out) *w_out = w_mid;
  return CovarianceStatus::kOk;
}

double TangentMahalanobis2(const Estimate& a, const Estimate& b, const Eigen::Vector3d& n) noexcept {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  if (!a.x.allFinite() || !b.x.allFinite() || !a.P.allFinite() || !b.P.allFinite() || !n.allFinite()) return kInf;
  const double norm = n.norm();
  if (!(norm > 1e-9)) return kInf;
  const Eigen::Vector3d u = n / norm;
  const Eigen::Vector3d t1 = u.unitOrthogonal();
  const Eigen::Vector3d t2 = u.cross(t1);
  Eigen::Matrix<double, 3, 2> T;
  T << t1, t2;
  const Eigen::Vector2d d = T.transpose() * (a.x - b.x);
  const Eigen::Matrix3d S3 = 0.5 * (a.P + a.P.transpose() + b.P + b.P.transpose());
  const Eigen::Matrix2d S = T.transpose() * S3 * T;
  const Eigen::LLT<Eigen::Matrix2d> llt(S);
  if (llt.info() != Eigen::Success) return kInf;
  const double d2 = d.dot(llt.solve(d));
  return std::isfinite(d2) && d2 >= 0.0 ? d2 : kInf;
}

}  // namespace ruffini::fusion
