// The cascade of QPs (Herzog et al. 2016, eqs. 8-11), compiled: a line-for-line mirror of
// wholebody.solvers.cascade._solve_cascade (the reference, run with compiled=False). Each level
// QP (eqs. 10-11, posed in w = R u, see _level_qp) is either handed back to Python, solved there
// by the chosen backend (and the fallback backend) as everywhere else, or — DAQP — solved here
// through DAQP's C interface with the adapter's rows, settings and verdict (DaqpSolver; a QP it
// fails on still goes back to Python for the fallback). The NNLS of the implicit-equality
// search is the caller's (scipy.optimize.nnls, passed in).
// Everything else — the analytic first level's rows, dropping frozen rows, loosening tight rows,
// projecting each level onto the remaining null space, its regularised least-squares minimiser
// (Householder QR of [√ε I; M], structured), the implicit-equality search, the QP's rows, locking
// directions (QR with column pivoting) and the per-level costs — runs here. Usage (see
// compiled_cascade._solve_compiled):
//   run = CascadeRun(B, b, w, C, lower, upper, V, names, n, eps, x1, Z1, tolerances..., nnls)
//   while run.advance() == "qp": run.give_qp(y, status)
//   x, costs, ... = run.result()
//   (or run.advance_daqp(DaqpSolver(...)): the level QPs solved by DAQP here, see DaqpSolver)
//   run.reset()  # and again, on the arrays' new contents
// WeightedRun (below) is the weighted method's single QP (weighted._solve_weighted) compiled the
// same way; both hold the level arrays through LevelArrays.
#include <Eigen/Dense>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#ifndef _WIN32
#include <dlfcn.h> // DaqpSolver finds DAQP's C functions in the loaded daqp module
#endif

namespace py = pybind11;

namespace
{
  using Eigen::Index;
  using Eigen::MatrixXd;
  using Eigen::VectorXd;
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using Mask = std::vector<Index>;
  using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
  using ConstRowMap = Eigen::Map<const RowMatrix>;
  using ConstVecMap = Eigen::Map<const VectorXd>;
  using Clock = std::chrono::steady_clock;

  constexpr double kTightTol = 1e-8; // cascade._TIGHT_TOL
  constexpr double kInf = std::numeric_limits<double>::infinity();

  VectorXd sq_norms(const MatrixXd & A) { return A.rowwise().squaredNorm(); }

  // A new numpy vector with v's values: the per-cycle results (pybind11's Eigen caster wraps a
  // heap copy in a capsule, which costs more than the copy).
  py::array_t<double> numpy_copy(const VectorXd & v) { return py::array_t<double>(v.size(), v.data()); }

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

  std::string format_g(double value, const char * format = "%.3g")
  {
    char buf[32];
    std::snprintf(buf, sizeof buf, format, value);
    return buf;
  }

  // Inequality rows: (C, lower, upper, drop_tol² ‖C_i‖²) as the ``high`` tuple of _solve_cascade;
  // for a level's own rows also V (their slack weights).
  struct Rows
  {
    MatrixXd C;
    VectorXd lower, upper, norms, V;
    bool empty() const { return C.rows() == 0; }
    Rows subset(const Mask & keep) const
    {
      Rows out{rows_of(C, keep), entries_of(lower, keep), entries_of(upper, keep),
               entries_of(norms, keep), VectorXd()};
      if (V.size())
        out.V = entries_of(V, keep);
      return out;
    }
    void append(const Rows & other)
    {
      if (other.empty())
        return;
      if (empty())
      {
        *this = other;
        V.resize(0);
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

  constexpr double kSubspaceTol = 1e-6; // cascade._SUBSPACE_TOL

  // _rank_certified: the QR with column pivoting (``qr``: its packed factor, R on and above the
  // diagonal) gives the SVD's kernel: its rank ``rank`` is the SVD's count of singular values
  // above ``tol`` — σ_rank ≥ σ_min(R11) ≥ s = 1 / ‖R11⁻¹‖_F > tol (interlacing) and σ_rank+1 ≤
  // ‖R22‖_2 ≤ t = ‖R22‖_F ≤ tol (Weyl) — and its kernel is the SVD's within kSubspaceTol: sin θ
  // ≤ t / (s − t) (Wedin).
  bool rank_certified(const MatrixXd & qr, Index rank, double tol)
  {
    const Index p = std::min(qr.rows(), qr.cols());
    double trailing = 0.0;
    for (Index i = rank; i < p; ++i)
      trailing += qr.row(i).tail(qr.cols() - i).squaredNorm();
    trailing = std::sqrt(trailing);
    if (!(trailing <= tol))
      return false;
    if (rank == 0)
      return true;
    const MatrixXd inverse = qr.topLeftCorner(rank, rank).triangularView<Eigen::Upper>().solve(
        MatrixXd::Identity(rank, rank));
    const double lower = 1.0 / inverse.norm(); // (0 for an inf or NaN inverse)
    return lower > tol && trailing <= kSubspaceTol * (lower - trailing);
  }

  // _kernel: an orthonormal basis N of ker(RZ) (z × (z − rank)) from the QR with column pivoting
  // of RZᵀ = Q R P: N spans Q[:, rank:], formed from the first ``rank`` reflectors only (the
  // later ones map its span onto itself). When some |R_ii| is within three decades of the
  // threshold and the kernel is not certified (rank_certified), an SVD decides (``by_svd``).
  // False, and N untouched, when the kernel is all of it (nothing to lock).
  bool kernel_basis(const MatrixXd & RZ, double tol, MatrixXd & N, bool & by_svd)
  {
    const Index k = RZ.rows(), z = RZ.cols(), p = std::min(k, z);
    by_svd = false;
    if (p == 0) // no rows, or no freedom
      return false;
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
    by_svd = ambiguous && !rank_certified(qr.matrixQR(), rank, tol);
    if (by_svd)
    {
      Eigen::JacobiSVD<MatrixXd> svd(At, Eigen::ComputeFullU);
      rank = (svd.singularValues().array() > tol).count();
      if (rank > 0)
        N = svd.matrixU().rightCols(z - rank);
      return rank > 0;
    }
    if (rank == 0)
      return false;
    if (rank >= z)
    {
      N.resize(z, 0);
      return true;
    }
    // N = Q[:, rank:] formed (reflectors on a z × (z − rank) block), then products with N: at
    // these sizes a matrix product is several times faster per flop than applying reflectors
    // to Z and HZ one by one
    auto Q = qr.householderQ();
    Q.setLength(rank);
    N = MatrixXd::Identity(z, z).rightCols(z - rank);
    N.applyOnTheLeft(Q);
    return true;
  }

  // _kernel, applied: Z ← Z N with N = kernel_basis(RZ) (have_Z false: Z is the identity).
  // ``HZ`` (rows already multiplied by Z, or null) gets the same N (cheaper than multiplying by
  // the new Z afresh: z ≤ n). Returns false if nothing is locked.
  bool restrict_to_kernel(MatrixXd & Z, bool have_Z, Index n, const MatrixXd & RZ, double tol,
                          MatrixXd * HZ)
  {
    bool by_svd = false;
    MatrixXd N;
    if (!kernel_basis(RZ, tol, N, by_svd))
      return false;
    if (N.cols() == 0)
    {
      Z.resize(have_Z ? Z.rows() : n, 0);
      if (HZ)
        HZ->resize(HZ->rows(), 0);
      return true;
    }
    Z = have_Z ? MatrixXd(Z * N) : N;
    if (HZ)
      *HZ = *HZ * N;
    return true;
  }

  // The R factor and c = (Qᵀ rhs)[:z] of the QR of [√ε I; M] (M is k × z) with right-hand side
  // [top; bottom] — the regularised least squares min ‖M u − bottom‖² + ‖√ε u − top‖² of
  // _unconstrained, R u = c. Reflector j touches only row j of √ε I (still √ε e_jᵀ when its turn
  // comes) and the k rows of M, so it costs 4 (k + 1)(z − j) flops: 2 (k + 1) z² in all instead
  // of ~2 (k + z) z² for a dense Householder QR of the stacked (k + z) × z matrix.
  void regularised_qr(const MatrixXd & M, const VectorXd & bottom, const VectorXd & top,
                      double root, MatrixXd & R, VectorXd & c)
  {
    const Index k = M.rows(), z = M.cols();
    MatrixXd W(k + 1, z); // row 0: the row of √ε I being reduced; rows 1..k: M as reduced so far
    W.bottomRows(k) = M;
    VectorXd wr(k + 1);   // the same rows of the right-hand side
    wr.tail(k) = bottom;
    R.setZero(z, z);
    c.resize(z);
    VectorXd work(std::max<Index>(z, 1));
    for (Index j = 0; j < z; ++j)
    {
      W.row(0).tail(z - j).setZero();
      W(0, j) = root;
      wr[0] = top[j];
      double tau, beta;
      W.col(j).makeHouseholderInPlace(tau, beta);
      const auto essential = W.col(j).tail(k);
      if (j + 1 < z)
        W.rightCols(z - j - 1).applyHouseholderOnTheLeft(essential, tau, work.data());
      wr.applyHouseholderOnTheLeft(essential, tau, work.data());
      R(j, j) = beta;
      R.row(j).tail(z - j - 1) = W.row(0).tail(z - j - 1);
      c[j] = wr[0];
    }
  }

  // _loosen_tight: rows within δ = relax_tol (1 + |C x|) of a bound, or beyond it by at most
  // feas_tol (1 + |C x|), get bounds that include C x with the margin δ.
  void loosen_tight(const VectorXd & hx, VectorXd & lo, VectorXd & up, double relax_tol,
                    double feas_tol)
  {
    for (Index i = 0; i < hx.size(); ++i)
    {
      const double a = 1.0 + std::abs(hx[i]), dlt = relax_tol * a, out = feas_tol * a;
      if (hx[i] - lo[i] <= dlt && lo[i] - hx[i] <= out)
        lo[i] = std::min(lo[i], hx[i]) - dlt;
      if (up[i] - hx[i] <= dlt && hx[i] - up[i] <= out)
        up[i] = std::max(up[i], hx[i]) + dlt;
    }
  }

  // _range_basis: orthonormal columns spanning range(A) (A is z × k), from a Householder QR
  // without the columns whose |R_ii| ≤ 1e-12.
  MatrixXd range_basis(const MatrixXd & A)
  {
    const Index z = A.rows(), p = std::min(A.rows(), A.cols());
    Eigen::HouseholderQR<MatrixXd> qr(A);
    MatrixXd Q = MatrixXd::Identity(z, p);
    Q.applyOnTheLeft(qr.householderQ());
    Mask keep;
    for (Index i = 0; i < p; ++i)
      if (std::abs(qr.matrixQR()(i, i)) > 1e-12)
        keep.push_back(i);
    MatrixXd out(z, Index(keep.size()));
    for (std::size_t j = 0; j < keep.size(); ++j)
      out.col(Index(j)) = Q.col(keep[j]);
    return out;
  }

  // common.regular_nullspace: one complete Householder QR of Bᵀ = [Q1 Q2] [R; 0] (Bᵀ: n × k,
  // into ``qr``) and Z = Q2, its last n − min(k, n) columns (formed in any case); where B is
  // regular — k ≤ n, every |R_ii| > 1e-12 max |R_jj|, y = R⁻ᵀ b finite — x1 = Q1 y, the
  // least-norm solution of B x = b, and true (Z then spans null(B); Herzog et al. 2016, eq. 17).
  bool regular_nullspace(const MatrixXd & Bt, const VectorXd & b,
                         Eigen::HouseholderQR<MatrixXd> & qr, VectorXd & x1, MatrixXd & Z)
  {
    const Index n = Bt.rows(), k = Bt.cols(), p = std::min(k, n);
    qr.compute(Bt);
    Z.setZero(n, n - p);
    Z.bottomRows(n - p).setIdentity();
    Z.applyOnTheLeft(qr.householderQ());
    const auto R = qr.matrixQR().topLeftCorner(p, p);
    const auto d = R.diagonal().cwiseAbs();
    if (!(k <= n && p > 0 && d.allFinite() && d.minCoeff() > 1e-12 * d.maxCoeff()))
      return false;
    x1.setZero(n);
    x1.head(k) = R.triangularView<Eigen::Upper>().transpose().solve(b);
    if (!x1.allFinite())
      return false;
    x1.applyOnTheLeft(qr.householderQ());
    return true;
  }

  // _implicit_equalities: the rows tight at x whose signed, projected, normalised normals are
  // positively dependent (see the Python function's docstring), found with ``nnls`` — the
  // caller's NNLS solver (scipy.optimize.nnls), called as nnls(A, b) -> (y, residual).
  // Empty when there is none.
  std::vector<bool> implicit_equalities(const MatrixXd & HZ, const VectorXd & hx,
                                        const VectorXd & hlo, const VectorXd & hup,
                                        const py::object & nnls, double tight_tol = kTightTol,
                                        double dep_tol = 1e-7)
  {
    const Index m = HZ.rows(), z = HZ.cols();
    if (m < 2)
      return {};
    Mask tl, tu;
    for (Index i = 0; i < m; ++i)
    {
      const double tol = tight_tol * (1.0 + std::abs(hx[i]));
      if (std::abs(hx[i] - hlo[i]) <= tol)
        tl.push_back(i);
      if (std::abs(hup[i] - hx[i]) <= tol)
        tu.push_back(i);
    }
    if (tl.size() + tu.size() < 2)
      return {};
    Mask idx;
    std::vector<VectorXd> normals;
    for (int side = 0; side < 2; ++side)
      for (Index i : side == 0 ? tl : tu)
      {
        VectorXd g = side == 0 ? VectorXd(HZ.row(i).transpose()) : VectorXd(-HZ.row(i).transpose());
        const double nrm = g.norm();
        if (nrm > 0.0)
        {
          idx.push_back(i);
          normals.push_back(g / nrm);
        }
      }
    const Index k = Index(idx.size());
    MatrixXd G(k, z);
    for (Index j = 0; j < k; ++j)
      G.row(j) = normals[std::size_t(j)].transpose();
    // cheap certificates of NO dependency: a direction d with G d > 0
    VectorXd d = G.colwise().sum().transpose();
    if (k == 0 || ((G * d).array() > dep_tol).all())
      return {};
    MatrixXd GGt = G * G.transpose();
    GGt.diagonal().array() += 1e-10 * double(k);
    Eigen::LLT<MatrixXd> llt(GGt);
    if (llt.info() == Eigen::Success)
    {
      d = G.transpose() * llt.solve(VectorXd::Ones(k));
      if (d.allFinite() && ((G * d).array() > dep_tol).all())
        return {};
    }
    std::vector<bool> found(std::size_t(k), false);
    Index n_found = 0;
    MatrixXd P(z, 0); // orthonormal basis of the span of the rows found so far
    while (k - n_found >= 2)
    {
      Mask rest;
      for (Index j = 0; j < k; ++j)
        if (!found[std::size_t(j)])
          rest.push_back(j);
      MatrixXd Gr = rows_of(G, rest);
      if (P.cols())
        Gr -= (Gr * P) * P.transpose();
      const Index kr = Gr.rows();
      MatrixXd A(z + 1, kr);
      A.topRows(z) = Gr.transpose();
      A.row(z).setConstant(1e3);
      VectorXd b = VectorXd::Zero(z + 1);
      b[z] = 1e3;
      VectorXd y;
      try
      {
        y = nnls(A, b).cast<py::tuple>()[0].cast<VectorXd>();
      }
      catch (const py::error_already_set &)
      {
        break;
      }
      const double ys = y.sum();
      if (!(ys > 0.0) || (Gr.transpose() * y).norm() > dep_tol * ys)
        break;
      const double ymax = y.maxCoeff();
      for (Index j = 0; j < kr; ++j)
        if (y[j] > 1e-9 * ymax)
        {
          found[std::size_t(rest[std::size_t(j)])] = true;
          ++n_found;
        }
      Mask rows_found;
      for (Index j = 0; j < k; ++j)
        if (found[std::size_t(j)])
          rows_found.push_back(j);
      P = range_basis(rows_of(G, rows_found).transpose());
      // a tight row in the span of implicit equalities is one too: taken at once (its
      // projected row is ~0, a dependency of one row) rather than one NNLS each
      for (Index j = 0; j < k; ++j)
        if (!found[std::size_t(j)]
            && (G.row(j) - (G.row(j) * P) * P.transpose()).norm() <= dep_tol)
        {
          found[std::size_t(j)] = true;
          ++n_found;
        }
    }
    if (n_found == 0)
      return {};
    std::vector<bool> out(std::size_t(m), false);
    for (Index j = 0; j < k; ++j)
      if (found[std::size_t(j)])
        out[std::size_t(idx[std::size_t(j)])] = true;
    return out;
  }

  bool outside(const MatrixXd & A, const VectorXd & a0, const VectorXd & lo, const VectorXd & up,
               const VectorXd & u)
  {
    const VectorXd v = A * u + a0;
    return ((v.array() < lo.array()) || (v.array() > up.array())).any();
  }
  // The rows DAQP is given (backends.solve_daqp): each row of A and its bounds divided by the
  // row's norm (zero rows kept), bounds clipped to ±1e30 (DAQP_INF), sense 5 on equality rows.
  template <typename Matrix, typename Out>
  void scale_rows(const Matrix & A, const double * lo, const double * up, Out & Au, double * bu,
                  double * bl, int32_t * sense)
  {
    constexpr double kDaqpInf = 1e30;
    for (Index i = 0; i < A.rows(); ++i)
    {
      double norm = A.row(i).norm();
      if (norm == 0.0)
        norm = 1.0;
      Au.row(i) = A.row(i) / norm;
      bu[i] = std::min(up[i] / norm, kDaqpInf);
      bl[i] = std::max(lo[i] / norm, -kDaqpInf);
      sense[i] = lo[i] == up[i] ? 5 : 0;
    }
  }

  // The largest violation of lower <= A x <= upper beyond rounding: max(0, lower_i - a_i x,
  // a_i x - upper_i) less n eps |a_i| |x| per row; inf if x is not finite (backends._row_violation).
  template <typename Matrix, typename Vector>
  double violation(const Matrix & A, const Vector & x, const double * lo, const double * up)
  {
    if (!x.allFinite())
      return kInf;
    const VectorXd ax = A * x;
    const double unit = double(A.cols()) * std::numeric_limits<double>::epsilon() * x.norm();
    double over = 0.0;
    for (Index i = 0; i < A.rows(); ++i)
    {
      const double off = std::max(lo[i] - ax[i], ax[i] - up[i]);
      if (off > over) // the row norm only for a violated row
        over = std::max(over, off - unit * A.row(i).norm());
    }
    return over;
  }
} // namespace

// DAQP's C interface, declared as daqp 0.11.0 defines it (csrc/include/types.h and api.h of its
// source distribution) and reached through the symbols the installed daqp Python module exports:
// the cascade's level QPs are then solved without a trip through Python (no argument conversion,
// result packing or verdict per QP there). compiled_cascade._daqp_in_cascade uses this only for
// that daqp version and after checking the layout (daqp_default_settings read through these
// declarations must equal daqp.solve's keyword defaults); otherwise the QPs go through Python.
namespace daqp_c
{
  constexpr const char * kVersion = "0.11.0";
  extern "C" {
  struct Problem
  {
    int n, m, ms;
    double *H, *f, *A, *bupper, *blower;
    int * sense;
    int * break_points;
    int nh;
    int problem_type;
  };
  struct Settings
  {
    double primal_tol, dual_tol, zero_tol, pivot_tol, progress_tol;
    int cycle_tol, iter_limit;
    double fval_bound, eps_prox, eta_prox, rho_soft, rel_subopt, abs_subopt, sing_tol,
      refactor_tol, time_limit, w_soft;
    int eq_reduction, presolve;
  };
  struct Result
  {
    double *x, *lam;
    double fval, soft_slack;
    int exitflag, iter, nodes;
    double solve_time, setup_time;
  };
  }
  using QuadprogFn = void (*)(Result *, Problem *, Settings *);
  using DefaultsFn = void (*)(Settings *);

  // The settings by name (daqp.solve's keywords), as pointers to the double or int member.
  struct Field
  {
    const char * name;
    double Settings::*real;
    int Settings::*integer;
  };
  const Field kFields[] = {
    {"primal_tol", &Settings::primal_tol, nullptr}, {"dual_tol", &Settings::dual_tol, nullptr},
    {"zero_tol", &Settings::zero_tol, nullptr}, {"pivot_tol", &Settings::pivot_tol, nullptr},
    {"progress_tol", &Settings::progress_tol, nullptr},
    {"cycle_tol", nullptr, &Settings::cycle_tol},
    {"iter_limit", nullptr, &Settings::iter_limit}, {"fval_bound", &Settings::fval_bound, nullptr},
    {"eps_prox", &Settings::eps_prox, nullptr}, {"eta_prox", &Settings::eta_prox, nullptr},
    {"rho_soft", &Settings::rho_soft, nullptr}, {"rel_subopt", &Settings::rel_subopt, nullptr},
    {"abs_subopt", &Settings::abs_subopt, nullptr}, {"sing_tol", &Settings::sing_tol, nullptr},
    {"refactor_tol", &Settings::refactor_tol, nullptr},
    {"time_limit", &Settings::time_limit, nullptr}, {"w_soft", &Settings::w_soft, nullptr},
    {"eq_reduction", nullptr, &Settings::eq_reduction}, {"presolve", nullptr, &Settings::presolve},
  };
} // namespace daqp_c

// backends.solve_daqp on a level QP (Hessian I), in C++: the rows scaled as scale_rows does, the
// settings daqp.solve would use, one retry with proximal iterations after an "infeasible" or
// "cycling" verdict (solve_daqp_unit_rows) and the check of the unscaled rows (daqp_verdict). The
// caller (Python) gives the settings it would have passed, the exit-flag names and raw_tol.
class DaqpSolver
{
public:
  DaqpSolver(const std::string & module_path, const std::map<std::string, double> & settings,
             std::map<int, std::string> exit_names, double raw_tol)
  : exit_names_(std::move(exit_names)), raw_tol_(raw_tol)
  {
#ifdef _WIN32
    throw std::invalid_argument("DaqpSolver: not available on this platform (no dlopen)");
#else
    // the module is loaded (imported by the caller): RTLD_NOLOAD only looks it up
    void * handle = dlopen(module_path.c_str(), RTLD_NOW | RTLD_NOLOAD);
    if (!handle)
      throw std::invalid_argument("DaqpSolver: " + module_path + " is not a loaded library");
    quadprog_ = reinterpret_cast<daqp_c::QuadprogFn>(dlsym(handle, "daqp_quadprog"));
    const auto defaults =
      reinterpret_cast<daqp_c::DefaultsFn>(dlsym(handle, "daqp_default_settings"));
    dlclose(handle); // drops the reference taken above; the module stays loaded by Python
    if (!quadprog_ || !defaults)
      throw std::invalid_argument("DaqpSolver: " + module_path + " exports no DAQP C interface");
    defaults(&settings_);
#endif
    for (const auto & [name, value] : settings)
    {
      const daqp_c::Field * field = find(name);
      if (!field)
        throw std::invalid_argument("DaqpSolver: unknown DAQP setting '" + name + "'");
      if (field->real)
        settings_.*(field->real) = value;
      else
        settings_.*(field->integer) = int(value);
    }
    prox_retry_ = settings.count("eps_prox") == 0;
  }

  // The settings in use, by name (the caller compares the defaults with daqp.solve's).
  std::map<std::string, double> settings() const
  {
    std::map<std::string, double> out;
    for (const auto & field : daqp_c::kFields)
      out[field.name] = field.real ? settings_.*(field.real) : double(settings_.*(field.integer));
    return out;
  }

  // How often DAQP was called (retries included).
  long calls() const { return calls_; }

  // Solves min ½yᵀHy + gᵀy s.t. lower ≤ A y ≤ upper (A has rows; H null: the identity, the
  // cascade's level QPs); "" and y, or why it failed.
  template <typename Matrix>
  std::string solve(const VectorXd & g, const Matrix & A, const double * lower,
                    const double * upper, VectorXd & y, const double * H = nullptr)
  {
    const Index m = A.rows(), n = A.cols();
    unit_A_.resize(m, n);
    bu_.resize(m);
    bl_.resize(m);
    sense_.resize(std::size_t(m));
    scale_rows(A, lower, upper, unit_A_, bu_.data(), bl_.data(), sense_.data());
    if (!H && I_.rows() != n)
      I_ = RowMatrix::Identity(n, n);
    y.resize(n);
    lam_.resize(m);
    gradient_ = g;
    daqp_c::Problem problem{int(n), int(m), 0, const_cast<double *>(H ? H : I_.data()),
                            gradient_.data(), unit_A_.data(), bu_.data(), bl_.data(),
                            sense_.data(), nullptr, 0, 0};
    daqp_c::Result result{y.data(), lam_.data(), 0.0, 0.0, 0, 0, 0, 0.0, 0.0};
    daqp_c::Settings settings = settings_;
    quadprog_(&result, &problem, &settings);
    ++calls_;
    // see backends.solve_daqp_unit_rows
    if ((result.exitflag == -1 || result.exitflag == -2) && prox_retry_)
    {
      settings = settings_; // fresh, as daqp.solve's (DAQP gets a pointer to it)
      settings.eps_prox = 1e-6;
      quadprog_(&result, &problem, &settings);
      ++calls_;
    }
    if (result.exitflag != 1 && result.exitflag != 2)
    {
      const auto name = exit_names_.find(result.exitflag);
      return "daqp: " + (name == exit_names_.end() ? std::string("exitflag") : name->second) + " ("
             + std::to_string(result.exitflag) + ")";
    }
    const double over = violation(A, y, lower, upper);
    if (!std::isfinite(over))
      return "daqp: non-finite solution";
    if (over > raw_tol_)
      return "daqp: solution outside its rows by " + format_g(over, "%.3g") + " (> "
             + format_g(raw_tol_, "%g") + ")";
    return "";
  }

private:
  static const daqp_c::Field * find(const std::string & name)
  {
    for (const auto & field : daqp_c::kFields)
      if (name == field.name)
        return &field;
    return nullptr;
  }

  daqp_c::QuadprogFn quadprog_ = nullptr;
  daqp_c::Settings settings_{};
  bool prox_retry_ = true;
  long calls_ = 0;
  std::map<int, std::string> exit_names_;
  double raw_tol_;
  RowMatrix unit_A_, I_;
  VectorXd bu_, bl_, lam_, gradient_;
  std::vector<int32_t> sense_;
};

// The arrays of a list of levels (common.Level: B, b, w, C, lower, upper, V per level), held,
// not copied — a control loop changes their contents in place between solves — with the row
// checks, the views and the per-level evaluation the compiled methods share.
class LevelArrays
{
public:
  // Per-level costs ‖W(Bx − b)‖² + ‖V viol‖², weighted residuals and violations at x
  // (common.evaluate_levels).
  py::tuple evaluate(const VectorXd & x) const
  {
    VectorXd costs = VectorXd::Zero(Index(nl_));
    py::list res, vio;
    VectorXd e, s;
    for (std::size_t r = 0; r < nl_; ++r)
    {
      costs[Index(r)] = level_cost(r, x, e, s);
      res.append(e);
      vio.append(s);
    }
    return py::make_tuple(costs, res, vio);
  }

  // The per-level costs alone (evaluate's first entry).
  VectorXd costs(const VectorXd & x) const
  {
    VectorXd costs = VectorXd::Zero(Index(nl_)), e, s;
    for (std::size_t r = 0; r < nl_; ++r)
      costs[Index(r)] = level_cost(r, x, e, s);
    return costs;
  }

protected:
  // Level r's cost at x, its weighted residuals ``e`` and violations ``s``.
  double level_cost(std::size_t r, const VectorXd & x, VectorXd & e, VectorXd & s) const
  {
    const ConstRowMap B = matrix(Bs_, r), C = matrix(Cs_, r);
    e = vec(ws_, r).cwiseProduct(B * x - vec(bs_, r));
    const VectorXd cx = C * x;
    s = vec(Vs_, r).cwiseProduct((vec(lowers_, r) - cx).cwiseMax(cx - vec(uppers_, r)).cwiseMax(0.0));
    return e.squaredNorm() + s.squaredNorm();
  }

  LevelArrays(const char * who, std::vector<DoubleArray> Bs, std::vector<DoubleArray> bs,
              std::vector<DoubleArray> ws, std::vector<DoubleArray> Cs,
              std::vector<DoubleArray> lowers, std::vector<DoubleArray> uppers,
              std::vector<DoubleArray> Vs, std::vector<std::string> names, Index n)
  : Bs_(std::move(Bs)), bs_(std::move(bs)), ws_(std::move(ws)), Cs_(std::move(Cs)),
    lowers_(std::move(lowers)), uppers_(std::move(uppers)), Vs_(std::move(Vs)),
    names_(std::move(names)), nl_(Bs_.size()), n_(n)
  {
    const std::string name(who);
    for (auto * list : {&bs_, &ws_, &Cs_, &lowers_, &uppers_, &Vs_})
      if (list->size() != nl_)
        throw std::invalid_argument(name + ": per-level lists differ in length");
    if (names_.size() != nl_)
      throw std::invalid_argument(name + ": names differ in length from the levels");
    for (std::size_t r = 0; r < nl_; ++r)
      if (rows_of_level(Bs_, r) != bs_[r].size() || rows_of_level(Bs_, r) != ws_[r].size()
          || rows_of_level(Cs_, r) != lowers_[r].size() || rows_of_level(Cs_, r) != uppers_[r].size()
          || rows_of_level(Cs_, r) != Vs_[r].size())
        throw std::invalid_argument(name + ": level " + std::to_string(r)
                                    + ": row counts of its arrays differ");
  }

  // a matrix without n columns is an empty level (common._rows)
  Index rows_of_level(const std::vector<DoubleArray> & list, std::size_t r) const
  {
    const DoubleArray & a = list[r];
    return a.ndim() == 2 && a.shape(1) == n_ ? Index(a.shape(0)) : 0;
  }
  ConstRowMap matrix(const std::vector<DoubleArray> & list, std::size_t r) const
  {
    return ConstRowMap(list[r].data(), rows_of_level(list, r), n_);
  }
  static ConstVecMap vec(const std::vector<DoubleArray> & list, std::size_t r)
  {
    return ConstVecMap(list[r].data(), Index(list[r].size()));
  }

  std::vector<DoubleArray> Bs_, bs_, ws_, Cs_, lowers_, uppers_, Vs_;
  std::vector<std::string> names_;
  std::size_t nl_ = 0;
  Index n_;
};

class CascadeRun : public LevelArrays
{
public:
  enum class Kind { Done, QP, Failed };

  CascadeRun(std::vector<DoubleArray> Bs, std::vector<DoubleArray> bs, std::vector<DoubleArray> ws,
             std::vector<DoubleArray> Cs, std::vector<DoubleArray> lowers,
             std::vector<DoubleArray> uppers, std::vector<DoubleArray> Vs,
             std::vector<std::string> names, Index n, double eps,
             const std::optional<VectorXd> & x1, const std::optional<MatrixXd> & Z1,
             bool analytic_first, double rank_tol, double drop_tol, double relax_tol,
             double feas_tol, py::object nnls)
  : LevelArrays("CascadeRun", std::move(Bs), std::move(bs), std::move(ws), std::move(Cs),
                std::move(lowers), std::move(uppers), std::move(Vs), std::move(names), n),
    nnls_(std::move(nnls)), eps_(eps), rank_tol_(rank_tol), drop2_(drop_tol * drop_tol),
    relax_tol_(relax_tol), feas_tol_(feas_tol)
  {
    if (x1.has_value() != Z1.has_value())
      throw std::invalid_argument("CascadeRun: give both x1 and Z1, or neither");
    if (x1 && analytic_first)
      throw std::invalid_argument("CascadeRun: give x1 and Z1 or analytic_first, not both");
    analytic_first_ = analytic_first;
    if (x1)
    {
      if (x1->size() != n || Z1->rows() != n)
        throw std::invalid_argument("CascadeRun: x1 / Z1 do not have n rows");
      x1_ = *x1;
      Z1_ = *Z1;
      have_first_ = true;
    }
    reset();
  }

  // Back to the first level, for another solve on the same arrays (whose contents may have
  // changed in place: a control loop's level buffers); an analytic first level is recomputed.
  void reset()
  {
    r_ = 0;
    x_ = VectorXd::Zero(n_);
    have_Z_ = false;
    Z_.resize(n_, 0);
    z_ = n_;
    high_ = Rows();
    HZ_valid_ = false;
    zdims_.assign(nl_, 0);
    times_.assign(nl_, 0.0);
    qp_times_.assign(nl_, 0.0);
    qp_count_ = 0;
    daqp_status_.clear();
    warns_.clear();
    status_ = "optimal";
    finished_ = failed_ = false;
    pending_ = Kind::Done;
    tight_ = false;
    if (analytic_first_)
      have_first_ = false;
  }

  // Runs until the cascade needs a level QP solved or ends: "qp", "done" or "failed".
  std::string advance()
  {
    if (pending_ == Kind::QP)
      return "qp";
    if (finished_)
      return failed_ ? "failed" : "done";
    while (r_ < nl_)
    {
      const auto t0 = Clock::now();
      const std::size_t r = r_;
      const bool yielded = begin_level();
      times_[r] += seconds_since(t0);
      if (failed_)
        return "failed";
      if (yielded)
        return "qp";
    }
    finished_ = true;
    return "done";
  }

  // advance() with the level QPs solved here by ``daqp`` (backends.solve_daqp, in C++): "done",
  // "failed", or "qp" when a level QP is left to the caller: DAQP failed on it (daqp_status
  // says why; the caller's fallback backend may solve it) or it has no rows (daqp_status empty:
  // the adapter's special case). qp_count and qp_times count the QPs DAQP was given here.
  std::string advance_daqp(DaqpSolver & daqp)
  {
    std::string kind;
    while ((kind = advance()) == "qp")
    {
      daqp_status_.clear();
      if (qp_A_.rows() == 0)
        break;
      const auto t0 = Clock::now();
      ++qp_count_;
      daqp_status_ = daqp.solve(qp_g_, qp_A_, qp_lower_.data(), qp_upper_.data(), qp_y_);
      qp_times_[r_] += seconds_since(t0);
      if (!daqp_status_.empty())
        break;
      give_qp(qp_y_, "optimal");
    }
    return kind;
  }

  // reset() then advance_daqp(): the whole run from its first level, as WeightedRun.solve_daqp
  // solves its QP (the compiled cycle calls either alike).
  std::string solve_daqp(DaqpSolver & daqp)
  {
    reset();
    return advance_daqp(daqp);
  }

  // The QP of the pending level (cascade._level_qp): Hessian I (not returned), gradient g,
  // rows lower ≤ A [w; s] ≤ upper.
  py::tuple qp() const
  {
    if (pending_ != Kind::QP)
      throw std::runtime_error("CascadeRun.qp: no QP pending");
    return py::make_tuple(qp_g_, qp_A_, qp_lower_, qp_upper_);
  }

  // The pending QP's rows as DAQP takes them (g, unit rows, upper, lower, sense; see daqp_rows),
  // and the largest violation of its unscaled rows at y (see row_violation).
  py::tuple daqp_qp() const;
  double qp_violation(const DoubleArray & y) const;

  // The solution y = [w; s] of the pending QP, or None if the backends failed (``status`` why).
  void give_qp(const std::optional<VectorXd> & y, const std::string & status)
  {
    if (pending_ != Kind::QP)
      throw std::runtime_error("CascadeRun.give_qp: no QP pending");
    pending_ = Kind::Done;
    const auto t0 = Clock::now();
    const std::size_t r = r_;
    const Index z = R_.rows();
    if (!y || y->size() != qp_g_.size())
      fail(status);
    else
    {
      u_ = R_.triangularView<Eigen::Upper>().solve(y->head(z));
      if (!u_.allFinite())
        fail(status + ": non-finite solution after the change of variables");
      else
        end_level();
    }
    times_[r] += seconds_since(t0);
  }

  // Everything a HierarchySolution takes from the run, in one call (a control loop pays per
  // call): (x, costs, residuals, violations — see evaluate —, per-level seconds with the QPs
  // solved here, seconds in those QPs, their count, null-space dimensions, warnings, levels
  // solved, status).
  py::tuple result() const
  {
    const py::tuple ev = evaluate(x_);
    VectorXd level_times = VectorXd::Zero(Index(nl_));
    double qp = 0.0;
    for (std::size_t r = 0; r < nl_; ++r)
    {
      level_times[Index(r)] = times_[r] + qp_times_[r];
      qp += qp_times_[r];
    }
    const std::vector<Index> dims = nullspace_dims();
    py::array_t<Index> dims_out(py::ssize_t(dims.size()));
    std::copy(dims.begin(), dims.end(), dims_out.mutable_data());
    return py::make_tuple(VectorXd(x_), ev[0], ev[1], ev[2], level_times, qp, qp_count_, dims_out,
                          py::tuple(py::cast(warns_)), r_, status_);
  }

  // A finished run without warnings, in one call: (x, level costs, seconds in the QPs solved
  // here, their count); None for any other (then result() has what a HierarchySolution needs).
  py::object quick() const
  {
    if (!finished_ || failed_ || !warns_.empty())
      return py::none();
    VectorXd costs = this->costs(x_);
    if (!std::isfinite(costs.sum()))
      return py::none();
    double qp = 0.0;
    for (double t : qp_times_)
      qp += t;
    return py::make_tuple(numpy_copy(x_), numpy_copy(costs), qp, qp_count_);
  }

  std::vector<Index> nullspace_dims() const
  {
    return std::vector<Index>(zdims_.begin(), zdims_.begin() + Index(std::min(r_, nl_)));
  }
  std::size_t level() const { return r_; }
  const std::string & daqp_status() const { return daqp_status_; }

private:
  static double seconds_since(Clock::time_point t0)
  {
    return std::chrono::duration<double>(Clock::now() - t0).count();
  }

  std::string level_name(std::size_t r) const { return "'" + names_[r] + "'"; }

  void fail(const std::string & why)
  {
    status_ = "level " + std::to_string(r_) + " (" + level_name(r_) + "): " + why;
    failed_ = finished_ = true;
  }

  // _drop_frozen: keep the rows of ``rows`` with ‖C_i Z‖² > drop_tol² ‖C_i‖²; a dropped row that
  // violates its relaxed bounds is recorded as a warning.
  void drop_frozen(Rows & rows, MatrixXd & RZ)
  {
    const VectorXd n2 = sq_norms(RZ);
    Mask free_rows;
    Index bad = 0;
    double worst = 0.0;
    for (Index i = 0; i < RZ.rows(); ++i)
    {
      if (n2[i] > rows.norms[i])
      {
        free_rows.push_back(i);
        continue;
      }
      const double cx = rows.C.row(i).dot(x_);
      const double over = std::max(rows.lower[i] - cx, cx - rows.upper[i]);
      if (over > feas_tol_ * (1.0 + std::abs(cx)))
      {
        worst = bad ? std::max(worst, over) : over;
        ++bad;
      }
    }
    if (bad)
      warns_.push_back("before level " + level_name(r_) + ": " + std::to_string(bad)
                       + " higher-priority inequality row(s) without freedom violate their "
                         "relaxed bounds by up to " + format_g(worst));
    if (Index(free_rows.size()) != RZ.rows())
    {
      rows = rows.subset(free_rows);
      RZ = rows_of(RZ, free_rows);
    }
  }

  // _lock: Z ← Z N with N a basis of ker(rows Z); ``projected`` = rows Z. The higher rows'
  // projection HZ (when current) follows.
  void lock(const MatrixXd & rows, const MatrixXd & projected)
  {
    if (rows.rows() == 0 || z_ == 0)
      return;
    const double scale = std::sqrt(sq_norms(rows).maxCoeff());
    if (scale == 0.0)
      return;
    if (!restrict_to_kernel(Z_, have_Z_, n_, projected, rank_tol_ * scale,
                            HZ_valid_ ? &HZ_ : nullptr))
      return;
    have_Z_ = true;
    z_ = Z_.cols();
  }

  MatrixXd times_Z(const MatrixXd & A) const { return have_Z_ ? MatrixXd(A * Z_) : A; }

  // _project_level + _unconstrained + _qp_rows + _violated: the level over x = x* + Z u, its
  // least-squares minimiser u and whether u satisfies the own and relaxed higher rows.
  bool project_and_try()
  {
    const std::size_t r = r_;
    const ConstRowMap B = matrix(Bs_, r), C = matrix(Cs_, r);
    const ConstVecMap w = vec(ws_, r), b = vec(bs_, r);
    const Index k = B.rows(), m = C.rows();
    wB_ = w.asDiagonal() * B;
    M_ = have_Z_ ? MatrixXd(wB_ * Z_) : wB_;
    const Index zc = M_.cols();
    const double root = std::sqrt(eps_);
    own_ = Rows();
    own_CZ_.resize(0, zc);
    if (m)
    {
      const MatrixXd Cd = C;
      const MatrixXd CZ = times_Z(Cd);
      const VectorXd nC = drop2_ * Cd.rowwise().squaredNorm(), n2 = sq_norms(CZ);
      Mask free_rows;
      for (Index i = 0; i < m; ++i)
        if (n2[i] > nC[i])
          free_rows.push_back(i);
      if (!free_rows.empty())
      {
        Rows all{Cd, vec(lowers_, r), vec(uppers_, r), nC, vec(Vs_, r)};
        own_ = Index(free_rows.size()) == m ? all : all.subset(free_rows);
        own_CZ_ = Index(free_rows.size()) == m ? CZ : rows_of(CZ, free_rows);
      }
    }
    // least squares [√ε I; M] u ≈ [−√ε Zᵀx*; −r0]: R and c = (Qᵀ rhs)[:z]
    regularised_qr(M_, -(wB_ * x_ - w.cwiseProduct(b)),
                   -root * (have_Z_ ? VectorXd(Z_.transpose() * x_) : x_), root, R_, c_);
    u_ = R_.triangularView<Eigen::Upper>().solve(c_);
    if (!u_.allFinite())
      return false;
    if (!own_.empty() && outside(own_CZ_, own_.C * x_, own_.lower, own_.upper, u_))
      return false;
    if (!high_.empty() && outside(HZ_, hx_, hlo_, hup_, u_))
      return false;
    return true;
  }

  // x1 = B⁺ b (least norm) and an orthonormal basis Z1 of null(B) for level 1's weighted rows
  // (Herzog et al. 2016 eq. 17; hierarchy.analytic_first_level): regular_nullspace; a
  // rank-deficient B (some |R_ii| ≤ 1e-12 max |R_jj|) takes the pseudo-inverse.
  void first_level_solution()
  {
    const ConstRowMap B = matrix(Bs_, 0);
    const ConstVecMap w = vec(ws_, 0), b = vec(bs_, 0);
    const MatrixXd Bt = (w.asDiagonal() * B).transpose();
    const VectorXd wb = w.cwiseProduct(b);
    Eigen::HouseholderQR<MatrixXd> qr;
    if (!regular_nullspace(Bt, wb, qr, x1_, Z1_))
      x1_ = Bt.completeOrthogonalDecomposition().pseudoInverse().transpose() * wb;
  }

  // The higher rows over the current null space: HZ, without the rows that have no freedom left
  // (_drop_frozen), their values hx at x* and bounds (hlo, hup), loosened where tight
  // (_loosen_tight) — always with ``loosen``, else only if some row is tight. Returns whether a
  // row is tight (or violated within tolerance).
  bool project_higher_rows(bool loosen)
  {
    if (high_.empty())
      return false;
    if (!HZ_valid_)
      HZ_ = times_Z(high_.C);
    HZ_valid_ = true;
    drop_frozen(high_, HZ_);
    if (high_.empty())
      return false;
    hx_ = high_.C * x_;
    hlo_ = high_.lower;
    hup_ = high_.upper;
    bool tight = false;
    const double gap_tol = std::max(kTightTol, relax_tol_);
    for (Index i = 0; i < hx_.size() && !tight; ++i)
    {
      const double gap = std::min(hx_[i] - hlo_[i], hup_[i] - hx_[i]); // < 0: violated
      tight = !(gap > gap_tol * (1.0 + std::abs(hx_[i])));
    }
    if (tight || loosen)
      loosen_tight(hx_, hlo_, hup_, relax_tol_, feas_tol_);
    return tight;
  }

  // Level r up to its QP request; true if it yields to Python.
  bool begin_level()
  {
    const std::size_t r = r_;
    const ConstRowMap C = matrix(Cs_, r);
    if (r == 0 && analytic_first_)
    {
      first_level_solution();
      have_first_ = true;
    }
    if (r == 0 && have_first_) // analytic first priority (§2.4, eq. 17), v*_1 = 0
    {
      x_ = x1_;
      Z_ = Z1_;
      have_Z_ = true;
      z_ = Z_.cols();
      if (C.rows())
      {
        const MatrixXd Cd = C;
        high_ = {Cd, vec(lowers_, r), vec(uppers_, r), drop2_ * Cd.rowwise().squaredNorm(), VectorXd()};
        HZ_ = z_ ? MatrixXd(Cd * Z_) : MatrixXd(C.rows(), 0);
        drop_frozen(high_, HZ_);
        HZ_valid_ = true;
      }
      zdims_[r] = z_;
      ++r_;
      return false;
    }
    if (z_ == 0) // no freedom left: the level is only evaluated
    {
      zdims_[r] = 0;
      ++r_;
      return false;
    }
    // higher rows: drop those without freedom; rows tight at x* get a margin
    tight_ = project_higher_rows(false);
    if (project_and_try())
    {
      end_level();
      return false;
    }
    // implicit equalities keep the QP well posed: looked for only when a QP is solved
    if (tight_)
      return after_implicit(implicit_equalities(HZ_, hx_, high_.lower, high_.upper, nnls_));
    return request_qp();
  }

  // Locks the implicit equalities ``mask`` (none if empty) and retries the level; true if it
  // still needs its QP.
  bool after_implicit(const std::vector<bool> & mask)
  {
    if (!mask.empty())
    {
      Mask imp, keep;
      for (Index i = 0; i < Index(mask.size()); ++i)
        (mask[std::size_t(i)] ? imp : keep).push_back(i);
      if (!imp.empty())
      {
        const MatrixXd rows = rows_of(high_.C, imp), projected = rows_of(HZ_, imp);
        high_ = high_.subset(keep);
        HZ_ = rows_of(HZ_, keep);
        lock(rows, projected);
        if (z_ == 0)
        {
          zdims_[r_] = 0;
          ++r_;
          return false;
        }
        project_higher_rows(true);
        if (project_and_try())
        {
          end_level();
          return false;
        }
      }
    }
    return request_qp();
  }

  // _level_qp's rows in w = R u: own rows with a slack each (C Z u ± s / V against bound − C x*),
  // the relaxed higher rows; A[:, :z] = Au R⁻¹.
  bool request_qp()
  {
    const Index z = R_.rows(), m = own_.C.rows(), nh = high_.C.rows();
    if (m == 0 && nh == 0) // nothing to satisfy: the least-squares minimiser failed
    {
      fail("least squares: non-finite solution");
      return false;
    }
    Mask il, iu;
    for (Index i = 0; i < m; ++i)
    {
      if (std::isfinite(own_.lower[i]))
        il.push_back(i);
      if (std::isfinite(own_.upper[i]))
        iu.push_back(i);
    }
    const Index nlo = Index(il.size()), nup = Index(iu.size()), nr = nlo + nup + nh;
    const VectorXd c0 = m ? VectorXd(own_.C * x_) : VectorXd();
    MatrixXd Au(nr, z);
    qp_A_.setZero(nr, z + m);
    qp_lower_.resize(nr);
    qp_upper_.resize(nr);
    for (Index j = 0; j < nlo; ++j)
    {
      const Index i = il[std::size_t(j)];
      Au.row(j) = own_CZ_.row(i);
      qp_A_(j, z + i) = 1.0 / own_.V[i];
      qp_lower_[j] = own_.lower[i] - c0[i];
      qp_upper_[j] = kInf;
    }
    for (Index j = 0; j < nup; ++j)
    {
      const Index i = iu[std::size_t(j)];
      Au.row(nlo + j) = own_CZ_.row(i);
      qp_A_(nlo + j, z + i) = -1.0 / own_.V[i];
      qp_lower_[nlo + j] = -kInf;
      qp_upper_[nlo + j] = own_.upper[i] - c0[i];
    }
    if (nh)
    {
      Au.bottomRows(nh) = HZ_;
      qp_lower_.tail(nh) = hlo_ - hx_;
      qp_upper_.tail(nh) = hup_ - hx_;
    }
    if (nr)
      qp_A_.leftCols(z) = R_.triangularView<Eigen::Upper>().solve<Eigen::OnTheRight>(Au);
    qp_g_ = VectorXd::Zero(z + m);
    qp_g_.head(z) = -c_;
    pending_ = Kind::QP;
    return true;
  }

  // After u is known: x ← x* + Z u, the own free rows join the higher ones relaxed by v*
  // (eq. 9), the weighted equality rows' directions are locked (eq. 8).
  void end_level()
  {
    const std::size_t r = r_;
    if (!high_.empty()) // the margins stay for the lower levels
    {
      high_.lower = hlo_;
      high_.upper = hup_;
    }
    x_ += have_Z_ ? VectorXd(Z_ * u_) : u_;
    if (!own_.empty())
    {
      const VectorXd cx = own_.C * x_;
      const VectorXd viol = (own_.lower - cx).cwiseMax(cx - own_.upper).cwiseMax(0.0);
      own_.lower -= viol;
      own_.upper += viol;
      if (high_.empty())
      {
        HZ_ = own_CZ_;
        HZ_valid_ = true;
      }
      else if (HZ_valid_)
      {
        HZ_.conservativeResize(HZ_.rows() + own_CZ_.rows(), Eigen::NoChange);
        HZ_.bottomRows(own_CZ_.rows()) = own_CZ_;
      }
      high_.append(own_);
    }
    if (wB_.rows() && r + 1 < nl_)
      lock(wB_, M_);
    zdims_[r] = z_;
    ++r_;
  }

  // problem
  py::object nnls_;
  double eps_, rank_tol_, drop2_, relax_tol_, feas_tol_;
  bool have_first_ = false, analytic_first_ = false;
  VectorXd x1_;
  MatrixXd Z1_;
  // cascade state
  std::size_t r_ = 0;
  VectorXd x_;
  bool have_Z_ = false; // false stands for Z = identity (nothing locked yet)
  MatrixXd Z_;
  Index z_ = 0;
  Rows high_;
  std::vector<Index> zdims_;
  std::vector<double> times_, qp_times_;
  int qp_count_ = 0;
  std::string daqp_status_;
  std::vector<std::string> warns_;
  std::string status_ = "optimal";
  bool finished_ = false, failed_ = false;
  Kind pending_ = Kind::Done;
  // the level in progress
  bool tight_ = false;
  MatrixXd HZ_, wB_, M_, R_, own_CZ_;
  bool HZ_valid_ = false; // HZ_ = high_.C Z_ (kept through the locks)
  VectorXd hx_, hlo_, hup_, u_, c_;
  Rows own_;
  // its QP
  MatrixXd qp_A_;
  VectorXd qp_g_, qp_lower_, qp_upper_, qp_y_;
};

// The weighted method (weighted._solve_weighted, line for line; Fahmi et al. 2019, eq. 7):
// levels = [hard, objective] (or [objective]) as one QP over y = [u; s]. The hard level's
// equality rows of positive weight E x = e are eliminated when independent (Herzog et al. 2016,
// eq. 17: x = x1 + Z u with x1 = E⁺e and Z an orthonormal basis of null(E), from one complete
// Householder QR of Eᵀ), else (dependent rows, or as many rows as variables) they stay rows of
// the QP and x = u. H = (WBZ)ᵀWBZ + ε I on u and I on the objective's slacks s, g = (WBZ)ᵀ(WB x1
// − W b) + ε Zᵀx1; as rows the hard level's inequalities (and its equalities where not
// eliminated), and the objective's inequality rows V C x + s ≥ V lower, V C x − s ≤ V upper, one
// slack each, all over u. DAQP's QP is solved here (DaqpSolver: the adapter's rows, settings,
// retry and verdict, as for the cascade's level QPs); another backend's comes from qp() and its
// solution back through give(). The solution is refused (the caller then runs the cascade)
// unless the hard level holds within feas_tol. Buffers are sized for the levels' row counts;
// the arrays are held, not copied (a control loop's level buffers). Usage:
//   run = WeightedRun(B, b, w, C, lower, upper, V, names, n, eps, feas_tol)
//   kind = run.solve_daqp(DaqpSolver(...))  # or: kind = run.give(backend(*run.qp()))
//   x, costs, residuals, violations, level_seconds, qp_seconds = run.result()  # kind "done"
class WeightedRun : public LevelArrays
{
public:
  WeightedRun(std::vector<DoubleArray> Bs, std::vector<DoubleArray> bs, std::vector<DoubleArray> ws,
              std::vector<DoubleArray> Cs, std::vector<DoubleArray> lowers,
              std::vector<DoubleArray> uppers, std::vector<DoubleArray> Vs,
              std::vector<std::string> names, Index n, double eps, double feas_tol)
  : LevelArrays("WeightedRun", std::move(Bs), std::move(bs), std::move(ws), std::move(Cs),
                std::move(lowers), std::move(uppers), std::move(Vs), std::move(names), n),
    eps_(eps), feas_tol_(feas_tol)
  {
    if (nl_ < 1 || nl_ > 2)
      throw std::invalid_argument("WeightedRun: takes [hard, objective] levels, got "
                                  + std::to_string(nl_) + " levels");
    obj_ = nl_ - 1;
    const Index m = rows_of_level(Cs_, obj_);
    most_ = (nl_ == 2 ? rows_of_level(Bs_, 0) + rows_of_level(Cs_, 0) : 0) + 2 * m;
    lower_.setZero(most_);
    upper_.setZero(most_);
    wB_.setZero(rows_of_level(Bs_, obj_), n_);
    x_.setZero(n_);
  }

  // The QP of the arrays' current contents, as _solve_weighted builds it up to solve_qp.
  void assemble()
  {
    const ConstRowMap Bo = matrix(Bs_, obj_), Co = matrix(Cs_, obj_);
    const ConstVecMap wo = vec(ws_, obj_), bo = vec(bs_, obj_);
    const Index m = Co.rows();
    eliminate();
    const Index nu = eliminated_ ? Z_.cols() : n_, nv = nu + m;
    if (H_.rows() != nv) // (the same size every cycle unless the equalities' rank changes)
    {
      H_.resize(nv, nv);
      g_.resize(nv);
      A_.resize(most_, nv);
    }
    wB_.noalias() = wo.asDiagonal() * Bo;
    rhs_ = wo.cwiseProduct(bo);
    H_.setZero();
    g_.setZero();
    if (eliminated_)
    {
      M_.noalias() = wB_ * Z_;
      rhs_.noalias() -= wB_ * x1_;
      add_gram(M_);
      g_.head(nu).noalias() += eps_ * (Z_.transpose() * x1_);
    }
    else
      add_gram(wB_);
    H_.diagonal().head(nu).array() += eps_;
    H_.diagonal().tail(m).setOnes();
    rows_ = 0;
    if (nl_ == 2)
    {
      const ConstRowMap Bh = matrix(Bs_, 0), Ch = matrix(Cs_, 0);
      const ConstVecMap wh = vec(ws_, 0), bh = vec(bs_, 0), lh = vec(lowers_, 0),
                        uh = vec(uppers_, 0);
      if (!eliminated_)
        for (Index i = 0; i < Bh.rows(); ++i)
          if (wh[i] > 0) // a zero-weight row is not part of the hard level's cost
            add_row(Bh.row(i), 1.0, -1, 0.0, bh[i], bh[i]);
      if (eliminated_ && Ch.rows()) // the block over u in one product, its values at x1
      {
        CZ_.noalias() = Ch * Z_;
        cx1_.noalias() = Ch * x1_;
        for (Index i = 0; i < Ch.rows(); ++i)
        {
          A_.row(rows_).head(nu) = CZ_.row(i);
          end_row(nu, -1, 0.0, lh[i] - cx1_[i], uh[i] - cx1_[i]);
        }
      }
      else
        for (Index i = 0; i < Ch.rows(); ++i)
          add_row(Ch.row(i), 1.0, -1, 0.0, lh[i], uh[i]);
    }
    if (m) // soft rows of the objective level, one slack each (as in the cascade)
    {
      const ConstVecMap vo = vec(Vs_, obj_), lo = vec(lowers_, obj_), uo = vec(uppers_, obj_);
      for (Index i = 0; i < m; ++i)
        if (std::isfinite(lo[i]))
          add_row(Co.row(i), vo[i], nu + i, 1.0, vo[i] * lo[i], kInf);
      for (Index i = 0; i < m; ++i)
        if (std::isfinite(uo[i]))
          add_row(Co.row(i), vo[i], nu + i, -1.0, -kInf, vo[i] * uo[i]);
    }
  }

  // The QP as (H, g, A, lower, upper), new arrays, for a backend called from Python.
  py::tuple qp()
  {
    assemble();
    return py::make_tuple(RowMatrix(H_), VectorXd(g_), RowMatrix(A_.topRows(rows_)),
                          VectorXd(lower_.head(rows_)), VectorXd(upper_.head(rows_)));
  }

  // The QP solved by ``daqp`` here: "done" (x accepted), "failed" (DAQP failed or the hard level
  // does not hold: ``status`` says why) or "qp" — no rows, left to the caller (the adapter adds
  // a free row then; the cascade leaves such QPs to Python alike).
  std::string solve_daqp(DaqpSolver & daqp)
  {
    assemble();
    if (rows_ == 0)
      return "qp";
    const auto t0 = Clock::now();
    status_ = daqp.solve(g_, A_.topRows(rows_), lower_.data(), upper_.data(), y_, H_.data());
    qp_time_ = std::chrono::duration<double>(Clock::now() - t0).count();
    if (!status_.empty())
      return "failed";
    return accept();
  }

  // The solution y = [x; s] of qp() from a backend: "done" or "failed" (the hard level).
  std::string give(const VectorXd & y)
  {
    if (y.size() != H_.rows())
      throw std::invalid_argument("WeightedRun.give: y must have one value per QP variable");
    y_ = y;
    qp_time_ = 0.0;
    status_.clear();
    return accept();
  }

  // (x, costs, residuals, violations — LevelArrays::evaluate —, per-level seconds: NaN, one QP
  // for all levels, seconds in DAQP here).
  py::tuple result() const
  {
    const py::tuple ev = evaluate(x_);
    return py::make_tuple(VectorXd(x_), ev[0], ev[1], ev[2],
                          VectorXd::Constant(Index(nl_), std::numeric_limits<double>::quiet_NaN()),
                          qp_time_);
  }

  const std::string & status() const { return status_; }

  // After solve_daqp or give returned "done": (x, level costs, seconds in DAQP here, 1); None
  // where the costs are not finite (then result() has what a HierarchySolution needs).
  py::object quick() const
  {
    VectorXd costs = this->costs(x_);
    if (!std::isfinite(costs.sum()))
      return py::none();
    return py::make_tuple(numpy_copy(x_), numpy_copy(costs), qp_time_, 1);
  }

private:
  // x1 = E⁺e and Z, an orthonormal basis of null(E), of the hard level's equality rows of
  // positive weight E x = e (regular_nullspace) — ``eliminated_`` where E has rows, fewer than
  // the variables, and is regular.
  void eliminate()
  {
    eliminated_ = false;
    if (nl_ != 2)
      return;
    const ConstRowMap Bh = matrix(Bs_, 0);
    const ConstVecMap wh = vec(ws_, 0), bh = vec(bs_, 0);
    Index k = 0;
    for (Index i = 0; i < Bh.rows(); ++i)
      k += wh[i] > 0;
    if (k == 0 || k >= n_)
      return;
    Et_.resize(n_, k);
    e_.resize(k);
    for (Index i = 0, j = 0; i < Bh.rows(); ++i)
      if (wh[i] > 0)
      {
        Et_.col(j) = Bh.row(i).transpose();
        e_[j++] = bh[i];
      }
    eliminated_ = regular_nullspace(Et_, e_, qr_, x1_, Z_);
  }

  // H's first block += MᵀM and g's −= Mᵀ rhs_ (M: the objective's weighted rows over the QP's
  // variables), each row of M over its span of nonzero columns only (an objective's rows are
  // mostly short where nothing is eliminated: a posture or force regulariser's one entry, a
  // wrench task's the forces), row after row into the lower triangle, then mirrored.
  template <typename Rows>
  void add_gram(const Rows & M)
  {
    const Index n = M.cols();
    for (Index i = 0; i < M.rows(); ++i)
    {
      const double * r = M.row(i).data();
      Index first = 0, last = n - 1;
      while (first < n && r[first] == 0.0)
        ++first;
      if (first == n)
        continue;
      while (r[last] == 0.0)
        --last;
      const double ri = rhs_[i];
      for (Index a = first; a <= last; ++a)
      {
        const double ra = r[a];
        if (ra == 0.0)
          continue;
        double * h = H_.row(a).data();
        for (Index c = first; c <= a; ++c)
          h[c] += ra * r[c];
        g_[a] -= ra * ri;
      }
    }
    for (Index a = 0; a < n; ++a)
      for (Index c = 0; c < a; ++c)
        H_(c, a) = H_(a, c);
  }

  // Row ``rows_`` of the QP: scale · a on x, ``slack_sign`` in column ``slack`` (none if < 0).
  // Over u where the equalities are eliminated: scale · a Z, the bounds less scale · a x1.
  template <typename Row>
  void add_row(const Row & a, double scale, Index slack, double slack_sign, double lo, double up)
  {
    if (!eliminated_)
    {
      A_.row(rows_).head(n_) = scale * a;
      return end_row(n_, slack, slack_sign, lo, up);
    }
    const Index nu = Z_.cols();
    A_.row(rows_).head(nu).noalias() = scale * (a * Z_);
    const double shift = scale * a.dot(x1_);
    end_row(nu, slack, slack_sign, lo - shift, up - shift);
  }

  // Row ``rows_`` of the QP, its first ``nu`` entries written: the rest zero but
  // ``slack_sign`` in column ``slack`` (none if < 0), its bounds; the next row.
  void end_row(Index nu, Index slack, double slack_sign, double lo, double up)
  {
    auto row = A_.row(rows_);
    row.tail(A_.cols() - nu).setZero();
    if (slack >= 0)
      row[slack] = slack_sign;
    lower_[rows_] = lo;
    upper_[rows_] = up;
    ++rows_;
  }

  // x = x1 + Z u (or u), kept if the hard level holds: |B x − b| ≤ feas_tol (1 + |b|) on its rows of
  // positive weight, violations ≤ feas_tol (1 + |C x|).
  std::string accept()
  {
    if (eliminated_)
      x_.noalias() = x1_ + Z_ * y_.head(Z_.cols());
    else
      x_ = y_.head(n_);
    if (nl_ == 2)
    {
      const ConstRowMap Bh = matrix(Bs_, 0), Ch = matrix(Cs_, 0);
      const ConstVecMap wh = vec(ws_, 0), bh = vec(bs_, 0), lh = vec(lowers_, 0),
                        uh = vec(uppers_, 0);
      bool bad = false;
      for (Index i = 0; i < Bh.rows() && !bad; ++i)
        bad = wh[i] > 0 && std::abs(Bh.row(i).dot(x_) - bh[i]) > feas_tol_ * (1.0 + std::abs(bh[i]));
      for (Index i = 0; i < Ch.rows() && !bad; ++i)
      {
        const double cx = Ch.row(i).dot(x_);
        bad = std::max(std::max(lh[i] - cx, cx - uh[i]), 0.0) > feas_tol_ * (1.0 + std::abs(cx));
      }
      if (bad)
      {
        status_ = "hard level not satisfied";
        return "failed";
      }
    }
    return "done";
  }

  double eps_, feas_tol_;
  std::size_t obj_ = 0;
  Index rows_ = 0;
  Index most_ = 0; // the QP's rows at most
  RowMatrix H_, A_, wB_, M_, CZ_;
  VectorXd g_, lower_, upper_, y_, x_, rhs_, cx1_;
  // the eliminated equalities: Eᵀ, e, its QR, x1, Z
  bool eliminated_ = false;
  MatrixXd Et_, Z_;
  VectorXd e_, x1_;
  Eigen::HouseholderQR<MatrixXd> qr_;
  double qp_time_ = 0.0;
  std::string status_;
};

// The rows DAQP is given, as a tuple of new arrays (backends.solve_daqp; see scale_rows).
template <typename Matrix>
py::tuple unit_rows(const Matrix & A, const double * lo, const double * up)
{
  const Index m = A.rows(), n = A.cols();
  py::array_t<double> A_out({py::ssize_t(m), py::ssize_t(n)}), bu(m), bl(m);
  py::array_t<int32_t> sense(m);
  Eigen::Map<RowMatrix> Au(A_out.mutable_data(), m, n);
  scale_rows(A, lo, up, Au, bu.mutable_data(), bl.mutable_data(), sense.mutable_data());
  return py::make_tuple(A_out, bu, bl, sense);
}

py::tuple daqp_rows(const DoubleArray & A_in, const DoubleArray & lower_in, const DoubleArray & upper_in)
{
  if (A_in.ndim() != 2 || lower_in.size() != A_in.shape(0) || upper_in.size() != A_in.shape(0))
    throw std::invalid_argument("daqp_rows: A must be m x n with m lower and upper bounds");
  return unit_rows(ConstRowMap(A_in.data(), A_in.shape(0), A_in.shape(1)), lower_in.data(),
                   upper_in.data());
}

double row_violation(const DoubleArray & A_in, const DoubleArray & x_in, const DoubleArray & lower_in,
                     const DoubleArray & upper_in)
{
  if (A_in.ndim() != 2 || x_in.size() != A_in.shape(1) || lower_in.size() != A_in.shape(0)
      || upper_in.size() != A_in.shape(0))
    throw std::invalid_argument("row_violation: A must be m x n with n values of x and m bounds");
  const Index m = A_in.shape(0), n = A_in.shape(1);
  return violation(ConstRowMap(A_in.data(), m, n), ConstVecMap(x_in.data(), n), lower_in.data(),
                   upper_in.data());
}

py::tuple CascadeRun::daqp_qp() const
{
  if (pending_ != Kind::QP)
    throw std::runtime_error("CascadeRun.daqp_qp: no QP pending");
  const py::tuple rows = unit_rows(qp_A_, qp_lower_.data(), qp_upper_.data());
  return py::make_tuple(qp_g_, rows[0], rows[1], rows[2], rows[3]);
}

double CascadeRun::qp_violation(const DoubleArray & y) const
{
  if (pending_ != Kind::QP)
    throw std::runtime_error("CascadeRun.qp_violation: no QP pending");
  if (y.ndim() != 1 || y.size() != qp_g_.size())
    throw std::invalid_argument("CascadeRun.qp_violation: y must have one value per QP variable");
  return violation(qp_A_, ConstVecMap(y.data(), y.size()), qp_lower_.data(), qp_upper_.data());
}

PYBIND11_MODULE(_cascade, m)
{
  m.doc() = "The cascade and the weighted QP of wholebody.solvers.hierarchy, compiled.";
  m.def("daqp_rows", &daqp_rows, py::arg("A"), py::arg("lower"), py::arg("upper"));
  m.def("kernel_basis", [](const MatrixXd & RZ, double tol) {
          bool by_svd = false;
          MatrixXd N;
          if (!kernel_basis(RZ, tol, N, by_svd))
            N = MatrixXd::Identity(RZ.cols(), RZ.cols()); // nothing locked: all of it
          return py::make_tuple(N, by_svd);
        }, py::arg("RZ"), py::arg("tol"),
        "(N, by_svd): the orthonormal kernel basis of the cascade's locks (cascade._kernel)");
  m.def("row_violation", &row_violation, py::arg("A"), py::arg("x"), py::arg("lower"),
        py::arg("upper"));
  m.attr("DAQP_C_VERSION") = daqp_c::kVersion;
  py::class_<DaqpSolver>(m, "DaqpSolver")
    .def(py::init<const std::string &, const std::map<std::string, double> &,
                  std::map<int, std::string>, double>(),
         py::arg("module_path"), py::arg("settings"), py::arg("exit_names"), py::arg("raw_tol"))
    .def("settings", &DaqpSolver::settings)
    .def_property_readonly("calls", &DaqpSolver::calls);
  py::class_<CascadeRun>(m, "CascadeRun")
    .def(py::init<std::vector<DoubleArray>, std::vector<DoubleArray>, std::vector<DoubleArray>,
                  std::vector<DoubleArray>, std::vector<DoubleArray>, std::vector<DoubleArray>,
                  std::vector<DoubleArray>, std::vector<std::string>, Index, double,
                  const std::optional<VectorXd> &, const std::optional<MatrixXd> &, bool, double,
                  double, double, double, py::object>(),
         py::arg("B"), py::arg("b"), py::arg("w"), py::arg("C"), py::arg("lower"), py::arg("upper"),
         py::arg("V"), py::arg("names"), py::arg("n"), py::arg("eps"), py::arg("x1"), py::arg("Z1"),
         py::arg("analytic_first"),
         py::arg("rank_tol"), py::arg("drop_tol"), py::arg("relax_tol"), py::arg("feas_tol"),
         py::arg("nnls"))
    .def("reset", &CascadeRun::reset)
    .def("advance", &CascadeRun::advance)
    .def("advance_daqp", &CascadeRun::advance_daqp, py::arg("daqp"))
    .def("solve_daqp", &CascadeRun::solve_daqp, py::arg("daqp"))
    .def("qp", &CascadeRun::qp)
    .def("daqp_qp", &CascadeRun::daqp_qp)
    .def("qp_violation", &CascadeRun::qp_violation, py::arg("y"))
    .def("give_qp", &CascadeRun::give_qp, py::arg("y"), py::arg("status"))
    .def("result", &CascadeRun::result)
    .def("quick", &CascadeRun::quick)
    .def_property_readonly("level", &CascadeRun::level)
    .def_property_readonly("daqp_status", &CascadeRun::daqp_status);
  py::class_<WeightedRun>(m, "WeightedRun")
    .def(py::init<std::vector<DoubleArray>, std::vector<DoubleArray>, std::vector<DoubleArray>,
                  std::vector<DoubleArray>, std::vector<DoubleArray>, std::vector<DoubleArray>,
                  std::vector<DoubleArray>, std::vector<std::string>, Index, double, double>(),
         py::arg("B"), py::arg("b"), py::arg("w"), py::arg("C"), py::arg("lower"), py::arg("upper"),
         py::arg("V"), py::arg("names"), py::arg("n"), py::arg("eps"), py::arg("feas_tol"))
    .def("qp", &WeightedRun::qp)
    .def("solve_daqp", &WeightedRun::solve_daqp, py::arg("daqp"))
    .def("give", &WeightedRun::give, py::arg("y"))
    .def("result", &WeightedRun::result)
    .def("quick", &WeightedRun::quick)
    .def_property_readonly("status", &WeightedRun::status);
}
