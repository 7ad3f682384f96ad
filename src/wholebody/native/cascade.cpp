// The common path of the cascade of QPs (Herzog et al. 2016, eqs. 8-11), compiled: every level's
// unconstrained regularised least-squares minimiser over the remaining null space is feasible for
// the level's own inequality rows and for the (relaxed) higher ones, so no QP is solved. This is
// wholebody.solvers.hierarchy._solve_cascade line for line for that case; at the first level
// where the Python cascade would do anything else (a level QP, an implicit-equality search, a
// failed least-squares solve, a warning about a frozen higher row) this returns the cascade's
// state at the start of that level and the Python cascade resumes from there — it stays the
// reference, and the only place where QPs are solved.
#include <Eigen/Dense>

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

namespace py = pybind11;

namespace
{
  using Eigen::Index;
  using Eigen::MatrixXd;
  using Eigen::VectorXd;
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using Mask = std::vector<Index>;

  constexpr double kTightTol = 1e-8; // hierarchy._TIGHT_TOL

  VectorXd sq_norms(const MatrixXd & A) { return A.rowwise().squaredNorm(); }

  MatrixXd rows_of(const MatrixXd & A, const Mask & keep)
  {
    MatrixXd out(Index(keep.size()), A.cols());
    for (std::size_t i = 0; i < keep.size(); ++i)
      out.row(Index(i)) = A.row(keep[i]);
    return out;
  }

  VectorXd entries_of(const VectorXd & a, const Mask & keep)
  {
    VectorXd out(Index(keep.size()));
    for (std::size_t i = 0; i < keep.size(); ++i)
      out[Index(i)] = a[keep[i]];
    return out;
  }

  // Higher-priority inequality rows that still have freedom: (C, relaxed lower, relaxed upper,
  // drop_tol² ‖C_i‖²), as the ``high`` tuple of _solve_cascade.
  struct Rows
  {
    MatrixXd C;
    VectorXd lower, upper, norms;
    bool empty() const { return C.rows() == 0; }
    Rows subset(const Mask & keep) const
    {
      return {rows_of(C, keep), entries_of(lower, keep), entries_of(upper, keep), entries_of(norms, keep)};
    }
    void append(const Rows & other)
    {
      if (other.empty())
        return;
      if (empty())
      {
        *this = other;
        return;
      }
      const Index m = C.rows(), k = other.C.rows();
      C.conservativeResize(m + k, Eigen::NoChange);
      C.bottomRows(k) = other.C;
      for (VectorXd * v : {&lower, &upper, &norms})
        v->conservativeResize(m + k);
      lower.tail(k) = other.lower;
      upper.tail(k) = other.upper;
      norms.tail(k) = other.norms;
    }
  };

  // _drop_frozen: keep the rows with ‖C_i Z‖² > drop_tol² ‖C_i‖²; false if a dropped row violates
  // its relaxed bounds (the Python cascade then records a warning: not the common path).
  bool drop_frozen(Rows & high, MatrixXd & HZ, const VectorXd & x, double feas_tol)
  {
    const VectorXd n2 = sq_norms(HZ);
    Mask free_rows;
    for (Index i = 0; i < HZ.rows(); ++i)
    {
      if (n2[i] > high.norms[i])
      {
        free_rows.push_back(i);
        continue;
      }
      const double cx = high.C.row(i).dot(x);
      const double over = std::max(high.lower[i] - cx, cx - high.upper[i]);
      if (over > feas_tol * (1.0 + std::abs(cx)))
        return false;
    }
    if (Index(free_rows.size()) != HZ.rows())
    {
      high = high.subset(free_rows);
      HZ = rows_of(HZ, free_rows);
    }
    return true;
  }

  // _kernel: orthonormal basis of ker(RZ) by QR with column pivoting of RZᵀ, SVD when a |R_ii|
  // is within three decades of the threshold.
  MatrixXd kernel(const MatrixXd & RZ, double tol)
  {
    const Index k = RZ.rows(), z = RZ.cols(), p = std::min(k, z);
    const MatrixXd At = RZ.transpose();
    Eigen::ColPivHouseholderQR<MatrixXd> qr(At);
    const VectorXd d = qr.matrixQR().diagonal().head(p).cwiseAbs();
    Index rank = 0;
    bool ambiguous = false;
    for (Index i = 0; i < p; ++i)
    {
      rank += d[i] > tol;
      ambiguous = ambiguous || (d[i] > 1e-3 * tol && d[i] < 1e3 * tol);
    }
    if (ambiguous)
    {
      Eigen::JacobiSVD<MatrixXd> svd(At, Eigen::ComputeFullU);
      const Index r = (svd.singularValues().array() > tol).count();
      return svd.matrixU().rightCols(z - r);
    }
    if (rank == 0)
      return MatrixXd::Identity(z, z);
    if (rank >= z)
      return MatrixXd(z, 0);
    const MatrixXd Q = qr.householderQ() * MatrixXd::Identity(z, z);
    return Q.rightCols(z - rank);
  }

  struct Level
  {
    MatrixXd B, C;
    VectorXd b, w, lower, upper;
  };
} // namespace

using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using ConstRowMap = Eigen::Map<const RowMatrix>;
using ConstVecMap = Eigen::Map<const VectorXd>;

ConstRowMap matrix_at(const std::vector<DoubleArray> & list, std::size_t i, Index cols)
{
  const DoubleArray & a = list[i];
  const Index rows = a.ndim() == 2 && a.shape(1) == cols ? Index(a.shape(0)) : 0;
  return ConstRowMap(a.data(), rows, cols);
}

ConstVecMap vector_at(const std::vector<DoubleArray> & list, std::size_t i)
{
  return ConstVecMap(list[i].data(), Index(list[i].size()));
}

// Returns ((x, null-space dimensions), None) when every level took the common path; (None,
// (r, x*, Z or None, higher rows or None, null-space dimensions of levels < r)) — the state of
// the cascade at the start of level r — when level r needs the Python cascade; None when the
// first level already does (the Python cascade then starts from scratch).
// The per-level arrays are read in place (numpy, C order); a matrix without n columns is an
// empty level (hierarchy._rows).
py::object cascade_common_path(
  const std::vector<DoubleArray> & Bs, const std::vector<DoubleArray> & bs,
  const std::vector<DoubleArray> & ws, const std::vector<DoubleArray> & Cs,
  const std::vector<DoubleArray> & lowers, const std::vector<DoubleArray> & uppers, Index n,
  double eps, const std::optional<VectorXd> & x1, const std::optional<MatrixXd> & Z1,
  double rank_tol, double drop_tol, double relax_tol, double feas_tol)
{
  const std::size_t nl = Bs.size();
  if (bs.size() != nl || ws.size() != nl || Cs.size() != nl || lowers.size() != nl
      || uppers.size() != nl)
    throw std::invalid_argument("cascade_common_path: per-level lists differ in length");
  const double drop2 = drop_tol * drop_tol;
  std::vector<Index> zdims(nl, 0);
  VectorXd x = VectorXd::Zero(n);
  bool haveZ = false; // false stands for Z = identity (nothing locked yet)
  MatrixXd Z;
  Index z = n;
  Rows high;

  for (std::size_t r = 0; r < nl; ++r)
  {
    const ConstRowMap B = matrix_at(Bs, r, n), C = matrix_at(Cs, r, n);
    const ConstVecMap b = vector_at(bs, r), w = vector_at(ws, r);
    const ConstVecMap lower = vector_at(lowers, r), upper = vector_at(uppers, r);
    const Index k = B.rows(), m = C.rows();
    if (r == 0 && x1 && Z1) // analytic first priority (§2.4): v*_1 = 0
    {
      x = *x1;
      Z = *Z1;
      haveZ = true;
      z = Z.cols();
      if (m)
      {
        high = {C, lower, upper, drop2 * C.rowwise().squaredNorm()};
        MatrixXd CZ1 = z ? MatrixXd(C * Z) : MatrixXd(m, 0);
        if (!drop_frozen(high, CZ1, x, feas_tol))
          return py::none();
      }
      zdims[0] = z;
      continue;
    }
    if (z == 0)
      continue;
    // where the Python cascade resumes if this level needs more than the common path
    const Rows high_at_start = high;
    auto resume = [&]() -> py::object {
      py::object Zout = haveZ ? py::cast(Z) : py::none();
      py::object hout = py::none();
      if (!high_at_start.empty())
        hout = py::make_tuple(high_at_start.C, high_at_start.lower, high_at_start.upper,
                              high_at_start.norms);
      std::vector<Index> done(zdims.begin(), zdims.begin() + r);
      return py::make_tuple(py::none(), py::make_tuple(Index(r), x, Zout, hout, done));
    };

    // higher rows: drop those without freedom; rows tight at x* are loosened (_loosen_tight)
    MatrixXd HZ;
    VectorXd hx, hlo, hup;
    if (!high.empty())
    {
      HZ = haveZ ? MatrixXd(high.C * Z) : high.C;
      if (!drop_frozen(high, HZ, x, feas_tol))
        return resume();
    }
    if (!high.empty())
    {
      hx = high.C * x;
      hlo = high.lower;
      hup = high.upper;
      const double gap_tol = std::max(kTightTol, relax_tol);
      bool tight = false;
      for (Index i = 0; i < hx.size(); ++i)
      {
        const double gap = std::min(std::abs(hx[i] - hlo[i]), std::abs(hup[i] - hx[i]));
        tight = tight || !(gap > gap_tol * (1.0 + std::abs(hx[i])));
      }
      if (tight)
        for (Index i = 0; i < hx.size(); ++i)
        {
          const double dlt = relax_tol * (1.0 + std::abs(hx[i]));
          if (std::abs(hx[i] - hlo[i]) <= dlt)
            hlo[i] = std::min(hlo[i], hx[i]) - dlt;
          if (std::abs(hx[i] - hup[i]) <= dlt)
            hup[i] = std::max(hup[i], hx[i]) + dlt;
        }
    }

    // the level over x = x* + Z u (eq. 8) and its unconstrained minimiser (_project_level)
    const MatrixXd wB = w.asDiagonal() * B;
    const MatrixXd M = haveZ ? MatrixXd(wB * Z) : wB;
    // least squares [M; √ε I] u ≈ [−r0; −√ε Zᵀx*] by Householder QR (_unconstrained: the normal
    // equations would square the condition number)
    const Index zc = M.cols();
    const double root = std::sqrt(eps);
    MatrixXd A(k + zc, zc);
    A.topRows(k) = M;
    A.bottomRows(zc) = root * MatrixXd::Identity(zc, zc);
    VectorXd rhs(k + zc);
    rhs.head(k) = -(wB * x - w.cwiseProduct(b));
    rhs.tail(zc) = -root * (haveZ ? VectorXd(Z.transpose() * x) : x);
    Rows own;
    MatrixXd ownCZ;
    if (m)
    {
      const MatrixXd CZ = haveZ ? MatrixXd(C * Z) : C;
      const VectorXd nC = drop2 * C.rowwise().squaredNorm(), n2 = sq_norms(CZ);
      Mask free_rows;
      for (Index i = 0; i < m; ++i)
        if (n2[i] > nC[i])
          free_rows.push_back(i);
      Rows all{C, lower, upper, nC};
      own = all.subset(free_rows);
      ownCZ = rows_of(CZ, free_rows);
    }
    const VectorXd u = A.householderQr().solve(rhs);
    if (!u.allFinite())
      return resume();
    // feasible for its own rows and the relaxed higher rows (exactly, no tolerance: _violated)?
    if (!own.empty())
    {
      const VectorXd v = ownCZ * u + own.C * x;
      if (((v.array() < own.lower.array()) || (v.array() > own.upper.array())).any())
        return resume();
    }
    if (!high.empty())
    {
      const VectorXd v = HZ * u + hx;
      if (((v.array() < hlo.array()) || (v.array() > hup.array())).any())
        return resume();
      high.lower = hlo; // the margins stay for the lower levels
      high.upper = hup;
    }
    x += haveZ ? VectorXd(Z * u) : u;

    // this level's free rows join the higher ones, relaxed by v* (eq. 9)
    if (!own.empty())
    {
      const VectorXd cx = own.C * x;
      const VectorXd viol =
        (own.lower - cx).cwiseMax(cx - own.upper).cwiseMax(0.0);
      own.lower -= viol;
      own.upper += viol;
      high.append(own);
    }
    // lock the weighted equality rows' directions (_lock): Z ← Z N
    if (k && r + 1 < nl && z)
    {
      const double scale = std::sqrt(sq_norms(wB).maxCoeff());
      if (scale != 0.0)
      {
        const MatrixXd N = kernel(M, rank_tol * scale);
        if (N.cols() != z)
        {
          Z = haveZ ? MatrixXd(Z * N) : N;
          haveZ = true;
          z = Z.cols();
        }
      }
    }
    zdims[r] = z;
  }
  return py::make_tuple(py::make_tuple(x, zdims), py::none());
}

PYBIND11_MODULE(_cascade, m)
{
  m.doc() = "Compiled common path of wholebody.solvers.hierarchy's cascade (no level QP).";
  m.def("cascade_common_path", &cascade_common_path, py::arg("B"), py::arg("b"), py::arg("w"),
        py::arg("C"), py::arg("lower"), py::arg("upper"), py::arg("n"), py::arg("eps"),
        py::arg("x1"), py::arg("Z1"), py::arg("rank_tol"), py::arg("drop_tol"),
        py::arg("relax_tol"), py::arg("feas_tol"));
}
