// The passive whole-body controller's per-cycle work in one compiled object (Fahmi et al. 2019):
// Pinocchio's rigid-body terms, the QP of eqs. 7-18 written into the arrays that
// wholebody.control.passive.PassiveWBC hands to DAQP, and the torques of eq. 19.
//
// It mirrors PassiveWBC's Python assembly (the tested reference) row for row: same layout, same
// senses, same formulas; tests/test_passive_native.py checks both on recorded closed-loop cycles.
// Only the arithmetic lives here; the QP is solved by DAQP from Python and failures are handled
// there. Python allocates every array this object writes (``bind``) so nothing is copied back.
#include "native_common.hpp"

#include <pinocchio/algorithm/centroidal.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/spatial.hpp>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace py = pybind11;
using namespace wholebody_native;

class PassiveCycle
{
public:
  explicit PassiveCycle(const py::dict & spec)
  {
    build_model(spec);
    configure(spec);
  }

  // Weights, gains and limits (see PassiveWBC._native_spec); may be called between cycles.
  void configure(const py::dict & spec)
  {
    slack_none_ = get<std::string>(spec, "swing_slack") == "none";
    slack_weight_ = get<double>(spec, "slack_weight");
    K_st_ = get<double>(spec, "K_st");
    D_st_ = get<double>(spec, "D_st");
    control_period_ = get<double>(spec, "control_period");
    Q_ = get_vector(spec, "Q", 6);
    R_qdd_ = get<double>(spec, "R_qdd");
    R_force_ = get<double>(spec, "R_force");
    posture_ = get_vector(spec, "posture", nq_);
    posture_K_ = get<double>(spec, "posture_K");
    posture_D_ = get<double>(spec, "posture_D");
    posture_mask_ = get_vector(spec, "posture_mask", na_);
    posture_on_ = (posture_K_ != 0.0 || posture_D_ != 0.0) && posture_mask_.any();
    torque_regularization_ = get<std::string>(spec, "regularization") == "torque";
    force_parallel_ = get<std::string>(spec, "regularization") == "force-parallel";
    tangential_weight_ = get<double>(spec, "tangential_weight");
    torque_weights_ = get_vector(spec, "torque_weights", na_);
    mu_ = get<double>(spec, "mu");
    f_min_ = get<double>(spec, "f_min");
    f_max_ = get<double>(spec, "f_max");
    swing_K_ = get<double>(spec, "swing_K");
    swing_D_ = get<double>(spec, "swing_D");
    swing_feedforward_ = get<bool>(spec, "swing_feedforward");
    K_x_ = get_vector(spec, "K_x", 3);
    D_x_ = get_vector(spec, "D_x", 3);
    K_theta_ = get_vector(spec, "K_theta", 3);
    D_theta_ = get_vector(spec, "D_theta", 3);
    trunk_feedforward_ = get<bool>(spec, "trunk_feedforward");
    mass_ = get<double>(spec, "mass");
    limits_tanh_ = get<std::string>(spec, "limits_mode") == "tanh";
    horizon_ = get<double>(spec, "horizon");
    a_max_ = get<double>(spec, "a_max");
    steepness_ = get<double>(spec, "steepness");
    torque_ = TorqueProfile::from_spec(spec, na_);
    torque_scale_ = get<double>(spec, "torque_scale");
    torque_cap_ = get_vector(spec, "torque_cap", na_);
  }

  // The arrays this object writes (allocated by Python, see PassiveQP.__init__ and
  // PassiveWBC._build_native).
  void bind(const py::dict & b)
  {
    keep_.clear();
    H_ = buffer<double>(b, "H", n_ * n_, keep_);
    g_ = buffer<double>(b, "g", n_, keep_);
    A_ = buffer<double>(b, "A", m_ * n_, keep_);
    upper_ = buffer<double>(b, "upper", n_ + m_, keep_);
    lower_ = buffer<double>(b, "lower", n_ + m_, keep_);
    sense_ = buffer<int32_t>(b, "sense", n_ + m_, keep_);
    feet_ = buffer<double>(b, "feet", 3 * n_legs_, keep_);
    tau_ = buffer<double>(b, "tau", na_, keep_);
    tau_lo_ = buffer<double>(b, "tau_lo", na_, keep_);
    tau_hi_ = buffer<double>(b, "tau_hi", na_, keep_);
    h_out_ = buffer<double>(b, "h", nv_, keep_);
    hg_out_ = buffer<double>(b, "h_G", 6, keep_);
    wrench_d_ = buffer<double>(b, "wrench_d", 6, keep_);
    commanded_ = buffer<double>(b, "commanded", 6, keep_);
    errors_ = buffer<double>(b, "errors", 12, keep_);
    swing_residual_ = buffer<double>(b, "swing_residual", nc_, keep_);
    qdd_ = buffer<double>(b, "qdd", nv_, keep_);
    forces_ = buffer<double>(b, "forces", nf_, keep_);
    bound_ = true;
  }

  // Robot.update for this cycle: Pinocchio's terms and the contact points, Jacobians and drifts.
  void update(const DoubleArray & q_in, const DoubleArray & v_in)
  {
    require_bound();
    rigid_body_pass(model_, data_, q_in, v_in, q_, v_);
    joint_angles_(q_, angles_);
    for (Index i = 0; i < nc_; ++i)
    {
      Matrix6x & J6 = frame_jacobians_[i];
      J6.setZero();
      pinocchio::getFrameJacobian(model_, data_, frame_ids_[i], pinocchio::LOCAL_WORLD_ALIGNED, J6);
      const pinocchio::Motion acc = pinocchio::getFrameClassicalAcceleration(
        model_, data_, frame_ids_[i], pinocchio::LOCAL_WORLD_ALIGNED);
      frame_drifts_.row(i) = acc.linear().transpose();
      const Vector3d origin = data_.oMf[frame_ids_[i]].translation();
      origins_.row(i) = origin.transpose();
      Map<Vector3d>(feet_ + 3 * leg_[i]) = origin;
      const double r = radii_[i];
      sphere_point(J6, acc.linear(), acc.angular(), v_, r, J_.middleRows(3 * i, 3),
                   drift_.segment<3>(3 * i));
      points_.row(i) = origin.transpose();
      points_(i, 2) -= r;
    }
    Map<VectorXd>(h_out_, nv_) = data_.nle;
    Map<Eigen::Matrix<double, 6, 1>> h_G(hg_out_);
    h_G = data_.hg.toVector();
    updated_ = true;
  }

  // The QP of PassiveWBC.solve for one plan (arrays in the planner's leg order), written into
  // the bound arrays without the swing feet's force variables (fixed at zero) and the rows left
  // free (swing feet's rows and friction rows): the same optimum, a smaller QP for DAQP.
  // Returns (variables, rows) of that QP.
  py::tuple assemble(
    const py::array_t<bool, py::array::c_style | py::array::forcecast> & stance_in,
    const DoubleArray & normals_in, const DoubleArray & foot_position,
    const DoubleArray & foot_velocity, const DoubleArray & foot_acceleration,
    const DoubleArray & trunk_position, const DoubleArray & trunk_velocity,
    const DoubleArray & trunk_acceleration, const DoubleArray & trunk_rotation,
    const DoubleArray & trunk_angular_velocity, const DoubleArray & trunk_angular_acceleration,
    const DoubleArray & external_wrench)
  {
    if (!updated_)
      throw std::runtime_error("assemble: call update(q, v) first");
    if (stance_in.size() != n_legs_)
      throw std::invalid_argument("contact: expected " + std::to_string(n_legs_) + " flags");
    const bool * stance_legs = stance_in.data();
    const double * normals = input(normals_in, 3 * n_legs_, "touchdown_normal");
    const double * fp = input(foot_position, 3 * n_legs_, "foot_position");
    const double * fv = input(foot_velocity, 3 * n_legs_, "foot_velocity");
    const double * fa = input(foot_acceleration, 3 * n_legs_, "foot_acceleration");
    RowMatrix & A = A_full_;
    RowMatrix & H = H_full_;
    VectorXd & g = g_full_;
    VectorXd & up = upper_full_;
    VectorXd & lo = lower_full_;
    std::vector<int32_t> & sense = sense_full_;
    const Index nv = nv_, n = n_, rf = r_feet_, rq = r_fric_;
    for (Index i = 0; i < nc_; ++i)
      stance_[i] = stance_legs[leg_[i]];
    bool all_stance = true;
    for (Index i = 0; i < nc_; ++i)
      all_stance = all_stance && stance_[i];

    // eq. 9 and eq. 15 in one block: M q̈ − Jᵀ F = −h (base rows equal, joint rows bounded)
    A.topLeftCorner(nv, nv) = data_.M;
    A.block(0, nv, nv, nf_) = -J_.transpose();
    torque_bounds();
    up.segment(n, nv) = -data_.nle;
    lo.segment(n, nv) = -data_.nle;
    up.segment(n + 6, na_) += Map<VectorXd>(tau_hi_, na_);
    lo.segment(n + 6, na_) += Map<VectorXd>(tau_lo_, na_);
    joint_acceleration_bounds(lo, up);

    // stance feet, eq. 10 / 32 (rows of swing feet freed or overwritten below); x̂_st is the
    // contact point minus the slip, J v integrated since touchdown and at most the foot's radius
    // (PassiveWBC._stance_anchors)
    contact_velocity_.noalias() = J_ * v_;
    for (Index i = 0; i < nc_; ++i)
      stance_anchor(i, points_.row(i), contact_velocity_.segment<3>(3 * i).transpose());
    A.block(rf, 0, 3 * nc_, nv) = J_;
    VectorXd & target = feet_target_;
    target = -drift_;
    if (K_st_ != 0.0 || D_st_ != 0.0)
    {
      for (Index i = 0; i < nc_; ++i)
        target.segment<3>(3 * i) += K_st_ * (anchors_.row(i) - points_.row(i)).transpose();
      target.noalias() -= D_st_ * contact_velocity_;
    }
    for (Index k = 0; k < 3 * nc_; ++k)
    {
      const bool st = stance_[k / 3];
      up[n + rf + k] = st ? target[k] : kInf;
      lo[n + rf + k] = st ? target[k] : -kInf;
      sense[n + rf + k] = st ? kEqual : kFree;
    }

    // eqs. 13-14: friction pyramid and normal-force bounds; swing forces bounded to zero
    tangential_.setZero();
    for (Index i = 0; i < nc_; ++i)
    {
      Vector3d t1, t2, nn;
      tangent_basis(Map<const Vector3d>(normals + 3 * leg_[i]), t1, t2, nn);
      const Index rr = rq + 5 * i, fi = nv + 3 * i;
      A.block<1, 3>(rr, fi) = (t1 - mu_ * nn).transpose();
      A.block<1, 3>(rr + 1, fi) = (-t1 - mu_ * nn).transpose();
      A.block<1, 3>(rr + 2, fi) = (t2 - mu_ * nn).transpose();
      A.block<1, 3>(rr + 3, fi) = (-t2 - mu_ * nn).transpose();
      A.block<1, 3>(rr + 4, fi) = nn.transpose();
      const bool st = stance_[i];
      for (Index k = 0; k < 4; ++k)
      {
        up[n + rr + k] = st ? 0.0 : kInf;
        lo[n + rr + k] = -kInf;
      }
      up[n + rr + 4] = st ? f_max_ : kInf;
      lo[n + rr + 4] = st ? f_min_ : -kInf;
      if (st)
        tangential_.block<3, 3>(3 * i, 3 * i) = t1 * t1.transpose() + t2 * t2.transpose();
      for (Index k = 0; k < 3; ++k)
      {
        up[fi + k] = st ? kInf : 0.0;
        lo[fi + k] = st ? -kInf : 0.0;
        sense[fi + k] = st ? kFree : kEqual;
      }
    }

    // cost: ‖u‖²_R, the trunk wrench (eqs. 4, 7a, 8) and the force regulariser (Sect. V-D)
    H.setZero();
    H.diagonal().head(nv).setConstant(R_qdd_);
    H.diagonal().segment(nv, nf_).setConstant(R_force_);
    g.setZero();
    const Vector3d com = data_.com[0];
    for (Index i = 0; i < nc_; ++i)
    {
      const Vector3d r = points_.row(i).transpose() - com;
      auto Gi = G_.middleCols<3>(3 * i);
      Gi.topRows<3>().setIdentity();
      Gi.bottomRows<3>() << 0.0, -r[2], r[1], r[2], 0.0, -r[0], -r[1], r[0], 0.0;
    }
    const double * rotation = input(trunk_rotation, 9, "trunk.rotation");
    trunk_wrench(
      input(trunk_position, 3, "trunk.position"), input(trunk_velocity, 3, "trunk.velocity"),
      input(trunk_acceleration, 3, "trunk.acceleration"), rotation,
      input(trunk_angular_velocity, 3, "trunk.angular_velocity"),
      input(trunk_angular_acceleration, 3, "trunk.angular_acceleration"),
      input(external_wrench, 6, "external_wrench"), data_.oMi[1].rotation(),
      data_.oMi[1].rotation() * v_.segment<3>(3), data_.com[0], data_.vcom[0],
      data_.Ig.inertia().matrix());
    const Map<const Eigen::Matrix<double, 6, 1>> W_d(wrench_d_);
    GQ_.noalias() = G_.transpose() * heading_weights(rotation);
    HF_.noalias() = GQ_ * G_;
    g.segment(nv, nf_).noalias() = -GQ_ * W_d;
    if (posture_on_) // ‖q̈ − q̈_posture‖²_R (PassiveWBC.posture_acceleration)
    {
      pinocchio::difference(model_, q_, posture_, posture_error_);
      g.segment(6, na_) -= R_qdd_ * posture_mask_.cwiseProduct(
        posture_K_ * posture_error_.tail(na_) - posture_D_ * v_.tail(na_));
    }
    if (torque_regularization_) // footnote 16: R_F = J_st,j R_τ J_st,jᵀ
      HF_.noalias() += J_.rightCols(na_) * torque_weights_.asDiagonal() * J_.rightCols(na_).transpose();
    else if (tangential_weight_ != 0.0)
    {
      if (force_parallel_) // every force leaning like the desired net force (ours)
        for (Index i = 0; i < nc_; ++i)
        {
          if (!stance_[i])
            continue;
          const Eigen::Matrix<double, 2, 3> rows =
            tangent_rows(Map<const Vector3d>(normals + 3 * leg_[i]), W_d.head<3>(), mu_);
          tangential_.block<3, 3>(3 * i, 3 * i).noalias() = rows.transpose() * rows;
        }
      HF_ += tangential_weight_ * tangential_;
    }
    H.block(nv, nv, nf_, nf_) += HF_;

    // swing feet: eq. 6 and eq. 12, as a weighted least-squares term (eq. 33) or hard (eq. 11)
    if (!all_stance)
    {
      for (Index i = 0; i < nc_; ++i)
      {
        if (stance_[i])
          continue;
        const auto Jsw = frame_jacobians_[i].topRows<3>();
        const Index l = leg_[i];
        Vector3d a_d = swing_K_ * (Map<const Vector3d>(fp + 3 * l) - origins_.row(i).transpose());
        a_d += swing_D_ * (Map<const Vector3d>(fv + 3 * l) - Jsw * v_);
        if (swing_feedforward_)
          a_d += Map<const Vector3d>(fa + 3 * l);
        const Vector3d b = a_d - frame_drifts_.row(i).transpose();
        swing_targets_.row(i) = b.transpose();
        if (slack_none_)
        {
          A.block(rf + 3 * i, 0, 3, nv) = Jsw;
          for (Index k = 0; k < 3; ++k)
          {
            up[n + rf + 3 * i + k] = lo[n + rf + 3 * i + k] = b[k];
            sense[n + rf + 3 * i + k] = kEqual;
          }
        }
        else // rows stay free: α‖J q̈ − b‖² in the cost
        {
          H.topLeftCorner(nv, nv).noalias() += slack_weight_ * (Jsw.transpose() * Jsw);
          g.head(nv).noalias() -= slack_weight_ * (Jsw.transpose() * b);
        }
      }
    }
    H.triangularView<Eigen::StrictlyUpper>() = H.transpose().triangularView<Eigen::StrictlyUpper>();
    compact();
    assembled_ = true;
    return py::make_tuple(kept_vars_.size(), kept_rows_.size());
  }

  // Eq. 19 for a QP solution x = [q̈, F]: torques (not clipped: wholebody.guard.guard_torque
  // checks and clips them on the Python side, for both engines; returns by how much they exceed
  // the bounds), the commanded contact wrench and the swing residuals.
  // x is the solution of the compact QP; NaN is returned (nothing written) if it is not finite.
  double finish(const DoubleArray & x_in)
  {
    if (!assembled_)
      throw std::runtime_error("finish: call assemble(...) first");
    const double * xc = input(x_in, Index(kept_vars_.size()), "x", false);
    x_full_.setZero();
    for (std::size_t a = 0; a < kept_vars_.size(); ++a)
    {
      if (!std::isfinite(xc[a]))
        return std::numeric_limits<double>::quiet_NaN();
      x_full_[kept_vars_[a]] = xc[a];
    }
    const Map<const VectorXd> qdd(x_full_.data(), nv_), F(x_full_.data() + nv_, nf_);
    Map<VectorXd> tau(tau_, na_);
    tau.noalias() = data_.M.bottomRows(na_) * qdd;
    tau += data_.nle.tail(na_);
    tau.noalias() -= J_.rightCols(na_).transpose() * F;
    const Map<VectorXd> lo(tau_lo_, na_), hi(tau_hi_, na_);
    const double excess = std::max((tau - hi).maxCoeff(), (lo - tau).maxCoeff());
    Map<VectorXd>(qdd_, nv_) = qdd;
    Map<VectorXd>(forces_, nf_) = F;
    Map<Eigen::Matrix<double, 6, 1>>(commanded_).noalias() = G_ * F;
    for (Index i = 0; i < nc_; ++i)
      swing_residual_[i] =
        stance_[i] ? 0.0
                   : (frame_jacobians_[i].topRows<3>() * qdd - swing_targets_.row(i).transpose()).norm();
    return excess;
  }

  // Writes the full-layout QP without fixed-at-zero variables and free rows into the bound arrays.
  void compact()
  {
    kept_vars_.clear();
    kept_rows_.clear();
    for (Index j = 0; j < n_; ++j)
      if (!(sense_full_[j] == kEqual && upper_full_[j] == 0.0 && lower_full_[j] == 0.0))
        kept_vars_.push_back(j);
    for (Index r = 0; r < m_; ++r)
      if (upper_full_[n_ + r] != kInf || lower_full_[n_ + r] != -kInf)
        kept_rows_.push_back(r);
    const Index k = Index(kept_vars_.size()), rows = Index(kept_rows_.size());
    Map<RowMatrix> H(H_, k, k), A(A_, rows, k);
    for (Index a = 0; a < k; ++a)
    {
      g_[a] = g_full_[kept_vars_[a]];
      upper_[a] = upper_full_[kept_vars_[a]];
      lower_[a] = lower_full_[kept_vars_[a]];
      sense_[a] = sense_full_[kept_vars_[a]];
      for (Index b = 0; b < k; ++b)
        H(a, b) = H_full_(kept_vars_[a], kept_vars_[b]);
    }
    for (Index r = 0; r < rows; ++r)
    {
      const Index row = kept_rows_[r];
      upper_[k + r] = upper_full_[n_ + row];
      lower_[k + r] = lower_full_[n_ + row];
      sense_[k + r] = sense_full_[n_ + row];
      for (Index b = 0; b < k; ++b)
        A(r, b) = A_full_(row, kept_vars_[b]);
    }
  }

  // The stack engine (PassiveWBC engine "stack"): the arrays of the compiled HierarchyCycle's
  // terms (HierarchyCycle.terms_view, rewritten by its every update) and those the references
  // go to (Python-owned: the PassiveStack tasks' parameters, the controller's W_d and bounds).
  void bind_stack(const py::dict & b)
  {
    std::vector<py::object> keep;
    terms_q_ = buffer<double>(b, "q", nq_, keep);
    terms_v_ = buffer<double>(b, "v", nv_, keep);
    terms_points_ = buffer<double>(b, "points", 3 * nc_, keep);
    terms_point_velocities_ = buffer<double>(b, "point_velocities", 3 * nc_, keep);
    terms_com_ = buffer<double>(b, "com", 3, keep);
    terms_vcom_ = buffer<double>(b, "vcom", 3, keep);
    terms_rotation_ = buffer<double>(b, "rotation", 9, keep);
    terms_Ig_ = buffer<double>(b, "Ig", 9, keep);
    terms_tau_max_ = buffer<double>(b, "tau_max", na_, keep);
    anchors_out_ = buffer<double>(b, "anchors", 3 * nc_, keep);
    anchor_frames_ = buffer<double>(b, "anchor_frames", 3 * nc_, keep);
    posture_target_ = buffer<double>(b, "posture_target", nv_, keep);
    tau_lo_ = buffer<double>(b, "tau_lo", na_, keep);
    tau_hi_ = buffer<double>(b, "tau_hi", na_, keep);
    wrench_d_ = buffer<double>(b, "wrench_d", 6, keep);
    errors_ = buffer<double>(b, "errors", 12, keep);
    commanded_ = buffer<double>(b, "commanded", 6, keep);
    stack_keep_ = std::move(keep);
    stack_bound_ = true;
  }

  // The controller's settings the stack engine's references read as they are each cycle, as
  // its tasks do (PassiveWBC's attributes): the torque-limit task's scale and per-joint caps
  // (inf: none), the posture regulariser's gains and joint mask, the control period.
  void stack_settings(double torque_scale, const DoubleArray & torque_cap, double posture_K,
                      double posture_D, const DoubleArray & posture_mask, double control_period)
  {
    stack_torque_scale_ = torque_scale;
    torque_cap_ = Map<const VectorXd>(input(torque_cap, na_, "torque_cap", false), na_);
    posture_K_ = posture_K;
    posture_D_ = posture_D;
    posture_mask_ = Map<const VectorXd>(input(posture_mask, na_, "posture_mask"), na_);
    posture_on_ = (posture_K_ != 0.0 || posture_D_ != 0.0) && posture_mask_.any();
    control_period_ = control_period;
  }

  // PassiveWBC._solve_stack's references of one cycle from the bound terms, for a plan given as
  // its arrays (planner's leg order): first the plan is checked (nothing else is done if an
  // array has a NaN/inf entry), then the τ bounds (eq. 15), the stance anchors (eq. 32; also as
  // the contact frames' origins, the anchor plus the radius along z, what the stance task
  // anchors), W_d (eq. 4, with the impedance's gains given) with its errors and the posture
  // regulariser's target accelerations. Returns -1, or the index of the first non-finite array in the order of the arguments
  // (wholebody.control.passive.PLAN_ARRAYS), or 10 if W_d is not finite.
  int stack_references(
    const py::array_t<bool, py::array::c_style | py::array::forcecast> & stance_in,
    const DoubleArray & normals, const DoubleArray & foot_position,
    const DoubleArray & foot_velocity, const DoubleArray & foot_acceleration,
    const DoubleArray & trunk_position, const DoubleArray & trunk_velocity,
    const DoubleArray & trunk_acceleration, const DoubleArray & trunk_rotation,
    const DoubleArray & trunk_angular_velocity, const DoubleArray & trunk_angular_acceleration,
    const DoubleArray & external_wrench, const DoubleArray & K_x, const DoubleArray & D_x,
    const DoubleArray & K_theta, const DoubleArray & D_theta, bool trunk_feedforward)
  {
    if (!stack_bound_)
      throw std::runtime_error("stack_references: call bind_stack(arrays) first");
    if (stance_in.size() != n_legs_)
      throw std::invalid_argument("contact: expected " + std::to_string(n_legs_) + " flags");
    const py::ssize_t feet = 3 * n_legs_;
    const std::pair<const DoubleArray *, py::ssize_t> plan[] = {
      {&normals, feet}, {&foot_position, feet}, {&foot_velocity, feet},
      {&foot_acceleration, feet}, {&trunk_position, 3}, {&trunk_velocity, 3},
      {&trunk_acceleration, 3}, {&trunk_rotation, 9}, {&trunk_angular_velocity, 3},
      {&trunk_angular_acceleration, 3}};
    const char * names[] = {"touchdown_normal", "foot_position", "foot_velocity",
                            "foot_acceleration", "trunk.position", "trunk.velocity",
                            "trunk.acceleration", "trunk.rotation", "trunk.angular_velocity",
                            "trunk.angular_acceleration"};
    const double * p[10];
    for (int k = 0; k < 10; ++k)
    {
      p[k] = input(*plan[k].first, plan[k].second, names[k], false);
      for (py::ssize_t i = 0; i < plan[k].second; ++i)
        if (!std::isfinite(p[k][i]))
          return k;
    }
    // the impedance's gains as they are now (the trunk wrench task reads them every cycle too)
    K_x_ = Map<const Vector3d>(input(K_x, 3, "K_x"));
    D_x_ = Map<const Vector3d>(input(D_x, 3, "D_x"));
    K_theta_ = Map<const Vector3d>(input(K_theta, 3, "K_theta"));
    D_theta_ = Map<const Vector3d>(input(D_theta, 3, "D_theta"));
    trunk_feedforward_ = trunk_feedforward;
    const bool * stance_legs = stance_in.data();
    for (Index i = 0; i < nc_; ++i)
      stance_[i] = stance_legs[leg_[i]];
    { // τ bounds: the robot's τ_max(q) of the terms times the torque-limit task's scale, capped
      Map<VectorXd> hi(tau_hi_, na_), lo(tau_lo_, na_);
      hi = Map<const VectorXd>(terms_tau_max_, na_) * stack_torque_scale_;
      hi = hi.cwiseMin(torque_cap_);
      lo = -hi;
    }
    using Rows3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
    const Map<const Rows3> points(terms_points_, nc_, 3), velocities(terms_point_velocities_, nc_, 3);
    Map<Rows3> anchors(anchors_out_, nc_, 3), frames(anchor_frames_, nc_, 3);
    for (Index i = 0; i < nc_; ++i)
    {
      stance_anchor(i, points.row(i), velocities.row(i));
      anchors.row(i) = anchors_.row(i);
      frames.row(i) = anchors_.row(i);
      frames(i, 2) += radii_[i];
    }
    const Map<const VectorXd> v(terms_v_, nv_);
    const Matrix3d R = Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(terms_rotation_);
    trunk_wrench(p[4], p[5], p[6], p[7], p[8], p[9],
      input(external_wrench, 6, "external_wrench", false), R, R * v.segment<3>(3),
      Map<const Vector3d>(terms_com_), Map<const Vector3d>(terms_vcom_),
      Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(terms_Ig_));
    Map<VectorXd> target(posture_target_, nv_);
    if (posture_on_) // PassiveWBC.posture_acceleration
    {
      pinocchio::difference(model_, Map<const VectorXd>(terms_q_, nq_), posture_, posture_error_);
      target.tail(na_) = posture_mask_.cwiseProduct(posture_K_ * posture_error_.tail(na_)
                                                    - posture_D_ * v.tail(na_));
    }
    else
      target.tail(na_).setZero();
    return Map<const Eigen::Matrix<double, 6, 1>>(wrench_d_).allFinite() ? -1 : 10;
  }

  // The contact wrench about the CoM of the forces ``forces`` (3 per contact, contact order) at
  // the bound terms' contact points: Σ [f_i; (p_i − c) × f_i] (eq. 2, the trunk wrench task's
  // G F), written into the bound ``commanded``.
  void stack_commanded(const DoubleArray & forces)
  {
    if (!stack_bound_)
      throw std::runtime_error("stack_commanded: call bind_stack(arrays) first");
    const double * f = input(forces, 3 * nc_, "forces", false);
    const Map<const Vector3d> com(terms_com_);
    Map<Eigen::Matrix<double, 6, 1>> out(commanded_);
    out.setZero();
    for (Index i = 0; i < nc_; ++i)
    {
      const Map<const Vector3d> fi(f + 3 * i);
      out.head<3>() += fi;
      out.tail<3>() += (Map<const Vector3d>(terms_points_ + 3 * i) - com).cross(fi);
    }
  }

  // Copies of the rigid-body terms of the last update (for tests against Robot.update).
  py::dict terms() const
  {
    py::dict d = rigid_body_terms(data_);
    d["J"] = MatrixXd(J_);
    d["drift"] = VectorXd(drift_);
    d["points"] = MatrixXd(points_);
    d["anchors"] = MatrixXd(anchors_);
    return d;
  }

  Index nv() const { return nv_; }
  Index n() const { return n_; }
  Index m() const { return m_; }

private:
  void build_model(const py::dict & spec)
  {
    add_joints(spec, model_);
    nq_ = model_.nq;
    joint_angles_ = JointAngles(model_);
    angles_ = VectorXd::Zero(model_.nv - 6);
    nv_ = model_.nv;
    na_ = nv_ - 6;
    posture_error_.setZero(nv_);

    auto contact_joints = get<std::vector<int>>(spec, "contact_joints");
    leg_ = get<std::vector<int>>(spec, "leg");
    n_legs_ = get<int>(spec, "n_legs");
    nc_ = Index(contact_joints.size());
    if (Index(leg_.size()) != nc_)
      throw std::invalid_argument("spec: 'leg' and 'contact_joints' differ in length");
    DoubleArray cpl = get<DoubleArray>(spec, "contact_placements");
    const double * cp = input(cpl, 16 * nc_, "contact_placements");
    radii_ = get_vector(spec, "radii", nc_);
    for (Index i = 0; i < nc_; ++i)
    {
      if (leg_[i] < 0 || leg_[i] >= n_legs_)
        throw std::invalid_argument("spec: 'leg' index out of range");
      frame_ids_.push_back(model_.addFrame(pinocchio::Frame(
        "contact" + std::to_string(i), pinocchio::JointIndex(contact_joints[i]),
        placement_from(cp + 16 * i), pinocchio::OP_FRAME)));
    }
    q_min_ = get_vector(spec, "q_min", na_);
    q_max_ = get_vector(spec, "q_max", na_);
    data_ = wholebody::LeggedData(model_);

    nf_ = 3 * nc_;
    n_ = nv_ + nf_;
    r_feet_ = nv_;
    r_fric_ = r_feet_ + 3 * nc_;
    m_ = r_fric_ + 5 * nc_;
    frame_jacobians_.assign(nc_, Matrix6x::Zero(6, nv_));
    frame_drifts_.setZero(nc_, 3);
    origins_.setZero(nc_, 3);
    points_.setZero(nc_, 3);
    anchors_.setZero(nc_, 3);
    slip_.setZero(nc_, 3);
    contact_velocity_.setZero(3 * nc_);
    swing_targets_.setZero(nc_, 3);
    J_.setZero(3 * nc_, nv_);
    drift_.setZero(3 * nc_);
    feet_target_.setZero(3 * nc_);
    G_.setZero(6, nf_);
    GQ_.setZero(nf_, 6);
    HF_.setZero(nf_, nf_);
    tangential_.setZero(nf_, nf_);
    stance_.assign(nc_, false);
    was_stance_.assign(nc_, false);
    // the full layout of PassiveQP.__init__ (control/passive_qp.py), and its constant parts
    H_full_.setZero(n_, n_);
    A_full_.setZero(m_, n_);
    g_full_.setZero(n_);
    x_full_.setZero(n_);
    upper_full_.setZero(n_ + m_);
    lower_full_.setZero(n_ + m_);
    upper_full_.head(6).setConstant(kInf);
    lower_full_.head(6).setConstant(-kInf);
    sense_full_.assign(n_ + m_, kFree);
    for (Index i = n_; i < n_ + 6; ++i)
      sense_full_[i] = kEqual;
  }

  void require_bound() const
  {
    if (!bound_)
      throw std::runtime_error("update: call bind(buffers) first");
  }

  // τ_min(q), τ_max(q) of eq. 15: the robot's linkage profile (wholebody.robots.torque_limits),
  // scaled, capped by the weak-joint overrides.
  void torque_bounds()
  {
    Map<VectorXd> hi(tau_hi_, na_), lo(tau_lo_, na_);
    torque_.upper(angles_, hi);
    hi *= torque_scale_;
    hi = hi.cwiseMin(torque_cap_);
    lo = -hi;
  }

  // eqs. 16-18 (braking) or Herzog et al. 2016's tanh form, as JointAccelerationLimits.bounds.
  void joint_acceleration_bounds(VectorXd & lo, VectorXd & up) const
  {
    for (Index j = 0; j < na_; ++j)
    {
      const double q = angles_[j], qd = v_[6 + j];
      if (limits_tanh_)
      {
        lo[6 + j] = a_max_ * std::tanh(steepness_ * (q_min_[j] - q));
        up[6 + j] = a_max_ * std::tanh(steepness_ * (q_max_[j] - q));
      }
      else
      {
        const double h = horizon_;
        lo[6 + j] = 2.0 * (q_min_[j] - q - h * qd) / (h * h);
        up[6 + j] = 2.0 * (q_max_[j] - q - h * qd) / (h * h);
      }
    }
  }

  // wholebody.tasks.wrench.heading_weights: Q_ about the heading frame of the trunk reference
  // (row-major 3 x 3 rotation); weights equal about x and y: diag(Q_) exactly.
  Eigen::Matrix<double, 6, 6> heading_weights(const double * rotation) const
  {
    Eigen::Matrix<double, 6, 6> W = Q_.asDiagonal();
    const double norm = std::hypot(rotation[0], rotation[3]);
    if ((Q_[0] == Q_[1] && Q_[3] == Q_[4]) || norm == 0.0)
      return W;
    const double c = rotation[0] / norm, s = rotation[3] / norm;
    Matrix3d Rh;
    Rh << c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0;
    W.topLeftCorner<3, 3>() = Rh * Q_.head<3>().asDiagonal() * Rh.transpose();
    W.bottomRightCorner<3, 3>() = Rh * Q_.tail<3>().asDiagonal() * Rh.transpose();
    return W;
  }

  // W_com,d of eq. 4 (wholebody.tasks.wrench.TrunkImpedance.wrench_at) for base rotation R,
  // world angular velocity omega, CoM position and velocity and locked centroidal inertia Ig.
  void trunk_wrench(
    const double * position, const double * velocity, const double * acceleration,
    const double * rotation, const double * angular_velocity, const double * angular_acceleration,
    const double * external, const Matrix3d & R, const Vector3d & omega, const Vector3d & com,
    const Vector3d & vcom, const Matrix3d & Ig)
  {
    const Matrix3d R_d = Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(rotation);
    Map<Eigen::Matrix<double, 12, 1>> e(errors_);
    e.segment<3>(0) = Map<const Vector3d>(position) - com;
    e.segment<3>(3) = pinocchio::log3(Matrix3d(R_d * R.transpose()));
    e.segment<3>(6) = Map<const Vector3d>(velocity) - vcom;
    e.segment<3>(9) = Map<const Vector3d>(angular_velocity) - omega;
    Map<Eigen::Matrix<double, 6, 1>> out(wrench_d_);
    out.head<3>() = K_x_.cwiseProduct(e.segment<3>(0)) + D_x_.cwiseProduct(e.segment<3>(6));
    out.tail<3>() = K_theta_.cwiseProduct(e.segment<3>(3)) + D_theta_.cwiseProduct(e.segment<3>(9));
    out[2] += mass_ * kGravity;
    if (trunk_feedforward_)
    {
      out.head<3>() += mass_ * Map<const Vector3d>(acceleration);
      out.tail<3>() += Ig * Map<const Vector3d>(angular_acceleration);
    }
    out -= Map<const Eigen::Matrix<double, 6, 1>>(external);
  }

  // x̂_st of eq. 32 (PassiveWBC._stance_anchors) for contact i at ``point`` moving with
  // ``velocity``: the point minus the slip, J v integrated since touchdown and at most the foot's
  // radius (a rolling foot).
  void stance_anchor(Index i, const Eigen::Ref<const Eigen::RowVector3d> & point,
                     const Eigen::Ref<const Eigen::RowVector3d> & velocity)
  {
    if (stance_[i] && was_stance_[i])
    {
      slip_.row(i) += control_period_ * velocity;
      const double norm = slip_.row(i).norm(); // at most the foot's radius (a rolling foot)
      if (norm > radii_[i])
        slip_.row(i) *= norm > 0.0 ? radii_[i] / norm : 0.0;
    }
    else
      slip_.row(i).setZero();
    was_stance_[i] = stance_[i];
    anchors_.row(i) = point - slip_.row(i);
  }

  wholebody::LeggedModel model_;
  wholebody::LeggedData data_;
  Index nq_ = 0, nv_ = 0, na_ = 0, nc_ = 0, nf_ = 0, n_ = 0, m_ = 0, r_feet_ = 0, r_fric_ = 0;
  int n_legs_ = 0;
  std::vector<int> leg_;
  std::vector<pinocchio::FrameIndex> frame_ids_;
  VectorXd radii_, q_min_, q_max_, q_, v_;
  JointAngles joint_angles_; // the actuated joints' angles of q_ (continuous joints: atan2)
  VectorXd angles_;
  // settings
  bool slack_none_ = false, torque_regularization_ = false, force_parallel_ = false, swing_feedforward_ = true;
  bool trunk_feedforward_ = true, limits_tanh_ = false;
  double slack_weight_ = 0, K_st_ = 0, D_st_ = 0, control_period_ = 0, R_qdd_ = 0, R_force_ = 0, tangential_weight_ = 0;
  double mu_ = 0, f_min_ = 0, f_max_ = 0, swing_K_ = 0, swing_D_ = 0, mass_ = 0;
  double horizon_ = 0, a_max_ = 0, steepness_ = 0, torque_scale_ = 1, stack_torque_scale_ = 1;
  VectorXd Q_, torque_weights_, K_x_, D_x_, K_theta_, D_theta_, torque_cap_;
  TorqueProfile torque_;
  // per-cycle state
  std::vector<Matrix6x> frame_jacobians_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> frame_drifts_, origins_, points_, anchors_, slip_,
    swing_targets_;
  MatrixXd J_, G_, GQ_, HF_, tangential_;
  VectorXd posture_, posture_error_, posture_mask_;
  double posture_K_ = 0, posture_D_ = 0;
  bool posture_on_ = false;
  RowMatrix H_full_, A_full_;
  VectorXd g_full_, upper_full_, lower_full_, x_full_;
  std::vector<int32_t> sense_full_;
  std::vector<Index> kept_vars_, kept_rows_;
  VectorXd drift_, feet_target_, contact_velocity_;
  std::vector<bool> stance_, was_stance_;
  bool bound_ = false, updated_ = false, assembled_ = false, stack_bound_ = false;
  // Python-owned buffers
  std::vector<py::object> keep_, stack_keep_;
  double *H_ = nullptr, *g_ = nullptr, *A_ = nullptr, *upper_ = nullptr, *lower_ = nullptr;
  int32_t * sense_ = nullptr;
  double *feet_ = nullptr, *tau_ = nullptr, *tau_lo_ = nullptr, *tau_hi_ = nullptr, *h_out_ = nullptr;
  double *hg_out_ = nullptr, *wrench_d_ = nullptr, *commanded_ = nullptr, *errors_ = nullptr;
  double *swing_residual_ = nullptr, *qdd_ = nullptr, *forces_ = nullptr;
  // the stack engine's (bind_stack)
  double *terms_q_ = nullptr, *terms_v_ = nullptr, *terms_points_ = nullptr,
         *terms_point_velocities_ = nullptr, *terms_com_ = nullptr, *terms_vcom_ = nullptr,
         *terms_rotation_ = nullptr, *terms_Ig_ = nullptr, *terms_tau_max_ = nullptr;
  double *anchors_out_ = nullptr, *anchor_frames_ = nullptr, *posture_target_ = nullptr;
};

PYBIND11_MODULE(_passive_cycle, m)
{
  m.doc() = "Compiled per-cycle work of wholebody.control.passive.PassiveWBC (engine='native').";
  py::class_<PassiveCycle>(m, "PassiveCycle")
    .def(py::init<const py::dict &>(), py::arg("spec"))
    .def("configure", &PassiveCycle::configure, py::arg("spec"))
    .def("bind", &PassiveCycle::bind, py::arg("buffers"))
    .def("update", &PassiveCycle::update, py::arg("q"), py::arg("v"))
    .def("assemble", &PassiveCycle::assemble)
    .def("finish", &PassiveCycle::finish, py::arg("x"))
    .def("bind_stack", &PassiveCycle::bind_stack, py::arg("arrays"))
    .def("stack_references", &PassiveCycle::stack_references)
    .def("stack_commanded", &PassiveCycle::stack_commanded, py::arg("forces"))
    .def("stack_settings", &PassiveCycle::stack_settings)
    .def("terms", &PassiveCycle::terms)
    .def_property_readonly("nv", &PassiveCycle::nv)
    .def_property_readonly("n", &PassiveCycle::n)
    .def_property_readonly("m", &PassiveCycle::m);
}
