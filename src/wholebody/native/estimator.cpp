// The kinematic-inertial EKF's per-cycle numerics (Bloesch et al. 2013), compiled: a mirror of
// wholebody.estimation.ekf.KinematicInertialEKF (the reference, engine="python") for the rest
// test, the IMU prediction (eqs. 5-11, the ball feet rolling), the legs' kinematic update (eq. 12),
// the stance feet's heights on a known ground, the zero angular-rate update at rest, the
// injection of each correction and the estimate in the free-flyer's conventions. The forward
// kinematics of the measured joints stay in Python (Pinocchio), as do the ground map's queries.
// Eigen only. Python owns the state: ``bind`` takes its arrays by name, each cycle updates them
// in place. Usage (see KinematicInertialEKF._native_cycle):
//   est = Estimator(spec); est.bind(buffers)
//   at_rest = est.predict_correct(dt=, gyro=, accel=, contact=, joint_velocities=, measured=,
//                                 foot_rates=, rest_update=)
//   est.finish(heights=, at_rest=, gyro=, dt=)   # heights: per foot, NaN where not measured
#include "py_arrays.hpp"

#include <Eigen/Dense>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace py = pybind11;

namespace
{
  using Eigen::Index;
  using Eigen::Matrix3d;
  using Eigen::MatrixXd;
  using Eigen::Vector3d;
  using Eigen::VectorXd;
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  using RowMatrix3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
  using Feet = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
  using wholebody_native::DoubleArray;
  using BoolArray = wholebody_native::InputArray<bool>;
  using wholebody_native::get;
  using wholebody_native::input;
  constexpr double kGravity = 9.81; // wholebody.robot.GRAVITY

  Matrix3d skew(const Vector3d & x)
  {
    Matrix3d m;
    m << 0.0, -x[2], x[1], x[2], 0.0, -x[0], -x[1], x[0], 0.0;
    return m;
  }

  // The rotation exp([w]x) (Rodrigues; the series near zero).
  Matrix3d exp3(const Vector3d & w)
  {
    const double t2 = w.squaredNorm();
    const double t = std::sqrt(t2);
    double a, b;
    if (t < 1e-4)
    {
      a = 1.0 - t2 / 6.0;
      b = 0.5 - t2 / 24.0;
    }
    else
    {
      a = std::sin(t) / t;
      b = (1.0 - std::cos(t)) / t2;
    }
    const Matrix3d K = skew(w);
    return Matrix3d::Identity() + a * K + b * K * K;
  }

  Eigen::Map<Vector3d> vec3(double * p) { return Eigen::Map<Vector3d>(p); }

} // namespace

class Estimator
{
public:
  explicit Estimator(const py::dict & spec)
  {
    n_ = Index(get<double>(spec, "n_feet"));
    na_ = Index(get<double>(spec, "n_joints"));
    size_ = 15 + 3 * n_;
    ab_ = 9 + 3 * n_;
    gb_ = 12 + 3 * n_;
    // EstimatorNoise's fields, by name
    noise_ = {get<double>(spec, "gyro_noise"), get<double>(spec, "accel_noise"),
              get<double>(spec, "gyro_bias_walk"), get<double>(spec, "accel_bias_walk"),
              get<double>(spec, "stance_foot_walk"), get<double>(spec, "swing_foot_walk"),
              get<double>(spec, "kinematics_noise"), get<double>(spec, "ground_noise"),
              get<double>(spec, "encoder_noise"), get<double>(spec, "rest_window"),
              get<double>(spec, "rest_gate"), get<double>(spec, "rest_rate_noise")};
    const DoubleArray radii = spec["radii"].cast<DoubleArray>();
    radii_ = Eigen::Map<const VectorXd>(input(radii, n_, "radii", false), n_);
    rolls_ = (radii_.array() > 0.0).any();
    // each point's other point on the same sole (-1: a point foot), as KinematicInertialEKF.partner
    const DoubleArray partner = spec["partner"].cast<DoubleArray>();
    partner_ = Eigen::Map<const VectorXd>(input(partner, n_, "partner", false), n_).cast<Index>();
    const DoubleArray imu = spec["imu_rotation"].cast<DoubleArray>();
    imu_rotation_ = Eigen::Map<const RowMatrix3>(input(imu, 9, "imu_rotation", false));
    const DoubleArray lever = spec["lever_imu"].cast<DoubleArray>();
    lever_ = Eigen::Map<const Vector3d>(input(lever, 3, "lever_imu", false));
    twist_from_imu_.setZero();
    twist_from_imu_.topLeftCorner<3, 3>() = imu_rotation_;
    twist_from_imu_.bottomRightCorner<3, 3>() = imu_rotation_;
    twist_from_imu_.topRightCorner<3, 3>() = imu_rotation_ * skew(lever_);
    A_.resize(9, size_);
    PGt_.resize(size_, 3 * n_);
    S_.resize(3 * n_, 3 * n_);
    work_.resize(size_, size_);
    y_.resize(3 * n_);
    u_.resize(3 * n_);
    dx_.resize(size_);
    column_.resize(size_);
    gain_.resize(size_);
    Wt_.resize(3 * n_, size_);
    llt_ = Eigen::LLT<MatrixXd>(3 * n_);
    skews_.resize(static_cast<std::size_t>(n_));
    blocks_.resize(static_cast<std::size_t>(n_));
  }

  // Python's state arrays, by name (kept alive here; written in place every cycle).
  void bind(const py::dict & b)
  {
    keep_.clear();
    position_ = buffer(b, "position", 3);
    velocity_ = buffer(b, "velocity", 3);
    rotation_ = buffer(b, "rotation", 9);
    feet_ = buffer(b, "feet", 3 * n_);
    accel_bias_ = buffer(b, "accel_bias", 3);
    gyro_bias_ = buffer(b, "gyro_bias", 3);
    P_ = buffer(b, "P", size_ * size_);
    innovation_out_ = buffer(b, "innovation", 3 * n_);
    foot_test_ = buffer(b, "foot_test", n_);
    omega_ = buffer(b, "omega", 3);
    rest_gyro_ = buffer(b, "rest_gyro", 3);
    rest_joints_ = buffer(b, "rest_joints", na_);
    closed_for_ = buffer(b, "closed_for", 1);
    base_ = buffer(b, "base", 7);
    twist_ = buffer(b, "twist", 6);
  }

  // The rest test on this cycle's readings, the prediction over dt and the kinematic update;
  // returns whether the robot is at rest (``rest_update`` off: never). ``skipped`` tells whether
  // the kinematic update was skipped (a singular innovation covariance).
  bool predict_correct(double dt, const DoubleArray & gyro, const DoubleArray & accel,
                       const BoolArray & contact, const DoubleArray & joint_velocities,
                       const DoubleArray & measured, const DoubleArray & foot_rates,
                       bool rest_update)
  {
    if (!P_)
      throw std::runtime_error("predict_correct: call bind(buffers) first");
    const Vector3d w = Eigen::Map<const Vector3d>(input(gyro, 3, "gyro", false));
    const Vector3d f = Eigen::Map<const Vector3d>(input(accel, 3, "accel", false));
    const bool * c = input(contact, n_, "contact", false);
    const Eigen::Map<const VectorXd> qd(input(joint_velocities, na_, "joint_velocities", false), na_);
    const Eigen::Map<const Feet> s(input(measured, 3 * n_, "measured", false), n_, 3);
    const Eigen::Map<const Feet> rates(input(foot_rates, 3 * n_, "foot_rates", false), n_, 3);
    const Vector3d omega = w - vec3(gyro_bias_);
    const bool at_rest = rest_update && detect_rest(w, qd, c, dt);
    predict(omega, f, c, rates, dt);
    skipped_ = !correct(s);
    return at_rest;
  }

  // The stance feet's heights (``heights``: per foot the ground's height under it, NaN where not
  // measured; empty without a ground map), the rest update when ``at_rest``, and the estimate.
  void finish(const DoubleArray & heights, bool at_rest, const DoubleArray & gyro, double dt)
  {
    if (heights.size() > 0)
      correct_ground(input(heights, n_, "heights", false));
    if (at_rest)
      correct_rest(Eigen::Map<const Vector3d>(input(gyro, 3, "gyro", false)), dt);
    output();
  }

  bool skipped() const { return skipped_; }

private:
  double * buffer(const py::dict & b, const char * name, py::ssize_t size)
  {
    return wholebody_native::buffer<double>(b, name, size, keep_);
  }

  Eigen::Map<RowMatrix> P() { return Eigen::Map<RowMatrix>(P_, size_, size_); }
  Eigen::Map<RowMatrix3> R() { return Eigen::Map<RowMatrix3>(rotation_); }
  Eigen::Map<Feet> feet() { return Eigen::Map<Feet>(feet_, n_, 3); }

  // Every contact closed for the window, the averages of the raw gyro (less the bias estimate)
  // and of the joint velocities within rest_gate of their spread at rest.
  bool detect_rest(const Vector3d & gyro, const Eigen::Map<const VectorXd> & qd, const bool * c,
                   double dt)
  {
    const double window = noise_.rest_window;
    const double alpha = 1.0 - std::exp(-dt / window);
    Eigen::Map<Vector3d> mean_gyro(rest_gyro_);
    Eigen::Map<VectorXd> mean_joints(rest_joints_, na_);
    mean_gyro += alpha * (gyro - mean_gyro);
    mean_joints += alpha * (qd - mean_joints);
    const double gyro_noise = noise_.gyro_noise, encoder_noise = noise_.encoder_noise;
    const auto Pm = P();
    const Vector3d off = mean_gyro - vec3(gyro_bias_);
    double gyro_stat = 0.0;
    for (int a = 0; a < 3; ++a)
      gyro_stat += off[a] * off[a]
                   / (gyro_noise * gyro_noise * alpha / (2.0 - alpha) + Pm(gb_ + a, gb_ + a));
    // encoder noise differenced and averaged (telescoping): 2 (e alpha / dt)^2 / (2 - alpha)
    const double joint_variance = 2.0 * std::pow(encoder_noise * alpha / dt, 2) / (2.0 - alpha);
    bool closed = true;
    for (Index i = 0; i < n_; ++i)
      closed = closed && c[i];
    closed_for_[0] = closed ? closed_for_[0] + dt : 0.0;
    const double gate = noise_.rest_gate * noise_.rest_gate;
    return closed_for_[0] >= window && gyro_stat < 3.0 * gate
           && mean_joints.squaredNorm() / joint_variance < double(na_) * gate;
  }

  void predict(const Vector3d & omega, const Vector3d & accel, const bool * c,
               const Eigen::Map<const Feet> & rates, double dt)
  {
    const Matrix3d Rm = R();
    Eigen::Map<Vector3d> r(position_), v(velocity_);
    const Vector3d force = Rm * (accel - vec3(accel_bias_));
    const Vector3d acc = force + Vector3d(0.0, 0.0, -kGravity);
    r += dt * v + 0.5 * dt * dt * acc;
    v += dt * acc;
    if (rolls_)
    {
      auto p = feet();
      for (Index i = 0; i < n_; ++i)
      {
        if (!c[i])
          continue;
        const Vector3d rate = Rm * rates.row(i).transpose();
        const double step = dt * radii_[i];
        p(i, 0) += step * rate[1];
        p(i, 1) -= step * rate[0];
      }
    }
    R() = Rm * exp3(omega * dt);
    vec3(omega_) = omega;
    // F P F^T, F the identity but in the rows of r, v, phi: dr += dt dv,
    // dv += -dt [f]x dphi - dt R db_f, dphi += -dt R db_w
    auto Pm = P();
    const Matrix3d Fv = -dt * skew(force), Fb = -dt * Rm;
    A_.middleRows<3>(0) = Pm.middleRows<3>(0) + dt * Pm.middleRows<3>(3);
    A_.middleRows<3>(3) = Pm.middleRows<3>(3) + Fv * Pm.middleRows<3>(6) + Fb * Pm.middleRows<3>(ab_);
    A_.middleRows<3>(6) = Pm.middleRows<3>(6) + Fb * Pm.middleRows<3>(gb_);
    Pm.topRows<9>() = A_;
    A_.middleRows<3>(0) = (Pm.middleCols<3>(0) + dt * Pm.middleCols<3>(3)).transpose();
    A_.middleRows<3>(3) = (Pm.middleCols<3>(3) + Pm.middleCols<3>(6) * Fv.transpose()
                           + Pm.middleCols<3>(ab_) * Fb.transpose()).transpose();
    A_.middleRows<3>(6) = (Pm.middleCols<3>(6) + Pm.middleCols<3>(gb_) * Fb.transpose()).transpose();
    Pm.leftCols<9>() = A_.transpose();
    const double an = noise_.accel_noise, gn = noise_.gyro_noise;
    const double stance = noise_.stance_foot_walk, swing = noise_.swing_foot_walk;
    for (int k = 0; k < 3; ++k)
    {
      Pm(k, k) += 0.25 * an * an * std::pow(dt, 4);
      Pm(3 + k, 3 + k) += an * an * dt * dt;
      Pm(6 + k, 6 + k) += gn * gn * dt * dt;
      Pm(ab_ + k, ab_ + k) += std::pow(noise_.accel_bias_walk, 2) * dt;
      Pm(gb_ + k, gb_ + k) += std::pow(noise_.gyro_bias_walk, 2) * dt;
    }
    for (Index i = 0; i < n_; ++i)
    {
      const double walk = c[i] ? stance : swing;
      for (int k = 0; k < 3; ++k)
        Pm(9 + 3 * i + k, 9 + 3 * i + k) += walk * walk * dt;
    }
    // a sole's heel and toe walk together along the ground in stance: their horizontal walks'
    // cross-covariance (x and y)
    for (Index i = 0; i < n_; ++i)
    {
      const Index j = partner_[i];
      if (j < 0 || !c[i])
        continue;
      for (int k = 0; k < 2; ++k)
        Pm(9 + 3 * i + k, 9 + 3 * j + k) += stance * stance * dt;
    }
  }

  // Bloesch et al. 2013, eq. 12 in world axes: foot i's rows [-I, 0, [p_i - r]x, .. I ..].
  bool correct(const Eigen::Map<const Feet> & measured)
  {
    const Matrix3d Rm = R();
    const Eigen::Map<Vector3d> r(position_);
    const auto p = feet();
    auto Pm = P();
    VectorXd & y = y_;
    std::vector<Matrix3d> & skews = skews_;
    for (Index i = 0; i < n_; ++i)
    {
      const Vector3d relative = p.row(i).transpose() - r;
      y.segment<3>(3 * i) = Rm * measured.row(i).transpose() - relative;
      skews[std::size_t(i)] = skew(relative);
      // P G_i^T = -P_r + P_phi [rel]x^T + P_foot
      PGt_.middleCols<3>(3 * i) = -Pm.middleCols<3>(0)
                                  - Pm.middleCols<3>(6) * skews[std::size_t(i)]
                                  + Pm.middleCols(9 + 3 * i, 3);
    }
    for (Index i = 0; i < n_; ++i)
      S_.middleRows<3>(3 * i) = -PGt_.middleRows<3>(0).eval()
                                + skews[std::size_t(i)] * PGt_.middleRows<3>(6)
                                + PGt_.middleRows(9 + 3 * i, 3);
    S_.diagonal().array() += std::pow(noise_.kinematics_noise, 2);
    Eigen::LLT<MatrixXd> & llt = llt_.compute(S_);
    if (llt.info() != Eigen::Success)
      return false;
    std::vector<Eigen::LLT<Matrix3d>> & blocks = blocks_;
    for (Index i = 0; i < n_; ++i)
    {
      blocks[std::size_t(i)].compute(S_.block<3, 3>(3 * i, 3 * i));
      if (blocks[std::size_t(i)].info() != Eigen::Success)
        return false;
    }
    // W = P G^T L^-T, u = L^-1 y: dx = W u, P -= W W^T
    MatrixXd & Wt = Wt_;
    Wt = PGt_.transpose();
    llt.matrixL().solveInPlace(Wt);
    VectorXd & u = u_;
    u = y;
    llt.matrixL().solveInPlace(u);
    dx_.noalias() = Wt.transpose() * u;
    inject(dx_);
    work_.noalias() = Wt.transpose() * Wt;
    Pm -= work_;
    symmetrize();
    auto innovation = Eigen::Map<Feet>(innovation_out_, n_, 3);
    for (Index i = 0; i < n_; ++i)
    {
      const Vector3d yi = y.segment<3>(3 * i);
      innovation.row(i) = (Rm.transpose() * yi).transpose();
      foot_test_[i] = yi.dot(blocks[std::size_t(i)].solve(yi));
    }
    return true;
  }

  void correct_ground(const double * heights)
  {
    const double sigma2 = std::pow(noise_.ground_noise, 2);
    for (Index i = 0; i < n_; ++i)
    {
      if (!std::isfinite(heights[i]))
        continue;
      const Index j = 9 + 3 * i + 2;
      auto Pm = P();
      VectorXd & column = column_;
      column = Pm.col(j);
      gain_ = column / (column[j] + sigma2);
      dx_ = gain_ * (heights[i] + radii_[i] - feet()(i, 2));
      inject(dx_);
      Pm.noalias() -= gain_ * column.transpose();
      symmetrize();
    }
  }

  // The zero angular-rate update: gyro = b_w + noise, three rows on b_w; the rate left at rest
  // counted once per rest window.
  void correct_rest(const Eigen::Map<const Vector3d> & gyro, double dt)
  {
    auto Pm = P();
    const MatrixXd columns = Pm.middleCols<3>(gb_);
    const double variance = std::pow(noise_.gyro_noise, 2)
                            + std::pow(noise_.rest_rate_noise, 2) * noise_.rest_window / dt;
    const Matrix3d S = columns.middleRows<3>(gb_) + variance * Matrix3d::Identity();
    const MatrixXd gain = S.partialPivLu().solve(columns.transpose()).transpose();
    inject(gain * (gyro - vec3(gyro_bias_)));
    Pm.noalias() -= gain * columns.transpose();
    symmetrize();
  }

  void inject(const VectorXd & dx)
  {
    vec3(position_) += dx.segment<3>(0);
    vec3(velocity_) += dx.segment<3>(3);
    R() = exp3(dx.segment<3>(6)) * Matrix3d(R());
    Eigen::Map<VectorXd>(feet_, 3 * n_) += dx.segment(9, 3 * n_);
    vec3(accel_bias_) += dx.segment<3>(ab_);
    vec3(gyro_bias_) += dx.segment<3>(gb_);
  }

  void symmetrize()
  {
    auto Pm = P();
    work_ = Pm.transpose();
    Pm = 0.5 * (Pm + work_);
  }

  // The IMU's state carried to the free-flyer: its position and quaternion (x y z w), its twist
  // in the base frame.
  void output()
  {
    const Matrix3d Rm = R();
    vec3(base_) = vec3(position_) - Rm * lever_;
    Eigen::Quaterniond quaternion(Matrix3d(Rm * imu_rotation_.transpose()));
    quaternion.normalize();
    Eigen::Map<Eigen::Vector4d>(base_ + 3) = quaternion.coeffs();
    Eigen::Matrix<double, 6, 1> imu_twist;
    imu_twist << Rm.transpose() * vec3(velocity_), vec3(omega_);
    Eigen::Map<Eigen::Matrix<double, 6, 1>> twist(twist_);
    twist = twist_from_imu_ * imu_twist;
  }

  struct Noise
  {
    double gyro_noise, accel_noise, gyro_bias_walk, accel_bias_walk, stance_foot_walk,
      swing_foot_walk, kinematics_noise, ground_noise, encoder_noise, rest_window, rest_gate,
      rest_rate_noise;
  };

  Index n_ = 0, na_ = 0, size_ = 0, ab_ = 0, gb_ = 0;
  Noise noise_{};
  VectorXd radii_;
  Eigen::Matrix<Index, Eigen::Dynamic, 1> partner_;
  bool rolls_ = false, skipped_ = false;
  Matrix3d imu_rotation_;
  Vector3d lever_;
  Eigen::Matrix<double, 6, 6> twist_from_imu_;
  RowMatrix A_, work_;
  MatrixXd PGt_, S_, Wt_;
  VectorXd y_, u_, dx_, column_, gain_;  // the updates' work vectors, sized once
  Eigen::LLT<MatrixXd> llt_;
  std::vector<Matrix3d> skews_;
  std::vector<Eigen::LLT<Matrix3d>> blocks_;
  std::vector<py::object> keep_;
  double *position_ = nullptr, *velocity_ = nullptr, *rotation_ = nullptr, *feet_ = nullptr,
         *accel_bias_ = nullptr, *gyro_bias_ = nullptr, *P_ = nullptr, *innovation_out_ = nullptr,
         *foot_test_ = nullptr, *omega_ = nullptr, *rest_gyro_ = nullptr, *rest_joints_ = nullptr,
         *closed_for_ = nullptr, *base_ = nullptr, *twist_ = nullptr;
};

PYBIND11_MODULE(_estimator, m)
{
  m.doc() = "The kinematic-inertial EKF's per-cycle numerics (wholebody.estimation), compiled.";
  py::class_<Estimator>(m, "Estimator")
    .def(py::init<const py::dict &>(), py::arg("spec"))
    .def("bind", &Estimator::bind, py::arg("buffers"))
    .def("predict_correct", &Estimator::predict_correct, py::arg("dt"), py::arg("gyro"),
         py::arg("accel"), py::arg("contact"), py::arg("joint_velocities"), py::arg("measured"),
         py::arg("foot_rates"), py::arg("rest_update"))
    .def("finish", &Estimator::finish, py::arg("heights"), py::arg("at_rest"), py::arg("gyro"),
         py::arg("dt"))
    .def_property_readonly("skipped", &Estimator::skipped);
}
