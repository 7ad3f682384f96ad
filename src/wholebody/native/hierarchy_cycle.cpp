// One control cycle of hierarchical inverse dynamics in compiled code (Herzog et al. 2016, seed
// 000): Pinocchio's rigid-body terms (Robot.update), the rows of the tasks of Tables 1, 2 and 4
// (wholebody.tasks) and their mapping onto the solver's levels (wholebody.formulation: reduced
// [qdd, lambda] with tau eliminated by eq. 14, or full [qdd, lambda, tau]), written into the level
// arrays that wholebody.cycle.HierarchyCycle hands to the cascade; then tau from the solution.
//
// It mirrors the Python tasks and Formulation (the tested reference) row for row: same layout,
// same formulas; tests/test_cycle.py checks the level arrays of both on random states. Task
// parameters (gains, references, weights) live in Python-owned arrays that Python refills every
// cycle from the task objects, so a controller changes them on the tasks as before.
#include "native_common.hpp"

#include <pinocchio/algorithm/centroidal.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/spatial.hpp>

#include <pybind11/eigen.h>

#include <map>

namespace py = pybind11;
using namespace wholebody_native;

namespace
{
  using Vector6d = Eigen::Matrix<double, 6, 1>;
  using RowMap = Map<RowMatrix>;

  // the task kinds with a compiled counterpart (names as wholebody.cycle.KINDS)
  enum class Kind
  {
    NewtonEuler, FullDynamics, TorqueLimits, JointAccelerationLimits, ContactConstraint,
    CenterOfPressure, FrictionCone, NormalForceBounds, MomentumPD, MomentumForce, CoM, Frame,
    Posture, ForceRegularizer, AccelerationRegularizer, JointTrajectory
  };

  const std::map<std::string, Kind> kKinds = {
    {"newton_euler", Kind::NewtonEuler}, {"full_dynamics", Kind::FullDynamics},
    {"torque_limits", Kind::TorqueLimits}, {"joint_acceleration_limits", Kind::JointAccelerationLimits},
    {"contact_constraint", Kind::ContactConstraint}, {"center_of_pressure", Kind::CenterOfPressure},
    {"friction_cone", Kind::FrictionCone}, {"normal_force_bounds", Kind::NormalForceBounds},
    {"momentum_pd", Kind::MomentumPD}, {"momentum_force", Kind::MomentumForce}, {"com", Kind::CoM},
    {"frame", Kind::Frame}, {"posture", Kind::Posture}, {"force_regularizer", Kind::ForceRegularizer},
    {"acceleration_regularizer", Kind::AccelerationRegularizer},
    {"joint_trajectory", Kind::JointTrajectory}};

  // one task's rows in a program: where they go, where its parameters are, what it selects
  struct Slot
  {
    Kind kind;
    Index start = 0, m = 0, param = 0;
    std::vector<Index> contacts; // positions in the program's active contacts
    std::vector<Index> rows;     // CoM axes, frame mask rows, joint indices
    Index frame = -1;            // index into the cycle's frames (Frame tasks)
    bool base = false, torsion = false;
  };

  // the level arrays of one stack and contact set (Python-owned, see HierarchyCycle._compile)
  struct Program
  {
    std::vector<Index> contacts; // robot contact indices, in lambda order
    std::vector<Index> offsets;  // their first lambda column (relative to nv)
    Index nl = 0, n = 0, rows = 0, nparams = 0;
    bool reduced = true;
    VectorXd scales;
    std::vector<Slot> slots;
    double *mat = nullptr, *target = nullptr, *lower = nullptr, *upper = nullptr;
    const double * params = nullptr;
    double *qdd = nullptr, *lam = nullptr, *tau = nullptr, *tau_lo = nullptr, *tau_hi = nullptr;
    MatrixXd Jc;   // stacked contact Jacobians (nl x nv)
    VectorXd drift; // stacked contact drifts
    std::vector<py::object> keep;
  };
} // namespace

class HierarchyCycle
{
public:
  explicit HierarchyCycle(const py::dict & spec)
  {
    add_joints(spec, model_);
    nq_ = model_.nq;
    nv_ = model_.nv;
    na_ = nv_ - 6;
    auto frame_joints = get<std::vector<int>>(spec, "frame_joints");
    DoubleArray fpl = get<DoubleArray>(spec, "frame_placements");
    const double * fp = input(fpl, 16 * py::ssize_t(frame_joints.size()), "frame_placements");
    for (std::size_t i = 0; i < frame_joints.size(); ++i)
    {
      if (frame_joints[i] < 1 || frame_joints[i] >= model_.njoints)
        throw std::invalid_argument("spec: frame_joints index out of range");
      frames_.push_back(model_.addFrame(pinocchio::Frame(
        "frame" + std::to_string(i), pinocchio::JointIndex(frame_joints[i]),
        placement_from(fp + 16 * i), pinocchio::OP_FRAME)));
    }
    const Index nf = Index(frames_.size());
    contact_frames_ = get<std::vector<int>>(spec, "contact_frames");
    contact_dims_ = get<std::vector<int>>(spec, "contact_dims");
    nc_ = Index(contact_frames_.size());
    if (Index(contact_dims_.size()) != nc_)
      throw std::invalid_argument("spec: 'contact_dims' and 'contact_frames' differ in length");
    for (Index i = 0; i < nc_; ++i)
      if (contact_frames_[i] < 0 || contact_frames_[i] >= nf
          || (contact_dims_[i] != 3 && contact_dims_[i] != 6))
        throw std::invalid_argument("spec: contact " + std::to_string(i) + " is not a 3D/6D contact of a frame");
    radii_ = get_vector(spec, "contact_radii", nc_);
    DoubleArray hs = get<DoubleArray>(spec, "contact_half_sizes");
    half_sizes_ = Map<const RowMatrix>(input(hs, 2 * nc_, "contact_half_sizes"), nc_, 2);
    torque_ = TorqueProfile::from_spec(spec, na_);
    torque_scale_ = get<double>(spec, "torque_scale");
    q_min_ = get_vector(spec, "q_min", na_);
    q_max_ = get_vector(spec, "q_max", na_);
    mass_ = get<double>(spec, "mass");
    data_ = wholebody::LeggedData(model_);
    q_ = VectorXd::Zero(nq_);
    v_ = VectorXd::Zero(nv_);
    contact_J_.assign(nc_, MatrixXd::Zero(6, nv_));
    contact_J6_.assign(nc_, Matrix6x::Zero(6, nv_));
    contact_drift_.assign(nc_, Vector6d::Zero());
    points_.setZero(nc_, 3);
    frame_J_.setZero(6, nv_);
  }

  // Robot.update for this cycle: Pinocchio's terms, and every contact's Jacobian, drift and point
  // (LOCAL_WORLD_ALIGNED; point contacts at the bottom of the foot sphere, Robot._update_contacts).
  void update(const DoubleArray & q_in, const DoubleArray & v_in)
  {
    A_G_dot_v_ = rigid_body_pass(model_, data_, q_in, v_in, q_, v_);
    for (Index i = 0; i < nc_; ++i)
    {
      const auto fid = frames_[contact_frames_[i]];
      Matrix6x & J6 = contact_J6_[i];
      J6.setZero();
      pinocchio::getFrameJacobian(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED, J6);
      const Vector6d acc =
        pinocchio::getFrameClassicalAcceleration(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED)
          .toVector();
      points_.row(i) = data_.oMf[fid].translation().transpose();
      MatrixXd & J = contact_J_[i];
      Vector6d & drift = contact_drift_[i];
      if (contact_dims_[i] == 6)
      {
        J = J6;
        drift = acc;
        continue;
      }
      const double r = radii_[i]; // the bottom of the foot sphere
      sphere_point(J6, acc.head<3>(), acc.tail<3>(), v_, r, J.topRows(3), drift.head<3>());
      points_(i, 2) -= r;
    }
    updated_ = true;
  }

  // A program: the level layout of one stack and contact set (see HierarchyCycle._compile).
  int compile(const py::dict & p)
  {
    Program prog;
    prog.contacts = get<std::vector<Index>>(p, "contacts");
    for (Index c : prog.contacts)
    {
      if (c < 0 || c >= nc_)
        throw std::invalid_argument("compile: contact index out of range");
      prog.offsets.push_back(prog.nl);
      prog.nl += contact_dims_[c];
    }
    prog.reduced = get<bool>(p, "reduced");
    prog.n = nv_ + prog.nl + (prog.reduced ? 0 : na_);
    prog.rows = get<Index>(p, "rows");
    prog.nparams = get<Index>(p, "nparams");
    prog.scales = get_vector(p, "scales", prog.n);
    py::dict b = get<py::dict>(p, "buffers");
    prog.mat = buffer<double>(b, "mat", prog.rows * prog.n, prog.keep);
    prog.target = buffer<double>(b, "target", prog.rows, prog.keep);
    prog.lower = buffer<double>(b, "lower", prog.rows, prog.keep);
    prog.upper = buffer<double>(b, "upper", prog.rows, prog.keep);
    prog.params = buffer<double>(b, "params", prog.nparams, prog.keep);
    prog.qdd = buffer<double>(b, "qdd", nv_, prog.keep);
    prog.lam = buffer<double>(b, "lam", prog.nl, prog.keep);
    prog.tau = buffer<double>(b, "tau", na_, prog.keep);
    prog.tau_lo = buffer<double>(b, "tau_lo", na_, prog.keep);
    prog.tau_hi = buffer<double>(b, "tau_hi", na_, prog.keep);
    prog.Jc.setZero(prog.nl, nv_);
    prog.drift.setZero(prog.nl);
    for (const py::handle & item : get<py::list>(p, "slots"))
    {
      const py::dict s = py::reinterpret_borrow<py::dict>(item);
      Slot slot;
      const std::string kind = get<std::string>(s, "kind");
      const auto it = kKinds.find(kind);
      if (it == kKinds.end())
        throw std::invalid_argument("compile: unknown task kind '" + kind + "'");
      slot.kind = it->second;
      slot.start = get<Index>(s, "start");
      slot.m = get<Index>(s, "m");
      slot.param = get<Index>(s, "param");
      slot.contacts = get<std::vector<Index>>(s, "contacts");
      slot.rows = get<std::vector<Index>>(s, "rows");
      slot.frame = get<Index>(s, "frame");
      slot.base = get<bool>(s, "base");
      slot.torsion = get<bool>(s, "torsion");
      if (slot.start < 0 || slot.m < 0 || slot.start + slot.m > prog.rows || slot.param < 0
          || slot.param > prog.nparams)
        throw std::invalid_argument("compile: slot '" + kind + "' outside the buffers");
      for (Index c : slot.contacts)
        if (c < 0 || c >= Index(prog.contacts.size()))
          throw std::invalid_argument("compile: slot '" + kind + "' names an inactive contact");
      if (slot.kind == Kind::Frame && (slot.frame < 0 || slot.frame >= Index(frames_.size())))
        throw std::invalid_argument("compile: frame index out of range");
      if (slot.kind == Kind::FullDynamics && prog.reduced)
        throw std::invalid_argument("compile: FullDynamics belongs to the full formulation");
      const Index expected = rows_of(slot, prog);
      if (expected != slot.m)
        throw std::invalid_argument("compile: slot '" + kind + "' has " + std::to_string(slot.m)
                                    + " rows, its task has " + std::to_string(expected));
      prog.slots.push_back(std::move(slot));
    }
    programs_.push_back(std::move(prog));
    return int(programs_.size()) - 1;
  }

  // Fills a program's level arrays from this cycle's terms and its parameters (Formulation.levels
  // without the weights, which Python writes). False if some entry is NaN/inf or lower > upper.
  bool fill(int id)
  {
    Program & P = program(id);
    if (!updated_)
      throw std::runtime_error("fill: call update(q, v) first");
    for (std::size_t k = 0; k < P.contacts.size(); ++k)
    {
      const Index c = P.contacts[k], d = contact_dims_[c];
      P.Jc.middleRows(P.offsets[k], d) = contact_J_[c].topRows(d);
      P.drift.segment(P.offsets[k], d) = contact_drift_[c].head(d);
    }
    RowMap A(P.mat, P.rows, P.n);
    Map<VectorXd> e(P.target, P.rows), lo(P.lower, P.rows), up(P.upper, P.rows);
    for (const Slot & s : P.slots)
    {
      A.middleRows(s.start, s.m).setZero();
      fill_slot(P, s, A.middleRows(s.start, s.m), e.segment(s.start, s.m), lo.segment(s.start, s.m),
                up.segment(s.start, s.m), P.params + s.param);
    }
    if (P.n > nv_)
      A.rightCols(P.n - nv_).array().rowwise() *= P.scales.tail(P.n - nv_).transpose().array();
    return A.allFinite() && e.allFinite() && !(lo.array() > up.array()).any()
           && !lo.array().isNaN().any() && !up.array().isNaN().any();
  }

  // qdd, lambda and tau of a solution x (scaled, as the solver sees it; Formulation._recover),
  // and the robot's torque bounds at this state, into the program's output arrays.
  void recover(int id, const DoubleArray & x_in)
  {
    Program & P = program(id);
    const double * xp = input(x_in, P.n, "x", false);
    const VectorXd x = Map<const VectorXd>(xp, P.n).cwiseProduct(P.scales);
    Map<VectorXd> qdd(P.qdd, nv_), lam(P.lam, P.nl), tau(P.tau, na_);
    qdd = x.head(nv_);
    lam = x.segment(nv_, P.nl);
    if (P.reduced) // eq. 14
      tau.noalias() = data_.M.bottomRows(na_) * qdd + data_.nle.tail(na_)
                      - P.Jc.rightCols(na_).transpose() * lam;
    else
      tau = x.tail(na_);
    Map<VectorXd> hi(P.tau_hi, na_), lo(P.tau_lo, na_);
    torque_upper(hi);
    lo = -hi;
  }

  // Copies of the rigid-body terms of the last update (tests compare them with Robot.update).
  py::dict terms() const
  {
    py::dict d = rigid_body_terms(data_);
    d["A_G"] = MatrixXd(data_.Ag);
    d["A_G_dot_v"] = A_G_dot_v_;
    d["J_com"] = MatrixXd(data_.Jcom);
    d["points"] = MatrixXd(points_);
    Index rows = 0;  // every contact's drift (Robot.stacked_contact_drift of all contacts)
    for (Index i = 0; i < nc_; ++i)
      rows += contact_dims_[i];
    VectorXd drifts(rows);
    for (Index i = 0, r = 0; i < nc_; r += contact_dims_[i], ++i)
      drifts.segment(r, contact_dims_[i]) = contact_drift_[i].head(contact_dims_[i]);
    d["contact_drifts"] = drifts;
    return d;
  }

  Vector3d com() const { return data_.com[0]; }
  Vector3d vcom() const { return data_.vcom[0]; }
  Vector6d h_G() const { return data_.hg.toVector(); }

  // (position, rotation) of one of the cycle's frames (first-use references of FrameTask)
  py::tuple frame_placement(Index i) const
  {
    if (i < 0 || i >= Index(frames_.size()))
      throw std::invalid_argument("frame: index out of range");
    const pinocchio::SE3 & M = data_.oMf[frames_[i]];
    return py::make_tuple(Vector3d(M.translation()), Matrix3d(M.rotation()));
  }

  Index nv() const { return nv_; }
  Index na() const { return na_; }

private:
  Program & program(int id)
  {
    if (id < 0 || id >= int(programs_.size()))
      throw std::invalid_argument("program: unknown id " + std::to_string(id));
    return programs_[std::size_t(id)];
  }

  // rows a task of this kind has (the Python side's count, checked at compile)
  Index rows_of(const Slot & s, const Program & P) const
  {
    Index dims = 0, rect = 0;
    for (Index c : s.contacts)
    {
      dims += contact_dims_[P.contacts[c]];
      rect += contact_dims_[P.contacts[c]] == 6;
    }
    switch (s.kind)
    {
      case Kind::NewtonEuler: return 6;
      case Kind::FullDynamics: return nv_;
      case Kind::TorqueLimits: case Kind::JointAccelerationLimits: return na_;
      case Kind::ContactConstraint: case Kind::ForceRegularizer: return dims;
      case Kind::CenterOfPressure: return 4 * rect;
      case Kind::FrictionCone: return 4 * Index(s.contacts.size()) + (s.torsion ? 8 * rect : 0);
      case Kind::NormalForceBounds: return Index(s.contacts.size());
      case Kind::MomentumPD: case Kind::MomentumForce: return 6;
      case Kind::CoM: case Kind::Frame: case Kind::JointTrajectory: return Index(s.rows.size());
      case Kind::Posture: return s.base ? nv_ : na_;
      case Kind::AccelerationRegularizer: return nv_;
    }
    return -1;
  }

  template<typename Out>
  void torque_upper(Out && hi) const
  {
    torque_.upper(q_.tail(na_), hi);
    hi *= torque_scale_;
  }

  // tau = M_u qdd + h_u - J_u^T lambda (eq. 14) for rows whose tau block is the identity:
  // writes the qdd and lambda columns, returns the offset h_u moved to the bounds.
  template<typename Rows>
  void eq14_rows(const Program & P, Rows && A) const
  {
    A.leftCols(nv_) = data_.M.bottomRows(na_);
    A.middleCols(nv_, P.nl) = -P.Jc.rightCols(na_).transpose();
  }

  template<typename Rows, typename Vec>
  void fill_slot(const Program & P, const Slot & s, Rows A, Vec e, Vec lo, Vec up, const double * p)
  {
    const Index nv = nv_, na = na_;
    switch (s.kind)
    {
      case Kind::NewtonEuler: // eq. 13: M_l qdd - J_{c,l}^T lambda = -h_l
        A.leftCols(nv) = data_.M.topRows(6);
        A.middleCols(nv, P.nl) = -P.Jc.leftCols(6).transpose();
        e = -data_.nle.head(6);
        break;
      case Kind::FullDynamics: // eq. 1: M qdd - J_c^T lambda - S^T tau = -h
        A.leftCols(nv) = data_.M;
        A.middleCols(nv, P.nl) = -P.Jc.transpose();
        A.bottomRightCorner(na, na) = -MatrixXd::Identity(na, na);
        e = -data_.nle;
        break;
      case Kind::TorqueLimits: // eq. 16; p = [scale, cap (na)]
      {
        VectorXd hi(na);
        torque_upper(hi);
        const VectorXd lo0 = -hi * p[0], hi0 = hi * p[0];
        const Map<const VectorXd> cap(p + 1, na);
        lo = lo0.cwiseMax(-cap);
        up = hi0.cwiseMin(cap);
        if (P.reduced)
        {
          eq14_rows(P, A);
          lo -= data_.nle.tail(na);
          up -= data_.nle.tail(na);
        }
        else
          A.rightCols(na).setIdentity();
        break;
      }
      case Kind::JointAccelerationLimits: // p = [tanh?, horizon, a_max, steepness]
      {
        A.middleCols(6, na).setIdentity();
        for (Index j = 0; j < na; ++j)
        {
          const double q = q_[7 + j], qd = v_[6 + j];
          if (p[0] != 0.0)
          {
            lo[j] = p[2] * std::tanh(p[3] * (q_min_[j] - q));
            up[j] = p[2] * std::tanh(p[3] * (q_max_[j] - q));
          }
          else
          {
            const double h = p[1];
            lo[j] = 2.0 * (q_min_[j] - q - h * qd) / (h * h);
            up[j] = 2.0 * (q_max_[j] - q - h * qd) / (h * h);
          }
        }
        break;
      }
      case Kind::ContactConstraint: // eq. 2 (+ Fahmi eq. 32); p = [kp, kd, anchors (3 each)]
      {
        Index r = 0;
        for (std::size_t k = 0; k < s.contacts.size(); ++k)
        {
          const Index a = s.contacts[k], c = P.contacts[a], d = contact_dims_[c];
          A.block(r, 0, d, nv) = P.Jc.middleRows(P.offsets[a], d);
          e.segment(r, d) = -P.drift.segment(P.offsets[a], d);
          if (p[0] != 0.0 || p[1] != 0.0)
          {
            const Vector3d pos = data_.oMf[frames_[contact_frames_[c]]].translation();
            const VectorXd vel = contact_J_[c].topRows(d) * v_;
            e.segment(r, 3) += p[0] * (Map<const Vector3d>(p + 2 + 3 * k) - pos) - p[1] * vel.head(3);
            if (d == 6)
              e.segment(r + 3, 3) -= p[1] * vel.tail(3);
          }
          r += d;
        }
        break;
      }
      case Kind::CenterOfPressure: // p = [margin]
      {
        Index r = 0;
        for (Index a : s.contacts)
        {
          const Index c = P.contacts[a];
          if (contact_dims_[c] != 6)
            continue;
          const Matrix3d R = data_.oMf[frames_[contact_frames_[c]]].rotation();
          const double hx = (1.0 - p[0]) * half_sizes_(c, 0), hy = (1.0 - p[0]) * half_sizes_(c, 1);
          auto B = A.block(r, nv + P.offsets[a], 4, 6);
          B.row(0).head(3) = B.row(1).head(3) = -hx * R.col(2).transpose();
          B.row(2).head(3) = B.row(3).head(3) = -hy * R.col(2).transpose();
          B.row(0).tail(3) = -R.col(1).transpose();
          B.row(1).tail(3) = R.col(1).transpose();
          B.row(2).tail(3) = R.col(0).transpose();
          B.row(3).tail(3) = -R.col(0).transpose();
          lo.segment(r, 4).setConstant(-kInf);
          up.segment(r, 4).setZero();
          r += 4;
        }
        break;
      }
      case Kind::FrictionCone: // p = [mu, normals (3 each)]
      {
        const double mu = p[0];
        Index r = 0;
        for (std::size_t k = 0; k < s.contacts.size(); ++k)
        {
          const Index a = s.contacts[k], c = P.contacts[a], col = nv + P.offsets[a];
          Vector3d t1, t2, n;
          tangent_basis(Map<const Vector3d>(p + 1 + 3 * k), t1, t2, n);
          A.block(r, col, 1, 3) = (t1 - mu * n).transpose();
          A.block(r + 1, col, 1, 3) = (-t1 - mu * n).transpose();
          A.block(r + 2, col, 1, 3) = (t2 - mu * n).transpose();
          A.block(r + 3, col, 1, 3) = (-t2 - mu * n).transpose();
          r += 4;
          if (s.torsion && contact_dims_[c] == 6)
          { // the yaw-moment facets of the sole's contact wrench cone in its measured axes
            // (FrictionCone.wrench_cone_block; Caron et al. 2015)
            const Matrix3d R = data_.oMf[frames_[contact_frames_[c]]].rotation();
            const double hx = half_sizes_(c, 0), hy = half_sizes_(c, 1);
            for (double sx : {1.0, -1.0})
              for (double sy : {1.0, -1.0})
              {
                const Vector3d force = -mu * (hx + hy) * R.col(2) + sx * hy * R.col(0) + sy * hx * R.col(1);
                const Vector3d moment = R.col(2) + mu * (sx * R.col(0) + sy * R.col(1));
                A.block(r, col, 1, 3) = A.block(r + 1, col, 1, 3) = force.transpose();
                A.block(r, col + 3, 1, 3) = moment.transpose();
                A.block(r + 1, col + 3, 1, 3) = -moment.transpose();
                r += 2;
              }
          }
        }
        lo.setConstant(-kInf);
        up.setZero();
        break;
      }
      case Kind::NormalForceBounds: // p = [f_min, f_max, normals (3 each)]
        for (std::size_t k = 0; k < s.contacts.size(); ++k)
        {
          Vector3d t1, t2, n;
          tangent_basis(Map<const Vector3d>(p + 2 + 3 * k), t1, t2, n);
          A.block(Index(k), nv + P.offsets[s.contacts[k]], 1, 3) = n.transpose();
          lo[Index(k)] = p[0];
          up[Index(k)] = p[1];
        }
        break;
      case Kind::MomentumPD: // eq. 22; p = [P (36), D (36), com_ref, h_ref, hdot_ref]
      {
        const Map<const RowMatrix> Pm(p, 6, 6), Dm(p + 36, 6, 6);
        Vector6d err = Vector6d::Zero();
        err.head<3>() = mass_ * (Map<const Vector3d>(p + 72) - data_.com[0]);
        A.leftCols(nv) = data_.Ag;
        e = Pm * err + Dm * (Map<const Vector6d>(p + 75) - data_.hg.toVector())
            + Map<const Vector6d>(p + 81) - A_G_dot_v_;
        break;
      }
      case Kind::MomentumForce: // eq. 24; p = [K (nl_task x 9), k (nl_task)]
      {
        Index nt = 0;
        for (Index a : s.contacts)
          nt += contact_dims_[P.contacts[a]];
        const Map<const RowMatrix> K(p, nt, 9);
        const Map<const VectorXd> k(p + 9 * nt, nt);
        Eigen::Matrix<double, 9, 1> state;
        state << data_.com[0], data_.hg.toVector();
        const VectorXd force = k - K * state;
        e.setZero();
        Index col = 0;
        for (Index a : s.contacts)
        {
          const Index c = P.contacts[a], d = contact_dims_[c];
          const Vector3d r = points_.row(c).transpose() - data_.com[0];
          Eigen::Matrix<double, 6, 6> G = Eigen::Matrix<double, 6, 6>::Zero();
          G.topLeftCorner<3, 3>().setIdentity();
          G.block<3, 3>(3, 0) = pinocchio::skew(r);
          if (d == 6)
            G.bottomRightCorner<3, 3>().setIdentity();
          A.block(0, nv + P.offsets[a], 6, d) = G.leftCols(d);
          e += G.leftCols(d) * force.segment(col, d);
          col += d;
        }
        break;
      }
      case Kind::CoM: // p = [position, velocity, acceleration, kp (3), kd (3)]
      {
        const Vector3d a = Map<const Vector3d>(p + 6)
                           + Map<const Vector3d>(p + 9).cwiseProduct(Map<const Vector3d>(p) - data_.com[0])
                           + Map<const Vector3d>(p + 12).cwiseProduct(Map<const Vector3d>(p + 3) - data_.vcom[0])
                           - A_G_dot_v_.head<3>() / mass_;
        for (std::size_t k = 0; k < s.rows.size(); ++k)
        {
          A.row(Index(k)).head(nv) = data_.Jcom.row(s.rows[k]);
          e[Index(k)] = a[s.rows[k]];
        }
        break;
      }
      case Kind::Frame: // p = [position, rotation (9), velocity (6), acceleration (6), kp (6), kd (6)]
      {
        const auto fid = frames_[s.frame];
        const pinocchio::SE3 & M = data_.oMf[fid];
        const Matrix3d R_ref = Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(p + 3);
        Vector6d err;
        err.head<3>() = Map<const Vector3d>(p) - M.translation();
        err.tail<3>() = pinocchio::log3(Matrix3d(R_ref * M.rotation().transpose()));
        const Vector6d vel =
          pinocchio::getFrameVelocity(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED).toVector();
        const Vector6d drift =
          pinocchio::getFrameClassicalAcceleration(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED)
            .toVector();
        const Vector6d a = Map<const Vector6d>(p + 18) + Map<const Vector6d>(p + 24).cwiseProduct(err)
                           + Map<const Vector6d>(p + 30).cwiseProduct(Map<const Vector6d>(p + 12) - vel)
                           - drift;
        frame_J_.setZero();
        pinocchio::getFrameJacobian(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED, frame_J_);
        for (std::size_t k = 0; k < s.rows.size(); ++k)
        {
          A.row(Index(k)).head(nv) = frame_J_.row(s.rows[k]);
          e[Index(k)] = a[s.rows[k]];
        }
        break;
      }
      case Kind::Posture: // p = [q_ref (nq), kp (na), kd (na), base_kp (6), base_kd (6)]
      {
        const Map<const VectorXd> q_ref(p, nq_), kp(p + nq_, na), kd(p + nq_ + na, na);
        const VectorXd joint = kp.cwiseProduct(q_ref.tail(na) - q_.tail(na)) - kd.cwiseProduct(v_.tail(na));
        if (!s.base)
        {
          A.middleCols(6, na).setIdentity();
          e = joint;
          break;
        }
        // base error in the local frame: log6 of the relative placement
        const Eigen::Quaterniond quat(q_[6], q_[3], q_[4], q_[5]), quat_ref(q_ref[6], q_ref[3], q_ref[4], q_ref[5]);
        const pinocchio::SE3 base(quat.toRotationMatrix(), q_.head<3>());
        const pinocchio::SE3 base_ref(quat_ref.toRotationMatrix(), q_ref.head<3>());
        const Vector6d err = pinocchio::log6(base.actInv(base_ref)).toVector();
        A.leftCols(nv).setIdentity();
        e.head(6) = Map<const Vector6d>(p + nq_ + 2 * na).cwiseProduct(err)
                    - Map<const Vector6d>(p + nq_ + 2 * na + 6).cwiseProduct(v_.head<6>());
        e.tail(na) = joint;
        break;
      }
      case Kind::ForceRegularizer: // p = [targets (dim each)]; rows scaled (ForceRegularizer.row_scale)
      {
        Index r = 0;
        for (Index a : s.contacts)
        {
          const Index c = P.contacts[a], d = contact_dims_[c];
          for (Index j = 0; j < d; ++j)
          {
            const double scale = j < 3 ? 1.0 : 1.0 / half_sizes_.row(c).maxCoeff();
            A(r + j, nv + P.offsets[a] + j) = scale;
            e[r + j] = scale * p[r + j];
          }
          r += d;
        }
        break;
      }
      case Kind::AccelerationRegularizer:
        A.leftCols(nv).setIdentity();
        e.setZero();
        break;
      case Kind::JointTrajectory: // p = [position, velocity, acceleration, kp, kd] (k each)
      {
        const Index k = Index(s.rows.size());
        for (Index i = 0; i < k; ++i)
        {
          const Index j = s.rows[i];
          A(i, 6 + j) = 1.0;
          e[i] = p[2 * k + i] + p[3 * k + i] * (p[i] - q_[7 + j]) + p[4 * k + i] * (p[k + i] - v_[6 + j]);
        }
        break;
      }
    }
  }

  wholebody::LeggedModel model_;
  wholebody::LeggedData data_;
  Index nq_ = 0, nv_ = 0, na_ = 0, nc_ = 0;
  std::vector<pinocchio::FrameIndex> frames_;
  std::vector<int> contact_frames_, contact_dims_;
  VectorXd radii_, q_min_, q_max_, q_, v_;
  RowMatrix half_sizes_;
  TorqueProfile torque_;
  double torque_scale_ = 1.0, mass_ = 0.0;
  bool updated_ = false;
  // per-cycle terms
  Vector6d A_G_dot_v_ = Vector6d::Zero();
  std::vector<MatrixXd> contact_J_;
  std::vector<Matrix6x> contact_J6_;
  std::vector<Vector6d> contact_drift_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> points_;
  Matrix6x frame_J_;
  std::vector<Program> programs_;
};

PYBIND11_MODULE(_hierarchy_cycle, m)
{
  m.doc() = "Compiled rigid-body terms and task rows of wholebody.cycle.HierarchyCycle.";
  py::class_<HierarchyCycle>(m, "HierarchyCycle")
    .def(py::init<const py::dict &>(), py::arg("spec"))
    .def("update", &HierarchyCycle::update, py::arg("q"), py::arg("v"))
    .def("compile", &HierarchyCycle::compile, py::arg("program"))
    .def("fill", &HierarchyCycle::fill, py::arg("program"))
    .def("recover", &HierarchyCycle::recover, py::arg("program"), py::arg("x"))
    .def("terms", &HierarchyCycle::terms)
    .def("frame_placement", &HierarchyCycle::frame_placement, py::arg("frame"))
    .def_property_readonly("com", &HierarchyCycle::com)
    .def_property_readonly("vcom", &HierarchyCycle::vcom)
    .def_property_readonly("h_G", &HierarchyCycle::h_G)
    .def_property_readonly("nv", &HierarchyCycle::nv)
    .def_property_readonly("na", &HierarchyCycle::na);
}
