// PassiveWBC's per-cycle references in compiled code (Fahmi et al. 2019): what the controller
// computes around its QP, which is a stack of library tasks solved by the compiled hierarchy
// program (wholebody.control.passive_stack, wholebody.cycle.HierarchyCycle).
//
// From the hierarchy cycle's rigid-body terms (HierarchyCycle.terms_view, bound once) it writes,
// each cycle, the τ bounds (eq. 15), the stance anchors (eq. 32), the desired trunk wrench W_d
// (eq. 4) with its errors and the posture regulariser's target, into arrays Python owns (the
// tasks' parameters and the controller's); after the solve, the commanded contact wrench G F
// (eq. 8). It mirrors PassiveWBC's Python references (PassiveWBC._state_references, the tested
// reference); tests/parity/test_passive_native.py checks both.
#include "native_common.hpp"

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/spatial.hpp>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace py = pybind11;
using namespace wholebody_native;

class PassiveReferences
{
public:
  // spec: the robot's model (Robot.native_model_spec, for the posture's Lie difference), the
  // contacts' radii, the leg of the planner each contact is ("leg", "n_legs"), the robot's mass
  // and its reference posture ("posture").
  explicit PassiveReferences(const py::dict & spec)
  {
    add_joints(spec, model_);
    nq_ = model_.nq;
    nv_ = model_.nv;
    na_ = nv_ - 6;
    posture_error_.setZero(nv_);
    posture_ = get_vector(spec, "posture", nq_);
    leg_ = get<std::vector<int>>(spec, "leg");
    n_legs_ = get<int>(spec, "n_legs");
    nc_ = Index(leg_.size());
    radii_ = get_vector(spec, "radii", nc_);
    for (Index i = 0; i < nc_; ++i)
      if (leg_[i] < 0 || leg_[i] >= n_legs_)
        throw std::invalid_argument("spec: 'leg' index out of range");
    mass_ = get<double>(spec, "mass");
    torque_cap_.setConstant(na_, kInf);
    posture_mask_.setZero(na_);
    anchors_.setZero(nc_, 3);
    slip_.setZero(nc_, 3);
    stance_.assign(nc_, false);
    was_stance_.assign(nc_, false);
  }

  // The arrays of the compiled HierarchyCycle's terms (HierarchyCycle.terms_view, rewritten by
  // its every update) and those the references go to (Python-owned: the PassiveStack tasks'
  // parameters, the controller's W_d, errors, bounds and commanded wrench).
  void bind(const py::dict & b)
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
    keep_ = std::move(keep);
    bound_ = true;
  }

  // The controller's settings the references read as they are each cycle, as its tasks do
  // (PassiveWBC's attributes): the torque-limit task's scale and per-joint caps (inf: none), the
  // posture regulariser's gains and joint mask, the control period.
  void settings(double torque_scale, const DoubleArray & torque_cap, double posture_K,
                double posture_D, const DoubleArray & posture_mask, double control_period)
  {
    torque_scale_ = torque_scale;
    torque_cap_ = Map<const VectorXd>(input(torque_cap, na_, "torque_cap", false), na_);
    posture_K_ = posture_K;
    posture_D_ = posture_D;
    posture_mask_ = Map<const VectorXd>(input(posture_mask, na_, "posture_mask"), na_);
    posture_on_ = (posture_K_ != 0.0 || posture_D_ != 0.0) && posture_mask_.any();
    control_period_ = control_period;
  }

  // The references of one cycle from the bound terms, for a plan given as its arrays (planner's
  // leg order): first the plan is checked (nothing else is done if an array has a NaN/inf
  // entry), then the τ bounds (eq. 15), the stance anchors (eq. 32; also as the contact frames'
  // origins, the anchor plus the radius along z, what the stance task anchors), W_d (eq. 4, with
  // the impedance's gains given) with its errors and the posture regulariser's target
  // accelerations. Returns -1, or the index of the first non-finite array in the order of the
  // arguments (wholebody.control.passive.PLAN_ARRAYS), or 10 if W_d is not finite.
  int update(
    const py::array_t<bool, py::array::c_style | py::array::forcecast> & stance_in,
    const DoubleArray & normals, const DoubleArray & foot_position,
    const DoubleArray & foot_velocity, const DoubleArray & foot_acceleration,
    const DoubleArray & trunk_position, const DoubleArray & trunk_velocity,
    const DoubleArray & trunk_acceleration, const DoubleArray & trunk_rotation,
    const DoubleArray & trunk_angular_velocity, const DoubleArray & trunk_angular_acceleration,
    const DoubleArray & external_wrench, const DoubleArray & K_x, const DoubleArray & D_x,
    const DoubleArray & K_theta, const DoubleArray & D_theta, bool trunk_feedforward)
  {
    require_bound("update");
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
      hi = Map<const VectorXd>(terms_tau_max_, na_) * torque_scale_;
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
  void commanded(const DoubleArray & forces)
  {
    require_bound("commanded");
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

private:
  void require_bound(const char * what) const
  {
    if (!bound_)
      throw std::runtime_error(std::string(what) + ": call bind(arrays) first");
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
  Index nq_ = 0, nv_ = 0, na_ = 0, nc_ = 0;
  int n_legs_ = 0;
  std::vector<int> leg_;
  VectorXd radii_;
  // settings
  bool trunk_feedforward_ = true, posture_on_ = false;
  double control_period_ = 0, mass_ = 0, torque_scale_ = 1, posture_K_ = 0, posture_D_ = 0;
  Vector3d K_x_, D_x_, K_theta_, D_theta_;
  VectorXd torque_cap_, posture_, posture_error_, posture_mask_;
  // per-cycle state
  Eigen::Matrix<double, Eigen::Dynamic, 3> anchors_, slip_;
  std::vector<bool> stance_, was_stance_;
  bool bound_ = false;
  // Python-owned arrays (bind)
  std::vector<py::object> keep_;
  double *terms_q_ = nullptr, *terms_v_ = nullptr, *terms_points_ = nullptr,
         *terms_point_velocities_ = nullptr, *terms_com_ = nullptr, *terms_vcom_ = nullptr,
         *terms_rotation_ = nullptr, *terms_Ig_ = nullptr, *terms_tau_max_ = nullptr;
  double *anchors_out_ = nullptr, *anchor_frames_ = nullptr, *posture_target_ = nullptr;
  double *tau_lo_ = nullptr, *tau_hi_ = nullptr, *wrench_d_ = nullptr, *errors_ = nullptr,
         *commanded_ = nullptr;
};

PYBIND11_MODULE(_passive_references, m)
{
  m.doc() = "PassiveWBC's per-cycle references in compiled code "
            "(wholebody.control.passive.PassiveWBC, engine='native').";
  py::class_<PassiveReferences>(m, "PassiveReferences")
    .def(py::init<const py::dict &>(), py::arg("spec"))
    .def("bind", &PassiveReferences::bind, py::arg("arrays"))
    .def("settings", &PassiveReferences::settings)
    .def("update", &PassiveReferences::update)
    .def("commanded", &PassiveReferences::commanded, py::arg("forces"));
}
