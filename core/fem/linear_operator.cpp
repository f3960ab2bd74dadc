#include <mlfe/core/base/check.h>
#include <mlfe/core/fem/linear_operator.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/partitioner.h>

#include <cmath>

namespace mlfe {

namespace {
constexpr Eigen::Index kGrain = 8192;
}

void SparseOperator::apply(const Vector& x, Vector& y) const {
  MLFE_CHECK(x.size() == a_.cols());
  y.resize(a_.rows());
  const int* outer = a_.outerIndexPtr();
  const int* inner = a_.innerIndexPtr();
  const double* val = a_.valuePtr();
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, a_.rows(), 2048),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      for (Eigen::Index i = r.begin(); i != r.end(); ++i) {
                        double s = 0;
                        for (int k = outer[i]; k < outer[i + 1]; ++k) s += val[k] * x[inner[k]];
                        y[i] = s;
                      }
                    });
}

JacobiPreconditioner::JacobiPreconditioner(const SparseMatrix& a)
    : JacobiPreconditioner(Vector(a.diagonal())) {}

JacobiPreconditioner::JacobiPreconditioner(const Vector& d) : inv_diag_(d.size()) {
  for (Eigen::Index i = 0; i < d.size(); ++i) {
    MLFE_CHECK(d[i] > 0);
    inv_diag_[i] = 1.0 / d[i];
  }
}

void JacobiPreconditioner::apply(const Vector& x, Vector& y) const { y = inv_diag_.cwiseProduct(x); }

double deterministic_dot(const Vector& x, const Vector& y) {
  MLFE_CHECK(x.size() == y.size());
  return tbb::parallel_deterministic_reduce(
      tbb::blocked_range<Eigen::Index>(0, x.size(), kGrain), 0.0,
      [&](const tbb::blocked_range<Eigen::Index>& r, double s) {
        for (Eigen::Index i = r.begin(); i != r.end(); ++i) s += x[i] * y[i];
        return s;
      },
      [](double a, double b) { return a + b; }, tbb::simple_partitioner());
}

CgResult conjugate_gradient(const LinearOperator& a, const LinearOperator& m, const Vector& b, Vector& x,
                            double rtol, int max_iterations) {
  CgResult res;
  const Eigen::Index n = b.size();
  MLFE_CHECK(a.size() == n && m.size() == n);
  if (x.size() != n) x = Vector::Zero(n);
  const double bnorm = std::sqrt(deterministic_dot(b, b));
  if (bnorm == 0) {
    x.setZero();
    res.converged = true;
    return res;
  }
  Vector r(n), z(n), p(n), q(n);
  a.apply(x, q);
  r = b - q;
  double rnorm = std::sqrt(deterministic_dot(r, r));
  if (rnorm <= rtol * bnorm) {
    res.converged = true;
    res.relative_residual = rnorm / bnorm;
    return res;
  }
  m.apply(r, z);
  p = z;
  double rz = deterministic_dot(r, z);
  for (int it = 1; it <= max_iterations; ++it) {
    a.apply(p, q);
    const double pq = deterministic_dot(p, q);
    MLFE_CHECK_MSG(pq > 0, "CG: operator not positive definite");
    const double alpha = rz / pq;
    x += alpha * p;
    r -= alpha * q;
    rnorm = std::sqrt(deterministic_dot(r, r));
    res.iterations = it;
    if (rnorm <= rtol * bnorm) {
      res.converged = true;
      break;
    }
    m.apply(r, z);
    const double rz_new = deterministic_dot(r, z);
    p = z + (rz_new / rz) * p;
    rz = rz_new;
  }
  res.relative_residual = rnorm / bnorm;
  return res;
}

}  // namespace mlfe
