// One control cycle of hierarchical inverse dynamics in compiled code (Herzog et al. 2016):
// Pinocchio's rigid-body terms (Robot.update), the rows of the tasks that have a kernel
// (wholebody.tasks) and their mapping onto the solver's levels (wholebody.formulation: reduced
// [qdd, lambda] with tau eliminated by eq. 14, or full [qdd, lambda, tau]), written into the level
// arrays that wholebody.cycle.HierarchyCycle hands to the cascade; then tau from the solution.
//
// A kernel is registered by its task's name (HierarchyCycle::kernels, the Python class's
// ``kernel``) with the parameters it reads by name, in the order of its task's schema
// (wholebody.tasks.schema); a program's slots are checked against it at compile. The Python tasks
// are the reference, row for row; tests/parity/test_cycle.py checks the level arrays of both on
// random states. Task parameters live in Python-owned arrays refilled every cycle from the task
// objects (ParameterPacker, packer.hpp), so a controller changes them on the tasks as before.
#include "native_common.hpp"
#include "packer.hpp"

#include <pinocchio/algorithm/centroidal.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/spatial.hpp>

#include <Eigen/SVD>

#include <pybind11/eigen.h>

#include <chrono>
#include <map>

namespace py = pybind11;
using namespace wholebody_native;

namespace
{
  using Vector6d = Eigen::Matrix<double, 6, 1>;
  using RowMap = Map<RowMatrix>;
  using Rows = Eigen::Ref<RowMatrix>;
  using Segment = Eigen::Ref<VectorXd>;

  // what a kernel's parameter size counts (wholebody.tasks.schema.UNITS)
  enum class Unit { Fixed, Nq, Na, Nv, Contact, ContactDim, Rows, Frames, Auxiliary };

  // a kernel's parameter: its name and k entries per unit (wholebody.tasks.schema.Param)
  struct ParamSpec
  {
    std::string name;
    Index k = 1;
    Unit per = Unit::Fixed;
  };

  // one task's rows in a program: where they go, where its parameters are (in the order of its
  // kernel's ParamSpecs), what it selects (in the order of its kernel's selection names)
  struct Slot
  {
    std::string kernel;
    Index start = 0, m = 0;
    std::vector<Index> contacts;           // positions in the program's active contacts
    std::vector<Index> offsets, sizes;     // per kernel parameter
    std::vector<std::vector<Index>> picks; // per kernel selection name
    Index frame = -1;                      // the cycle's frame of a "frame" selection
    const double * params = nullptr;
    const double * p(std::size_t i) const { return params + offsets[i]; }
    const std::vector<Index> & pick(std::size_t i) const { return picks[i]; }
    bool flag(std::size_t i) const { return !picks[i].empty() && picks[i][0] != 0; }
  };

  // the level arrays of one stack and contact set (Python-owned, see wholebody.cycle._Program)
  struct Program
  {
    std::vector<Index> contacts; // robot contact indices, in lambda order
    std::vector<Index> offsets;  // their first lambda column (relative to nv)
    Index nl = 0, n = 0, rows = 0, nparams = 0;
    Index naux = 0;              // auxiliary variables: the last naux columns (wholebody.variables)
    bool reduced = true;
    VectorXd scales;
    std::vector<Slot> slots;
    double *mat = nullptr, *target = nullptr, *lower = nullptr, *upper = nullptr;
    const double * params = nullptr;
    double *qdd = nullptr, *lam = nullptr, *tau = nullptr, *tau_lo = nullptr, *tau_hi = nullptr;
    const double * weights = nullptr; // the rows' weights (packed before fill)
    VectorXd w_min;                    // their least values: 0 on equality rows, > 0 on inequality rows
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
    joint_angles_ = JointAngles(model_);
    angles_ = VectorXd::Zero(model_.nv - 6);
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
    joint_angles_(q_, angles_);
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
    if (state_.q)
      write_state();
  }

  // Python-owned arrays that every update refreshes with the terms a controller reads besides
  // the task rows (wholebody.cycle.HierarchyCycle.state): q, v, nle, h_G, com, vcom, the base's
  // rotation (row-major), the locked centroidal inertia Ig, and per contact its point (the bottom
  // of a foot sphere) and that point's velocity, its frame's origin, the origin's Jacobian
  // (linear rows, nc x 3 x nv), classical acceleration drift and velocity; the robot's torque
  // bounds tau_max(q) (TorqueProfile.upper, Robot.torque_limits).
  void bind_state(const py::dict & b)
  {
    StateOut s;
    s.q = buffer<double>(b, "q", nq_, s.keep);
    s.v = buffer<double>(b, "v", nv_, s.keep);
    s.nle = buffer<double>(b, "nle", nv_, s.keep);
    s.h_G = buffer<double>(b, "h_G", 6, s.keep);
    s.com = buffer<double>(b, "com", 3, s.keep);
    s.vcom = buffer<double>(b, "vcom", 3, s.keep);
    s.rotation = buffer<double>(b, "rotation", 9, s.keep);
    s.Ig = buffer<double>(b, "Ig", 9, s.keep);
    s.points = buffer<double>(b, "points", 3 * nc_, s.keep);
    s.point_velocities = buffer<double>(b, "point_velocities", 3 * nc_, s.keep);
    s.frame_positions = buffer<double>(b, "frame_positions", 3 * nc_, s.keep);
    s.frame_jacobians = buffer<double>(b, "frame_jacobians", 3 * nc_ * nv_, s.keep);
    s.frame_drifts = buffer<double>(b, "frame_drifts", 3 * nc_, s.keep);
    s.frame_velocities = buffer<double>(b, "frame_velocities", 3 * nc_, s.keep);
    s.tau_max = buffer<double>(b, "tau_max", na_, s.keep);
    state_ = std::move(s);
    if (updated_)
      write_state();
  }

  // A program: the level layout of one stack and contact set (wholebody.cycle._Program). Each
  // slot names its kernel and sends its parameters' {name: [offset, size]} and its selection
  // {name: [ints]}; they must be exactly the kernel's, with the sizes it expects.
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
    prog.naux = get<Index>(p, "auxiliary");
    if (prog.naux < 0)
      throw std::invalid_argument("compile: a negative number of auxiliary variables");
    prog.n = nv_ + prog.nl + (prog.reduced ? 0 : na_) + prog.naux;
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
    prog.weights = buffer<double>(b, "weights", prog.rows, prog.keep);
    prog.w_min = get_vector(p, "w_min", prog.rows);
    prog.Jc.setZero(prog.nl, nv_);
    prog.drift.setZero(prog.nl);
    for (const py::handle & item : get<py::list>(p, "slots"))
      prog.slots.push_back(slot_of(py::reinterpret_borrow<py::dict>(item), prog));
    programs_.push_back(std::move(prog));
    return int(programs_.size()) - 1;
  }

  // The names of the registered kernels (the Python task classes' ``kernel``).
  static std::vector<std::string> kernel_names()
  {
    std::vector<std::string> names;
    for (const auto & [name, kernel] : kernels())
      names.push_back(name);
    return names;
  }

  // Fills a program's level arrays from this cycle's terms and its parameters (Formulation.levels
  // without the weights, which are packed before, and without the rows of tasks that have no
  // kernel, which Python writes before this call). False if some entry is NaN/inf (or the
  // entries' sum overflows: the reference's check, sum_is_finite), lower > upper, or a weight is
  // not finite or below its least value (w_min).
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
      (this->*kernels().at(s.kernel).fill)(P, s, A.middleRows(s.start, s.m), e.segment(s.start, s.m),
                                           lo.segment(s.start, s.m), up.segment(s.start, s.m));
    }
    if (P.n > nv_)
      A.rightCols(P.n - nv_).array().rowwise() *= P.scales.tail(P.n - nv_).transpose().array();
    const Map<const VectorXd> w(P.weights, P.rows);
    return sum_is_finite(A) && sum_is_finite(e) && !(lo.array() > up.array()).any()
           && !lo.array().isNaN().any() && !up.array().isNaN().any() && std::isfinite(w.sum())
           && (w.array() >= P.w_min.array()).all();
  }

  // One cycle: update(q, v) unless q is None (the state of the last update), the tasks'
  // parameters packed, fill(); then, with ``quick`` — (solve, daqp, result) of a bound compiled
  // run (BoundCascade/BoundWeighted.quick_calls) — that run's common case, solve(daqp) == "done"
  // and result() not None, and recover() → (filled, seconds updating, seconds packing and
  // filling, (x, level costs, QP seconds, QP count, the torque's excess over its limits) or None
  // where the caller solves the levels itself).
  py::tuple cycle(int id, ParameterPacker & packer, const py::object & quick, const py::object & q,
                  const py::object & v)
  {
    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    if (!q.is_none())
      update(q.cast<DoubleArray>(), v.cast<DoubleArray>());
    const auto t1 = Clock::now();
    packer.pack();
    const bool filled = fill(id);
    const double update_seconds = std::chrono::duration<double>(t1 - t0).count();
    const double rows_seconds = std::chrono::duration<double>(Clock::now() - t1).count();
    if (!filled || quick.is_none())
      return py::make_tuple(filled, update_seconds, rows_seconds, py::none());
    const py::tuple calls = quick.cast<py::tuple>();
    if (calls[0](calls[1]).cast<std::string>() != "done")
      return py::make_tuple(true, update_seconds, rows_seconds, py::none());
    py::object result = calls[2]();
    if (result.is_none())
      return py::make_tuple(true, update_seconds, rows_seconds, py::none());
    const py::tuple r = result.cast<py::tuple>();
    const double excess = recover(id, r[0].cast<DoubleArray>());
    return py::make_tuple(true, update_seconds, rows_seconds,
                          py::make_tuple(r[0], r[1], r[2], r[3], excess));
  }

  // qdd, lambda and tau of a solution x (scaled, as the solver sees it; Formulation._recover),
  // and the robot's torque bounds at this state, into the program's output arrays. Returns how
  // far tau is outside them, max(tau - tau_hi, tau_lo - tau) (NaN if anything is not finite), for
  // wholebody.guard.guard_torque.
  double recover(int id, const DoubleArray & x_in)
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
      tau = x.segment(nv_ + P.nl, na_);
    Map<VectorXd> hi(P.tau_hi, na_), lo(P.tau_lo, na_);
    torque_upper(hi);
    lo = -hi;
    if (!tau.allFinite() || hi.hasNaN())
      return std::numeric_limits<double>::quiet_NaN();
    return na_ ? (tau - hi).cwiseMax(lo - tau).maxCoeff() : -kInf;
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

  VectorXd q() const { return q_; } // the configuration of the last update
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

  // A frame on ``joint`` at ``placement`` (4x4, row-major) added after construction (a FrameTask
  // inserted into a stack); its index. The state must be updated again before the next fill.
  Index add_frame(int joint, const DoubleArray & placement)
  {
    if (joint < 1 || joint >= model_.njoints)
      throw std::invalid_argument("add_frame: joint index out of range");
    frames_.push_back(model_.addFrame(pinocchio::Frame("frame" + std::to_string(frames_.size()),
                                                       pinocchio::JointIndex(joint),
                                                       placement_from(input(placement, 16, "placement")),
                                                       pinocchio::OP_FRAME)));
    data_ = wholebody::LeggedData(model_);
    updated_ = false;
    return Index(frames_.size()) - 1;
  }

  Index nv() const { return nv_; }
  Index na() const { return na_; }

private:
  // the arrays of bind_state (null: not bound)
  struct StateOut
  {
    double *q = nullptr, *v = nullptr, *nle = nullptr, *h_G = nullptr, *com = nullptr,
           *vcom = nullptr, *rotation = nullptr, *Ig = nullptr, *points = nullptr,
           *point_velocities = nullptr, *frame_positions = nullptr, *frame_jacobians = nullptr,
           *frame_drifts = nullptr, *frame_velocities = nullptr, *tau_max = nullptr;
    std::vector<py::object> keep;
  };

  void write_state()
  {
    using Mat3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
    Map<VectorXd>(state_.q, nq_) = q_;
    Map<VectorXd>(state_.v, nv_) = v_;
    Map<VectorXd>(state_.nle, nv_) = data_.nle;
    Map<Vector6d>(state_.h_G) = data_.hg.toVector();
    Map<Vector3d>(state_.com) = data_.com[0];
    Map<Vector3d>(state_.vcom) = data_.vcom[0];
    Map<Mat3>(state_.rotation) = data_.oMi[1].rotation();
    Map<Mat3>(state_.Ig) = data_.Ig.inertia().matrix();
    Map<VectorXd> tau_max(state_.tau_max, na_);
    torque_upper(tau_max);
    for (Index i = 0; i < nc_; ++i)
    {
      const auto fid = frames_[contact_frames_[i]];
      const Matrix6x & J6 = contact_J6_[i];
      Map<Vector3d>(state_.points + 3 * i) = points_.row(i).transpose();
      Map<Vector3d>(state_.point_velocities + 3 * i) = contact_J_[i].topRows(3) * v_;
      Map<Vector3d>(state_.frame_positions + 3 * i) = data_.oMf[fid].translation();
      RowMap(state_.frame_jacobians + 3 * nv_ * i, 3, nv_) = J6.topRows<3>();
      Map<Vector3d>(state_.frame_velocities + 3 * i) = J6.topRows<3>() * v_;
      Map<Vector3d>(state_.frame_drifts + 3 * i) =
        pinocchio::getFrameClassicalAcceleration(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED)
          .linear();
    }
  }

  StateOut state_;

  Program & program(int id)
  {
    if (id < 0 || id >= int(programs_.size()))
      throw std::invalid_argument("program: unknown id " + std::to_string(id));
    return programs_[std::size_t(id)];
  }

  // ------------------------------------------------------------------ kernels by name
  using RowCount = Index (HierarchyCycle::*)(const Program &, const Slot &) const;
  using Fill = void (HierarchyCycle::*)(const Program &, const Slot &, Rows, Segment, Segment, Segment);

  // A task's compiled counterpart: equality or inequality rows, its parameters and selection
  // (by name, in the order its fill reads them: s.p(0), s.pick(0)...), its row count and fill.
  // A selection's ParamSpec bounds its entries: each in [0, k * count(per)) (a flag: k = 2).
  struct Kernel
  {
    bool eq;
    std::vector<ParamSpec> params;
    std::vector<ParamSpec> selection;
    RowCount rows;
    Fill fill;
  };

  // The registry: one entry per task class with ``kernel = "<name>"`` (wholebody.tasks).
  static const std::map<std::string, Kernel> & kernels()
  {
    using C = HierarchyCycle;
    static const std::map<std::string, Kernel> registry = {
      {"newton_euler", {true, {}, {}, &C::rows_fixed<6>, &C::fill_newton_euler}},
      {"full_dynamics", {true, {}, {}, &C::rows_nv, &C::fill_full_dynamics}},
      {"torque_limits", {false, {{"scale"}, {"cap", 1, Unit::Na}}, {}, &C::rows_na, &C::fill_torque_limits}},
      {"joint_acceleration_limits",
       {false, {{"tanh"}, {"horizon"}, {"a_max"}, {"steepness"}}, {}, &C::rows_na,
        &C::fill_joint_acceleration_limits}},
      {"contact_constraint",
       {true, {{"kp"}, {"kd"}, {"anchors", 3, Unit::Contact}, {"rank_tolerance"}}, {},
        &C::rows_contact_dims, &C::fill_contact_constraint}},
      {"center_of_pressure", {false, {{"margin"}}, {}, &C::rows_cop, &C::fill_center_of_pressure}},
      {"friction_cone",
       {false, {{"mu"}, {"normals", 3, Unit::Contact}}, {{"torsion", 2}}, &C::rows_friction, &C::fill_friction_cone}},
      {"normal_force_bounds",
       {false, {{"f_min"}, {"f_max"}, {"normals", 3, Unit::Contact}}, {}, &C::rows_contacts,
        &C::fill_normal_force_bounds}},
      {"momentum_pd",
       {true, {{"P", 36}, {"D", 36}, {"com_ref", 3}, {"h_ref", 6}, {"hdot_ref", 6}}, {},
        &C::rows_fixed<6>, &C::fill_momentum_pd}},
      {"momentum_force",
       {true, {{"K", 9, Unit::ContactDim}, {"k", 1, Unit::ContactDim}}, {}, &C::rows_fixed<6>,
        &C::fill_momentum_force}},
      {"com",
       {true, {{"position", 3}, {"velocity", 3}, {"acceleration", 3}, {"kp", 3}, {"kd", 3}}, {{"rows", 3}},
        &C::rows_picked, &C::fill_com}},
      {"frame",
       {true, {{"position", 3}, {"rotation", 9}, {"velocity", 6}, {"acceleration", 6}, {"kp", 6}, {"kd", 6}},
        {{"rows", 6}, {"frame", 1, Unit::Frames}}, &C::rows_picked, &C::fill_frame}},
      {"slacked_frame",
       {false, {{"position", 3}, {"rotation", 9}, {"velocity", 6}, {"acceleration", 6}, {"kp", 6}, {"kd", 6}},
        {{"rows", 6}, {"frame", 1, Unit::Frames}, {"auxiliary", 1, Unit::Auxiliary}}, &C::rows_picked_twice,
        &C::fill_slacked_frame}},
      {"auxiliary_regularizer",
       {true, {}, {{"auxiliary", 1, Unit::Auxiliary}}, &C::rows_picked, &C::fill_auxiliary_regularizer}},
      {"posture",
       {true, {{"q_ref", 1, Unit::Nq}, {"kp", 1, Unit::Na}, {"kd", 1, Unit::Na}, {"base_kp", 6}, {"base_kd", 6}},
        {{"with_base", 2}}, &C::rows_posture, &C::fill_posture}},
      {"force_regularizer",
       {true, {{"targets", 1, Unit::ContactDim}}, {}, &C::rows_contact_dims, &C::fill_force_regularizer}},
      {"acceleration_regularizer", {true, {}, {}, &C::rows_nv, &C::fill_acceleration_regularizer}},
      {"acceleration_target", {true, {{"target", 1, Unit::Nv}}, {}, &C::rows_nv, &C::fill_acceleration_target}},
      {"trunk_wrench",
       {true, {{"K_x", 3}, {"D_x", 3}, {"K_theta", 3}, {"D_theta", 3}, {"feedforward"}, {"external_wrench", 6},
               {"position", 3}, {"velocity", 3}, {"acceleration", 3}, {"rotation", 9}, {"angular_velocity", 3},
               {"angular_acceleration", 3}, {"heading"}},
        {}, &C::rows_fixed<6>, &C::fill_trunk_wrench}},
      {"contact_torque_regularizer", {true, {}, {}, &C::rows_na, &C::fill_contact_torque_regularizer}},
      {"tangential_force_regularizer",
       {true, {{"mu"}, {"lean", 3}, {"normals", 3, Unit::Contact}}, {}, &C::rows_per_contact<2>,
        &C::fill_tangential_force_regularizer}},
      {"joint_trajectory",
       {true, {{"position", 1, Unit::Rows}, {"velocity", 1, Unit::Rows}, {"acceleration", 1, Unit::Rows},
               {"kp", 1, Unit::Rows}, {"kd", 1, Unit::Rows}},
        {{"rows", 1, Unit::Na}}, &C::rows_picked, &C::fill_joint_trajectory}}};
    return registry;
  }

  // One slot of a program from its Python description, checked against its kernel: the same
  // parameter names and sizes, the same selection names, the same row count and kind.
  Slot slot_of(const py::dict & s, const Program & P) const
  {
    Slot slot;
    slot.kernel = get<std::string>(s, "kernel");
    const auto it = kernels().find(slot.kernel);
    if (it == kernels().end())
      throw std::invalid_argument("compile: no kernel named '" + slot.kernel + "'");
    const Kernel & kernel = it->second;
    const std::string where = "compile: kernel '" + slot.kernel + "'";
    slot.start = get<Index>(s, "start");
    slot.m = get<Index>(s, "m");
    if (slot.start < 0 || slot.m < 0 || slot.start + slot.m > P.rows)
      throw std::invalid_argument(where + ": rows outside the buffers");
    if (get<bool>(s, "eq") != kernel.eq)
      throw std::invalid_argument(where + ": its rows are " + (kernel.eq ? "equalities" : "inequalities"));
    slot.contacts = get<std::vector<Index>>(s, "contacts");
    for (Index c : slot.contacts)
      if (c < 0 || c >= Index(P.contacts.size()))
        throw std::invalid_argument(where + ": names an inactive contact");
    const py::dict selection = get<py::dict>(s, "selection");
    std::vector<std::string> picked;
    for (const ParamSpec & spec : kernel.selection)
      picked.push_back(spec.name);
    bool same_selection = py::len(selection) == kernel.selection.size();
    for (const std::string & name : picked)
      same_selection = same_selection && selection.contains(name);
    if (!same_selection)
      throw std::invalid_argument(where + ": expected the selection " + joined(picked));
    for (const ParamSpec & spec : kernel.selection)
    {
      slot.picks.push_back(get<std::vector<Index>>(selection, spec.name.c_str()));
      const Index bound = spec.k * count(spec.per, slot, P);
      for (Index i : slot.picks.back())
        if (i < 0 || i >= bound)
          throw std::invalid_argument(where + ": selection '" + spec.name + "' has "
                                      + std::to_string(i) + ", outside [0, " + std::to_string(bound) + ")");
      if (spec.name == "frame") // the cycle's frame the kernel reads
      {
        if (slot.picks.back().size() != 1)
          throw std::invalid_argument(where + ": selection 'frame' must name one frame");
        slot.frame = slot.picks.back()[0];
      }
    }
    if (slot.kernel == "full_dynamics" && P.reduced)
      throw std::invalid_argument(where + ": FullDynamics belongs to the full formulation");
    const py::dict params = get<py::dict>(s, "params");
    std::vector<std::string> names;
    for (const ParamSpec & spec : kernel.params)
      names.push_back(spec.name);
    bool same = py::len(params) == kernel.params.size();
    for (const std::string & name : names)
      same = same && params.contains(name);
    if (!same)
      throw std::invalid_argument(where + ": expected the parameters " + joined(names));
    for (const ParamSpec & spec : kernel.params)
    {
      const auto range = get<std::vector<Index>>(params, spec.name.c_str());
      const Index expected = spec.k * count(spec.per, slot, P);
      if (range.size() != 2 || range[1] != expected || range[0] < 0 || range[0] + range[1] > P.nparams)
        throw std::invalid_argument(where + ": parameter '" + spec.name + "' must be "
                                    + std::to_string(expected) + " values inside the parameter array");
      slot.offsets.push_back(range[0]);
      slot.sizes.push_back(range[1]);
    }
    slot.params = P.params;
    const Index expected = (this->*kernel.rows)(P, slot);
    if (expected != slot.m)
      throw std::invalid_argument(where + ": " + std::to_string(slot.m) + " rows given, its task has "
                                  + std::to_string(expected));
    return slot;
  }

  static std::string joined(const std::vector<std::string> & names)
  {
    std::string out = "[";
    for (std::size_t i = 0; i < names.size(); ++i)
      out += (i ? ", '" : "'") + names[i] + "'";
    return out + "]";
  }

  Index contact_dims(const Slot & s, const Program & P) const
  {
    Index dims = 0;
    for (Index c : s.contacts)
      dims += contact_dims_[P.contacts[c]];
    return dims;
  }

  Index count(Unit unit, const Slot & s, const Program & P) const
  {
    switch (unit)
    {
      case Unit::Fixed: return 1;
      case Unit::Nq: return nq_;
      case Unit::Na: return na_;
      case Unit::Nv: return nv_;
      case Unit::Contact: return Index(s.contacts.size());
      case Unit::ContactDim: return contact_dims(s, P);
      case Unit::Rows: return Index(s.picks.empty() ? 0 : s.picks[0].size());
      case Unit::Frames: return Index(frames_.size());
      case Unit::Auxiliary: return P.naux;
    }
    return -1;
  }

  // row counts (the Python task's row_count, checked at compile)
  template<Index N>
  Index rows_fixed(const Program &, const Slot &) const { return N; }
  Index rows_nv(const Program &, const Slot &) const { return nv_; }
  Index rows_na(const Program &, const Slot &) const { return na_; }
  Index rows_contact_dims(const Program & P, const Slot & s) const { return contact_dims(s, P); }
  Index rows_contacts(const Program &, const Slot & s) const { return Index(s.contacts.size()); }
  template<Index N>
  Index rows_per_contact(const Program &, const Slot & s) const { return N * Index(s.contacts.size()); }
  Index rows_picked(const Program &, const Slot & s) const { return Index(s.pick(0).size()); }
  Index rows_picked_twice(const Program &, const Slot & s) const { return 2 * Index(s.pick(0).size()); }
  Index rows_posture(const Program &, const Slot & s) const { return s.flag(0) ? nv_ : na_; }
  Index soles(const Program & P, const Slot & s) const
  {
    Index rect = 0;
    for (Index c : s.contacts)
      rect += contact_dims_[P.contacts[c]] == 6;
    return rect;
  }
  Index rows_cop(const Program & P, const Slot & s) const { return 4 * soles(P, s); }
  Index rows_friction(const Program & P, const Slot & s) const
  {
    return 4 * Index(s.contacts.size()) + (s.flag(0) ? 8 * soles(P, s) : 0);
  }

  template<typename Out>
  void torque_upper(Out && hi) const
  {
    torque_.upper(angles_, hi);
    hi *= torque_scale_;
  }

  // eq. 13: M_l qdd - J_{c,l}^T lambda = -h_l
  void fill_newton_euler(const Program & P, const Slot &, Rows A, Segment e, Segment, Segment)
  {
    A.leftCols(nv_) = data_.M.topRows(6);
    A.middleCols(nv_, P.nl) = -P.Jc.leftCols(6).transpose();
    e = -data_.nle.head(6);
  }

  // eq. 1: M qdd - J_c^T lambda - S^T tau = -h
  void fill_full_dynamics(const Program & P, const Slot &, Rows A, Segment e, Segment, Segment)
  {
    A.leftCols(nv_) = data_.M;
    A.middleCols(nv_, P.nl) = -P.Jc.transpose();
    A.block(nv_ - na_, nv_ + P.nl, na_, na_) = -MatrixXd::Identity(na_, na_);
    e = -data_.nle;
  }

  // eq. 16, tau eliminated by eq. 14 in the reduced formulation
  void fill_torque_limits(const Program & P, const Slot & s, Rows A, Segment, Segment lo, Segment up)
  {
    const double scale = *s.p(0);
    const Map<const VectorXd> cap(s.p(1), na_);
    VectorXd hi(na_);
    torque_upper(hi);
    lo = (-hi * scale).cwiseMax(-cap);
    up = (hi * scale).cwiseMin(cap);
    if (P.reduced)
    {
      A.leftCols(nv_) = data_.M.bottomRows(na_);
      A.middleCols(nv_, P.nl) = -P.Jc.rightCols(na_).transpose();
      lo -= data_.nle.tail(na_);
      up -= data_.nle.tail(na_);
    }
    else
      A.middleCols(nv_ + P.nl, na_).setIdentity();
  }

  // Fahmi et al. 2019 eqs. 17-18 (braking) or Herzog et al. 2016 Sect. 2.1 (tanh)
  void fill_joint_acceleration_limits(const Program &, const Slot & s, Rows A, Segment, Segment lo, Segment up)
  {
    const bool tanh_mode = *s.p(0) != 0.0;
    const double h = *s.p(1), a_max = *s.p(2), k = *s.p(3);
    A.middleCols(6, na_).setIdentity();
    for (Index j = 0; j < na_; ++j)
    {
      const double q = angles_[j], qd = v_[6 + j];
      if (tanh_mode)
      {
        lo[j] = a_max * std::tanh(k * (q_min_[j] - q));
        up[j] = a_max * std::tanh(k * (q_max_[j] - q));
      }
      else
      {
        lo[j] = 2.0 * (q_min_[j] - q - h * qd) / (h * h);
        up[j] = 2.0 * (q_max_[j] - q - h * qd) / (h * h);
      }
    }
  }

  // eq. 2 (+ Fahmi et al. 2019 eq. 32: the anchor PD)
  void fill_contact_constraint(const Program & P, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const double kp = *s.p(0), kd = *s.p(1);
    const double * anchors = s.p(2);
    Index r = 0;
    for (std::size_t k = 0; k < s.contacts.size(); ++k)
    {
      const Index a = s.contacts[k], c = P.contacts[a], d = contact_dims_[c];
      A.block(r, 0, d, nv_) = P.Jc.middleRows(P.offsets[a], d);
      e.segment(r, d) = -P.drift.segment(P.offsets[a], d);
      if (kp != 0.0 || kd != 0.0)
      {
        const Vector3d pos = data_.oMf[frames_[contact_frames_[c]]].translation();
        const VectorXd vel = contact_J_[c].topRows(d) * v_;
        e.segment(r, 3) += kp * (Map<const Vector3d>(anchors + 3 * k) - pos) - kd * vel.head(3);
        if (d == 6)
          e.segment(r + 3, 3) -= kd * vel.tail(3);
      }
      r += d;
    }
    const double tolerance = *s.p(3);
    if (tolerance > 0.0 && r > 0)
      independent_rows(A.topLeftCorner(r, nv_), e.head(r), tolerance);
  }

  // tasks.contact.independent_rows, in place: rows J x = target replaced by U_rᵀ J x = U_rᵀ
  // target over the singular values above tolerance σ_max (each column of U_r signed so that its
  // entry of largest magnitude is positive), the remaining rows zero; rows with a NaN or inf
  // entry are left as they are (the fill's checks name the task).
  static void independent_rows(Eigen::Ref<RowMatrix> J, Segment target, double tolerance)
  {
    if (!J.allFinite() || !target.allFinite())
      return;
    const Eigen::JacobiSVD<MatrixXd> svd(MatrixXd(J), Eigen::ComputeFullU);
    const VectorXd & singular = svd.singularValues();
    Index rank = 0;
    while (rank < singular.size() && singular[rank] > tolerance * singular[0])
      ++rank;
    MatrixXd U = svd.matrixU().leftCols(rank);
    for (Index j = 0; j < rank; ++j)
    {
      Index largest = 0;
      U.col(j).cwiseAbs().maxCoeff(&largest);
      if (U(largest, j) < 0.0)
        U.col(j) = -U.col(j);
    }
    const MatrixXd rows = U.transpose() * J;
    const VectorXd targets = U.transpose() * target;
    J.setZero();
    target.setZero();
    J.topRows(rank) = rows;
    target.head(rank) = targets;
  }

  // the CoP inside each (margin-shrunk) sole: 4 rows per rectangle contact
  void fill_center_of_pressure(const Program & P, const Slot & s, Rows A, Segment, Segment lo, Segment up)
  {
    const double margin = *s.p(0);
    Index r = 0;
    for (Index a : s.contacts)
    {
      const Index c = P.contacts[a];
      if (contact_dims_[c] != 6)
        continue;
      const Matrix3d R = data_.oMf[frames_[contact_frames_[c]]].rotation();
      const double hx = (1.0 - margin) * half_sizes_(c, 0), hy = (1.0 - margin) * half_sizes_(c, 1);
      auto B = A.block(r, nv_ + P.offsets[a], 4, 6);
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
  }

  // the friction pyramid about each normal, and with torsion the soles' yaw-moment facets
  void fill_friction_cone(const Program & P, const Slot & s, Rows A, Segment, Segment lo, Segment up)
  {
    const double mu = *s.p(0);
    const double * normals = s.p(1);
    const bool torsion = s.flag(0);
    Index r = 0;
    for (std::size_t k = 0; k < s.contacts.size(); ++k)
    {
      const Index a = s.contacts[k], c = P.contacts[a], col = nv_ + P.offsets[a];
      Vector3d t1, t2, n;
      tangent_basis(Map<const Vector3d>(normals + 3 * k), t1, t2, n);
      A.block(r, col, 1, 3) = (t1 - mu * n).transpose();
      A.block(r + 1, col, 1, 3) = (-t1 - mu * n).transpose();
      A.block(r + 2, col, 1, 3) = (t2 - mu * n).transpose();
      A.block(r + 3, col, 1, 3) = (-t2 - mu * n).transpose();
      r += 4;
      if (torsion && contact_dims_[c] == 6)
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
  }

  // f_min <= f.n <= f_max per contact
  void fill_normal_force_bounds(const Program & P, const Slot & s, Rows A, Segment, Segment lo, Segment up)
  {
    const double * normals = s.p(2);
    for (std::size_t k = 0; k < s.contacts.size(); ++k)
    {
      Vector3d t1, t2, n;
      tangent_basis(Map<const Vector3d>(normals + 3 * k), t1, t2, n);
      A.block(Index(k), nv_ + P.offsets[s.contacts[k]], 1, 3) = n.transpose();
      lo[Index(k)] = *s.p(0);
      up[Index(k)] = *s.p(1);
    }
  }

  // eq. 22: A_G qdd = P [m (x_ref - x); 0] + D (h_ref - h) + hdot_ref - Adot_G v
  void fill_momentum_pd(const Program &, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const Map<const RowMatrix> Pm(s.p(0), 6, 6), Dm(s.p(1), 6, 6);
    Vector6d err = Vector6d::Zero();
    err.head<3>() = mass_ * (Map<const Vector3d>(s.p(2)) - data_.com[0]);
    A.leftCols(nv_) = data_.Ag;
    e = Pm * err + Dm * (Map<const Vector6d>(s.p(3)) - data_.hg.toVector()) + Map<const Vector6d>(s.p(4))
        - A_G_dot_v_;
  }

  // eq. 24: G lambda = G (k - K [x; h])
  void fill_momentum_force(const Program & P, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const Index nt = contact_dims(s, P);
    const Map<const RowMatrix> K(s.p(0), nt, 9);
    const Map<const VectorXd> k(s.p(1), nt);
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
      A.block(0, nv_ + P.offsets[a], 6, d) = G.leftCols(d);
      e += G.leftCols(d) * force.segment(col, d);
      col += d;
    }
  }

  // the CoM's PD on the selected axes
  void fill_com(const Program &, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const Vector3d a = Map<const Vector3d>(s.p(2))
                       + Map<const Vector3d>(s.p(3)).cwiseProduct(Map<const Vector3d>(s.p(0)) - data_.com[0])
                       + Map<const Vector3d>(s.p(4)).cwiseProduct(Map<const Vector3d>(s.p(1)) - data_.vcom[0])
                       - A_G_dot_v_.head<3>() / mass_;
    const auto & rows = s.pick(0);
    for (std::size_t k = 0; k < rows.size(); ++k)
    {
      A.row(Index(k)).head(nv_) = data_.Jcom.row(rows[k]);
      e[Index(k)] = a[rows[k]];
    }
  }

  // a frame's PD on the selected rows of [position; orientation] (world axes)
  void fill_frame(const Program &, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const auto fid = frames_[s.frame];
    const pinocchio::SE3 & M = data_.oMf[fid];
    const Matrix3d R_ref = Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(s.p(1));
    Vector6d err;
    err.head<3>() = Map<const Vector3d>(s.p(0)) - M.translation();
    err.tail<3>() = pinocchio::log3(Matrix3d(R_ref * M.rotation().transpose()));
    const Vector6d vel = pinocchio::getFrameVelocity(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED).toVector();
    const Vector6d drift =
      pinocchio::getFrameClassicalAcceleration(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED).toVector();
    const Vector6d a = Map<const Vector6d>(s.p(3)) + Map<const Vector6d>(s.p(4)).cwiseProduct(err)
                       + Map<const Vector6d>(s.p(5)).cwiseProduct(Map<const Vector6d>(s.p(2)) - vel) - drift;
    frame_J_.setZero();
    pinocchio::getFrameJacobian(model_, data_, fid, pinocchio::LOCAL_WORLD_ALIGNED, frame_J_);
    const auto & rows = s.pick(0);
    for (std::size_t k = 0; k < rows.size(); ++k)
    {
      A.row(Index(k)).head(nv_) = frame_J_.row(rows[k]);
      e[Index(k)] = a[rows[k]];
    }
  }

  // the frame task's k selected rows a_i within one shared slack eps (its auxiliary variable):
  // J_i qdd - eps <= a_i (rows 0..k-1) and a_i <= J_i qdd + eps (rows k..2k-1), i.e.
  // |J_i qdd - a_i| <= eps (Fahmi et al. 2019's single swing slack)
  void fill_slacked_frame(const Program & P, const Slot & s, Rows A, Segment e, Segment lo, Segment up)
  {
    const Index k = Index(s.pick(0).size());
    fill_frame(P, s, A.topRows(k), e.head(k), lo, up);
    A.bottomRows(k).leftCols(nv_) = A.topRows(k).leftCols(nv_);
    const Index column = P.n - P.naux + s.pick(2)[0];
    A.col(column).head(k).setConstant(-1.0);
    A.col(column).tail(k).setConstant(1.0);
    lo.head(k).setConstant(-kInf);
    up.head(k) = e.head(k);
    lo.tail(k) = e.head(k);
    up.tail(k).setConstant(kInf);
    e.head(k).setZero();
  }

  // the selected auxiliary variables = 0 (weighted: a cost on them)
  void fill_auxiliary_regularizer(const Program & P, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const auto & columns = s.pick(0);
    for (std::size_t k = 0; k < columns.size(); ++k)
      A(Index(k), P.n - P.naux + columns[k]) = 1.0;
    e.setZero();
  }

  // joint-space PD toward q_ref (pinocchio::difference: any joint type), with the base rows
  // (log6 of the relative placement, local frame) when selected
  void fill_posture(const Program &, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const Map<const VectorXd> q_ref(s.p(0), nq_), kp(s.p(1), na_), kd(s.p(2), na_);
    const VectorXd error = pinocchio::difference(model_, q_, q_ref);
    const VectorXd joint = kp.cwiseProduct(error.tail(na_)) - kd.cwiseProduct(v_.tail(na_));
    if (!s.flag(0))
    {
      A.middleCols(6, na_).setIdentity();
      e = joint;
      return;
    }
    const Eigen::Quaterniond quat(q_[6], q_[3], q_[4], q_[5]), quat_ref(q_ref[6], q_ref[3], q_ref[4], q_ref[5]);
    const pinocchio::SE3 base(quat.toRotationMatrix(), q_.head<3>());
    const pinocchio::SE3 base_ref(quat_ref.toRotationMatrix(), q_ref.head<3>());
    const Vector6d err = pinocchio::log6(base.actInv(base_ref)).toVector();
    A.leftCols(nv_).setIdentity();
    e.head(6) = Map<const Vector6d>(s.p(3)).cwiseProduct(err) - Map<const Vector6d>(s.p(4)).cwiseProduct(v_.head<6>());
    e.tail(na_) = joint;
  }

  // lambda ≈ targets, rows scaled (ForceRegularizer.row_scale)
  void fill_force_regularizer(const Program & P, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const double * targets = s.p(0);
    Index r = 0;
    for (Index a : s.contacts)
    {
      const Index c = P.contacts[a], d = contact_dims_[c];
      for (Index j = 0; j < d; ++j)
      {
        const double scale = j < 3 ? 1.0 : 1.0 / half_sizes_.row(c).maxCoeff();
        A(r + j, nv_ + P.offsets[a] + j) = scale;
        e[r + j] = scale * targets[r + j];
      }
      r += d;
    }
  }

  void fill_acceleration_regularizer(const Program &, const Slot &, Rows A, Segment e, Segment, Segment)
  {
    A.leftCols(nv_).setIdentity();
    e.setZero();
  }

  // qdd ≈ target (PassiveWBC's posture regulariser, Fahmi et al. 2019 eq. 7a)
  void fill_acceleration_target(const Program &, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    A.leftCols(nv_).setIdentity();
    e = Map<const VectorXd>(s.p(0), nv_);
  }

  // Fahmi et al. 2019 eqs. 2, 4, 8: sum_i [f_i; (p_i - c) x f_i] = W_com,d (point contacts), the
  // trunk impedance's desired wrench (TrunkImpedance.wrench); with "heading" both sides in the
  // heading frame of the reference rotation (wrench.heading_rotation), so that per-row weights
  // are the weights about that frame (wrench.heading_weights)
  void fill_trunk_wrench(const Program & P, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const Vector3d c = data_.com[0];
    for (Index a : s.contacts)
    {
      auto B = A.block(0, nv_ + P.offsets[a], 6, 3);
      B.topRows(3).setIdentity();
      B.bottomRows(3) = pinocchio::skew(Vector3d(points_.row(P.contacts[a]).transpose() - c));
    }
    using Vec3 = Map<const Vector3d>;
    const Vec3 K_x(s.p(0)), D_x(s.p(1)), K_theta(s.p(2)), D_theta(s.p(3));
    const bool feedforward = *s.p(4) != 0.0, heading = *s.p(12) != 0.0;
    const Matrix3d R_ref = Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(s.p(9));
    const Matrix3d R = data_.oMi[1].rotation();
    const Vector3d omega = R * v_.segment<3>(3);
    Vector6d w;
    w.head<3>() = K_x.cwiseProduct(Vec3(s.p(6)) - c) + D_x.cwiseProduct(Vec3(s.p(7)) - data_.vcom[0]);
    w.tail<3>() = K_theta.cwiseProduct(pinocchio::log3(Matrix3d(R_ref * R.transpose())))
                  + D_theta.cwiseProduct(Vec3(s.p(10)) - omega);
    w[2] += mass_ * kGravity; // gravity compensation
    if (feedforward)          // W_ff with the locked centroidal inertia
    {
      w.head<3>() += mass_ * Vec3(s.p(8));
      w.tail<3>() += data_.Ig.inertia().matrix() * Vec3(s.p(11));
    }
    w -= Map<const Vector6d>(s.p(5));
    e = w;
    const double norm = std::hypot(R_ref(0, 0), R_ref(1, 0));
    if (!heading || norm == 0.0)
      return;
    Matrix3d Rh = Matrix3d::Identity(); // the rotation about z by the heading, transposed
    Rh.topLeftCorner<2, 2>() << R_ref(0, 0) / norm, R_ref(1, 0) / norm, -R_ref(1, 0) / norm, R_ref(0, 0) / norm;
    for (Index a : s.contacts)
      for (Index half : {0, 3})
      {
        auto B = A.block(half, nv_ + P.offsets[a], 3, 3);
        B = (Rh * B).eval();
      }
    e.head(3) = Rh * w.head<3>();
    e.tail(3) = Rh * w.tail<3>();
  }

  // joint torques of the contact forces, -J_st,j^T lambda (Fahmi et al. 2019 Sect. V-D, fn. 16)
  void fill_contact_torque_regularizer(const Program & P, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    for (Index a : s.contacts)
    {
      const Index d = contact_dims_[P.contacts[a]];
      A.middleCols(nv_ + P.offsets[a], d) = -P.Jc.block(P.offsets[a], 6, d, na_).transpose();
    }
    e.setZero();
  }

  // the force's part off the lean's direction about each normal ≈ 0 (Fahmi et al. 2019 Sect. V-D)
  void fill_tangential_force_regularizer(const Program & P, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const double mu = *s.p(0);
    const Map<const Vector3d> lean(s.p(1));
    const double * normals = s.p(2);
    for (std::size_t k = 0; k < s.contacts.size(); ++k)
      A.block(2 * Index(k), nv_ + P.offsets[s.contacts[k]], 2, 3) =
        tangent_rows(Map<const Vector3d>(normals + 3 * k), lean, mu);
    e.setZero();
  }

  // named joints track (position, velocity, acceleration) with a PD (Herzog et al. 2016 Sect. 5.4)
  void fill_joint_trajectory(const Program &, const Slot & s, Rows A, Segment e, Segment, Segment)
  {
    const auto & rows = s.pick(0);
    const double *position = s.p(0), *velocity = s.p(1), *acceleration = s.p(2), *kp = s.p(3), *kd = s.p(4);
    for (std::size_t i = 0; i < rows.size(); ++i)
    {
      const Index j = rows[i];
      A(Index(i), 6 + j) = 1.0;
      e[Index(i)] = acceleration[i] + kp[i] * (position[i] - angles_[j]) + kd[i] * (velocity[i] - v_[6 + j]);
    }
  }

  wholebody::LeggedModel model_;
  wholebody::LeggedData data_;
  Index nq_ = 0, nv_ = 0, na_ = 0, nc_ = 0;
  std::vector<pinocchio::FrameIndex> frames_;
  std::vector<int> contact_frames_, contact_dims_;
  VectorXd radii_, q_min_, q_max_, q_, v_;
  JointAngles joint_angles_; // the actuated joints' angles of q_ (continuous joints: atan2)
  VectorXd angles_;
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
    .def("cycle", &HierarchyCycle::cycle, py::arg("program"), py::arg("packer"), py::arg("quick"),
         py::arg("q") = py::none(), py::arg("v") = py::none())
    .def("recover", &HierarchyCycle::recover, py::arg("program"), py::arg("x"))
    .def("bind_state", &HierarchyCycle::bind_state, py::arg("buffers"))
    .def("terms", &HierarchyCycle::terms)
    .def("frame_placement", &HierarchyCycle::frame_placement, py::arg("frame"))
    .def("add_frame", &HierarchyCycle::add_frame, py::arg("joint"), py::arg("placement"))
    .def_static("kernels", &HierarchyCycle::kernel_names)
    .def_property_readonly("q", &HierarchyCycle::q)
    .def_property_readonly("com", &HierarchyCycle::com)
    .def_property_readonly("vcom", &HierarchyCycle::vcom)
    .def_property_readonly("h_G", &HierarchyCycle::h_G)
    .def_property_readonly("nv", &HierarchyCycle::nv)
    .def_property_readonly("na", &HierarchyCycle::na);
  py::class_<ParameterPacker>(m, "ParameterPacker")
    .def(py::init<const py::list &>(), py::arg("sources"))
    .def("pack", &ParameterPacker::pack)
    .def("__len__", &ParameterPacker::size);
}
