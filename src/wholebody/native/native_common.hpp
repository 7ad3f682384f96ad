// Helpers shared by the compiled cycles (passive_cycle.cpp, hierarchy_cycle.cpp): checked views of
// Python inputs, Python-owned output buffers, spec access, and the Pinocchio model built from the
// Python model's joints and inertias (see wholebody.robot.Robot.native_model_spec).
#pragma once

#include "legged_model.hpp"
#include "py_arrays.hpp"

#include <pinocchio/algorithm/centroidal.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/frames.hpp>
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

namespace wholebody_native
{
  using Eigen::Index;
  using Eigen::Map;
  using Eigen::Matrix3d;
  using Eigen::MatrixXd;
  using Eigen::Vector3d;
  using Eigen::VectorXd;
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using Matrix6x = Eigen::Matrix<double, 6, Eigen::Dynamic>;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  constexpr double kGravity = 9.81; // as wholebody.tasks.wrench.GRAVITY
  constexpr int kEqual = 5, kFree = 0; // DAQP constraint senses

  // The finiteness test of the Python reference (formulation._LevelPlan._valid): the sum of the
  // entries is finite — false for a NaN or an infinity anywhere, and for finite entries whose sum
  // overflows (rows no QP can use). One vectorised pass, cheaper than Eigen's allFinite().
  template <typename Derived>
  inline bool sum_is_finite(const Eigen::DenseBase<Derived> & x)
  {
    return std::isfinite(x.sum());
  }

  // input() for a state vector: also refuses arrays of another shape with that many values.
  inline const double * vector_input(const DoubleArray & a, py::ssize_t size, const char * field)
  {
    if (a.ndim() != 1)
      throw std::invalid_argument(
        std::string(field) + ": expected a vector of size " + std::to_string(size) + ", got shape "
        + shape_of(a));
    return input(a, size, field);
  }

  inline VectorXd get_vector(const py::dict & spec, const char * key, Index size)
  {
    DoubleArray a = get<DoubleArray>(spec, key);
    const double * p = input(a, size, key, false);
    return Map<const VectorXd>(p, size);
  }

  inline pinocchio::SE3 placement_from(const double * h)
  {
    Eigen::Matrix<double, 4, 4, Eigen::RowMajor> m = Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(h);
    return pinocchio::SE3(m.topLeftCorner<3, 3>(), m.topRightCorner<3, 1>());
  }

  // Unit normal and two unit tangents (t1, t2, n right-handed), as wholebody.tasks.contact.tangent_basis.
  inline void tangent_basis(const Vector3d & normal, Vector3d & t1, Vector3d & t2, Vector3d & n)
  {
    n = normal / normal.norm();
    const Vector3d helper = std::abs(n[0]) < 0.9 ? Vector3d::UnitX() : Vector3d::UnitY();
    t1 = helper.cross(n);
    t1 /= t1.norm();
    t2 = n.cross(t1);
  }

  // The 2 x 3 rows t_k − r_k n that vanish on a force leaning like lean, as
  // wholebody.tasks.contact.tangent_rows (r the lean's tangential-to-normal ratios, at most mu;
  // r = 0 when the lean does not press into the surface).
  inline Eigen::Matrix<double, 2, 3> tangent_rows(const Vector3d & normal, const Vector3d & lean,
                                                   double mu)
  {
    Vector3d t1, t2, n;
    tangent_basis(normal, t1, t2, n);
    Eigen::Matrix<double, 2, 3> rows;
    rows.row(0) = t1.transpose();
    rows.row(1) = t2.transpose();
    const double pressing = n.dot(lean);
    if (!(pressing > 0.0))
      return rows;
    Eigen::Vector2d ratio = rows * lean / pressing;
    const double size = std::hypot(ratio[0], ratio[1]);
    if (size > mu)
      ratio *= mu / size;
    return rows - ratio * n.transpose();
  }

  // Adds the joints and bodies of spec (keys parents, kinds, axes, placements, masses, levers,
  // inertias: the Python model's joints 1..njoints-1) to an empty model, and its armature.
  inline void add_joints(const py::dict & spec, wholebody::LeggedModel & model)
  {
    auto parents = get<std::vector<int>>(spec, "parents");
    auto kinds = get<std::vector<std::string>>(spec, "kinds");
    const py::ssize_t nj = py::ssize_t(parents.size());
    if (py::ssize_t(kinds.size()) != nj)
      throw std::invalid_argument("spec: 'kinds' and 'parents' differ in length");
    DoubleArray placements = get<DoubleArray>(spec, "placements");
    DoubleArray masses = get<DoubleArray>(spec, "masses");
    DoubleArray levers = get<DoubleArray>(spec, "levers");
    DoubleArray inertias = get<DoubleArray>(spec, "inertias");
    DoubleArray axes = get<DoubleArray>(spec, "axes");
    const double * pl = input(placements, 16 * nj, "placements");
    const double * ms = input(masses, nj, "masses");
    const double * lv = input(levers, 3 * nj, "levers");
    const double * in = input(inertias, 9 * nj, "inertias");
    const double * ax = input(axes, 3 * nj, "axes");
    for (py::ssize_t k = 0; k < nj; ++k)
    {
      const pinocchio::SE3 placement = placement_from(pl + 16 * k);
      const std::string name = "joint" + std::to_string(k + 1);
      const auto parent = pinocchio::JointIndex(parents[k]);
      const std::string & kind = kinds[k];
      pinocchio::JointIndex id;
      if (kind == "JointModelFreeFlyer")
        id = model.addJoint(parent, pinocchio::JointModelFreeFlyer(), placement, name);
      else if (kind == "JointModelRX")
        id = model.addJoint(parent, pinocchio::JointModelRX(), placement, name);
      else if (kind == "JointModelRY")
        id = model.addJoint(parent, pinocchio::JointModelRY(), placement, name);
      else if (kind == "JointModelRZ")
        id = model.addJoint(parent, pinocchio::JointModelRZ(), placement, name);
      else if (kind == "JointModelPX")
        id = model.addJoint(parent, pinocchio::JointModelPX(), placement, name);
      else if (kind == "JointModelPY")
        id = model.addJoint(parent, pinocchio::JointModelPY(), placement, name);
      else if (kind == "JointModelPZ")
        id = model.addJoint(parent, pinocchio::JointModelPZ(), placement, name);
      else if (kind == "JointModelRevoluteUnaligned")
        id = model.addJoint(
          parent, pinocchio::JointModelRevoluteUnaligned(Map<const Vector3d>(ax + 3 * k)), placement,
          name);
      else if (kind == "JointModelRUBX")
        id = model.addJoint(parent, pinocchio::JointModelRUBX(), placement, name);
      else if (kind == "JointModelRUBY")
        id = model.addJoint(parent, pinocchio::JointModelRUBY(), placement, name);
      else if (kind == "JointModelRUBZ")
        id = model.addJoint(parent, pinocchio::JointModelRUBZ(), placement, name);
      else if (kind == "JointModelRevoluteUnboundedUnaligned")
        id = model.addJoint(
          parent, pinocchio::JointModelRevoluteUnboundedUnaligned(Map<const Vector3d>(ax + 3 * k)),
          placement, name);
      else if (kind == "JointModelPrismaticUnaligned")
        id = model.addJoint(
          parent, pinocchio::JointModelPrismaticUnaligned(Map<const Vector3d>(ax + 3 * k)), placement,
          name);
      else
        throw std::invalid_argument(
          "spec: joint " + std::to_string(k + 1) + " is a " + kind
          + "; the native cycle supports the free flyer and 1-DoF revolute (bounded or continuous) "
            "and prismatic joints (about any fixed axis)");
      const Matrix3d I = Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(in + 9 * k);
      model.appendBodyToJoint(
        id, pinocchio::Inertia(ms[k], Map<const Vector3d>(lv + 3 * k), I), pinocchio::SE3::Identity());
    }
    if (model.njoints < 2 || model.joints[1].nv() != 6)
      throw std::invalid_argument("spec: the root joint must be a free flyer");
    model.armature = get_vector(spec, "armature", model.nv);
  }

  // The actuated joints' angles (Robot.joint_angles): q[idx_q] of a one-coordinate joint,
  // atan2(sin, cos) of a continuous joint's (cos, sin) pair.
  struct JointAngles
  {
    std::vector<Index> idx_q;
    std::vector<bool> continuous;

    explicit JointAngles(const wholebody::LeggedModel & model)
    {
      for (int j = 2; j < model.njoints; ++j)
      {
        idx_q.push_back(model.joints[j].idx_q());
        continuous.push_back(model.joints[j].nq() == 2);
      }
    }
    JointAngles() = default;

    void operator()(const VectorXd & q, VectorXd & angles) const
    {
      angles.resize(Index(idx_q.size()));
      for (std::size_t j = 0; j < idx_q.size(); ++j)
        angles[Index(j)] = continuous[j] ? std::atan2(q[idx_q[j] + 1], q[idx_q[j]]) : q[idx_q[j]];
    }
  };

  // tau_max(q) of the actuated joints (wholebody.robots.torque_limits.TorqueProfile.upper without
  // its scale): the constant bound, replaced on the joints with a linkage profile
  // [a, b, force, q_peak] (Fahmi et al. 2019, eq. 15) evaluated at the joint positions.
  struct TorqueProfile
  {
    VectorXd constant;
    std::vector<int> rows;
    RowMatrix linkage; // one row [a, b, force, q_peak] per entry of rows

    // From spec keys torque_constant, linkage_rows, linkage_params (TorqueLimits.linkage).
    static TorqueProfile from_spec(const py::dict & spec, Index na)
    {
      TorqueProfile t;
      t.constant = get_vector(spec, "torque_constant", na);
      t.rows = get<std::vector<int>>(spec, "linkage_rows");
      const Index k = Index(t.rows.size());
      DoubleArray params = get<DoubleArray>(spec, "linkage_params");
      t.linkage = Map<const RowMatrix>(input(params, 4 * k, "linkage_params"), k, 4);
      for (int row : t.rows)
        if (row < 0 || row >= na)
          throw std::invalid_argument("linkage_rows: joint index out of range");
      return t;
    }

    template<typename Out>
    void upper(const Eigen::Ref<const VectorXd> & q_joints, Out && hi) const
    {
      hi = constant;
      for (std::size_t k = 0; k < rows.size(); ++k)
      {
        const int j = rows[k];
        const double a = linkage(Index(k), 0), b = linkage(Index(k), 1);
        const double force = linkage(Index(k), 2), q_peak = linkage(Index(k), 3);
        const double t = q_joints[j] + (M_PI / 2 - q_peak); // TorqueProfile's _angle_offset
        hi[j] = force * a * b * std::abs(std::sin(t)) / std::sqrt(a * a + b * b - 2.0 * a * b * std::cos(t));
      }
    }
  };

  // Robot.update's Pinocchio pass: q and v checked (size, shape, NaN/inf, unit base quaternion;
  // ValueError naming the field) and copied, then computeAllTerms, the frame placements and
  // the centroidal momentum's rate at zero acceleration Ȧ_G v (returned); M made symmetric.
  inline Eigen::Matrix<double, 6, 1> rigid_body_pass(
    const wholebody::LeggedModel & model, wholebody::LeggedData & data, const DoubleArray & q_in,
    const DoubleArray & v_in, VectorXd & q, VectorXd & v)
  {
    const double * qp = vector_input(q_in, model.nq, "q");
    const double * vp = vector_input(v_in, model.nv, "v");
    const double quat_norm = Map<const VectorXd>(qp + 3, 4).norm();
    if (std::abs(quat_norm - 1.0) > 1e-3)
      throw std::invalid_argument(
        "q: base quaternion q[3:7] must be unit, has norm " + std::to_string(quat_norm));
    q = Map<const VectorXd>(qp, model.nq);
    v = Map<const VectorXd>(vp, model.nv);
    pinocchio::computeAllTerms(model, data, q, v);
    pinocchio::updateFramePlacements(model, data);
    const Eigen::Matrix<double, 6, 1> dh =
      pinocchio::computeCentroidalMomentumTimeVariation(model, data).toVector();
    data.M.triangularView<Eigen::StrictlyLower>() =
      data.M.transpose().triangularView<Eigen::StrictlyLower>();
    return dh;
  }

  // Copies of the pass's terms that Robot.update caches (for tests against it).
  inline py::dict rigid_body_terms(const wholebody::LeggedData & data)
  {
    py::dict d;
    d["M"] = MatrixXd(data.M);
    d["h"] = VectorXd(data.nle);
    d["com"] = Vector3d(data.com[0]);
    d["vcom"] = Vector3d(data.vcom[0]);
    d["h_G"] = Eigen::Matrix<double, 6, 1>(data.hg.toVector());
    return d;
  }

  // The material point under a foot sphere's centre, d = (0, 0, -r) in world axes
  // (Robot._contact_jacobian / _contact_drift): its Jacobian J_p = J_lin - [d]x J_ang and drift
  // a_f + α x d + ω x (ω x d) at velocity v, from the frame's 6D Jacobian J6 and classical
  // acceleration (linear a_f, angular α; LOCAL_WORLD_ALIGNED).
  template<typename JOut, typename AOut>
  void sphere_point(const Matrix6x & J6, const Vector3d & a_f, const Vector3d & alpha,
                    const VectorXd & v, double r, JOut && Jp, AOut && a)
  {
    Jp = J6.topRows<3>();
    Jp.row(0) -= r * J6.row(4);
    Jp.row(1) += r * J6.row(3);
    const Vector3d w = J6.bottomRows<3>() * v;
    a = a_f;
    a[0] -= r * (alpha[1] + w[0] * w[2]);
    a[1] += r * (alpha[0] - w[1] * w[2]);
    a[2] += r * (w[0] * w[0] + w[1] * w[1]);
  }
} // namespace wholebody_native
