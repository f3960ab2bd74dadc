// Solvers take operators (MFEM style): a LinearOperator maps x to y = A x. The matrix, the
// Jacobi and the BPX preconditioners are all operators, so CG never sees a matrix type.
//
// Determinism: every reduction here uses a fixed blocking independent of the thread count
// (tbb::parallel_deterministic_reduce with simple_partitioner), so results are bitwise
// identical with 1 or N threads.
#pragma once
#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace mlfe {

using Vector = Eigen::VectorXd;
using SparseMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;

class LinearOperator {
 public:
  virtual ~LinearOperator() = default;
  /// Number of rows (= columns).
  virtual Eigen::Index size() const = 0;
  /// y = A x. x.size() == size(); y is resized. x and y must not alias.
  virtual void apply(const Vector& x, Vector& y) const = 0;
};

/// A sparse symmetric matrix as an operator; row-parallel y = A x (deterministic: each row is
/// summed by one thread in storage order). Holds a reference: the matrix must outlive it.
class SparseOperator final : public LinearOperator {
 public:
  explicit SparseOperator(const SparseMatrix& a) : a_(a) {}
  Eigen::Index size() const override { return a_.rows(); }
  void apply(const Vector& x, Vector& y) const override;

 private:
  const SparseMatrix& a_;
};

/// y = x.
class IdentityOperator final : public LinearOperator {
 public:
  explicit IdentityOperator(Eigen::Index n) : n_(n) {}
  Eigen::Index size() const override { return n_; }
  void apply(const Vector& x, Vector& y) const override { y = x; }

 private:
  Eigen::Index n_;
};

/// y = D^{-1} x with D the diagonal of a matrix (zero diagonal entries are a bug: CHECK).
class JacobiPreconditioner final : public LinearOperator {
 public:
  explicit JacobiPreconditioner(const SparseMatrix& a);
  /// From the diagonal itself (an operator without a matrix).
  explicit JacobiPreconditioner(const Vector& diagonal);
  Eigen::Index size() const override { return inv_diag_.size(); }
  void apply(const Vector& x, Vector& y) const override;

 private:
  Vector inv_diag_;
};

/// x · y, bitwise independent of the thread count.
double deterministic_dot(const Vector& x, const Vector& y);

struct CgResult {
  int iterations = 0;
  double relative_residual = 0;  ///< ||b - A x|| / ||b|| at exit
  bool converged = false;
};

/// Preconditioned conjugate gradients for SPD A and SPD preconditioner M (≈ A^{-1}).
/// x holds the start value (warm start) and receives the solution. Stops when
/// ||r|| <= rtol ||b|| or after max_iterations. b == 0 gives x = 0.
CgResult conjugate_gradient(const LinearOperator& a, const LinearOperator& m, const Vector& b, Vector& x,
                            double rtol, int max_iterations);

}  // namespace mlfe
