// What the simulator reads from MuJoCo every step, compiled; each function mirrors a Python
// reference with the same operations in the same order, every result bitwise the same (built
// with -ffp-contract=off, so that no multiply-add is fused). Usage:
//   contact_wrenches_at(model._address, data._address, owner, sites) -> (len(sites), 6)
//       (built where MuJoCo's headers were found: WHOLEBODY_MUJOCO_HEADERS; mujoco_version)
//       reference: wholebody.sim.simulator.Simulator._contact_wrenches_reference
//   mj_to_pin(qpos, qvel) -> (q, v)
//       reference: wholebody.sim.convert.mj_to_pin
//   beyond_limits(qpos, addresses, lower, upper) -> bool
//       reference: wholebody.sim.incidents.IncidentLog._beyond_limits
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#ifdef WHOLEBODY_MUJOCO_HEADERS
#include <mujoco/mujoco.h>
#endif

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace py = pybind11;

namespace
{
  template<typename T>
  using Strided = py::array_t<T, py::array::forcecast>;

  void check(bool ok, const std::string & what, const char * function)
  {
    if (!ok)
      throw std::invalid_argument(std::string(function) + ": " + what);
  }

#ifdef WHOLEBODY_MUJOCO_HEADERS
  // Force on the robot and torque about each contact frame's origin (world axes), summed over
  // MuJoCo's contacts of each robot contact's geoms, read from MuJoCo's own structs: the mjModel
  // and mjData at the addresses its Python bindings give (``_address``), no numpy view of their
  // fields made. ``owner`` (ngeom,): the robot contact a geom belongs to (-1: none); ``sites``:
  // the contacts' frame sites. geom[0] the robot's: the force on it is minus MuJoCo's. Only for
  // the MuJoCo whose headers this was built with (``mujoco_version``, which the caller compares
  // with ``mujoco.mj_version()``).
  py::array_t<double> contact_wrenches_at(std::uintptr_t model_address,
                                          std::uintptr_t data_address,
                                          const Strided<std::int64_t> & owner,
                                          const Strided<std::int64_t> & sites)
  {
    const char * f = "contact_wrenches_at";
    check(model_address != 0 && data_address != 0, "null model or data", f);
    const mjModel * m = reinterpret_cast<const mjModel *>(model_address);
    const mjData * d = reinterpret_cast<const mjData *>(data_address);
    check(owner.ndim() == 1 && owner.shape(0) == py::ssize_t(m->ngeom),
          "owner: expected one entry per geom of the model", f);
    check(sites.ndim() == 1, "sites: expected a vector", f);
    const py::ssize_t nc = sites.shape(0);
    py::array_t<double> result({nc, py::ssize_t(6)});
    auto out = result.mutable_unchecked<2>();
    for (py::ssize_t j = 0; j < nc; ++j)
      for (py::ssize_t c = 0; c < 6; ++c)
        out(j, c) = 0.0;
    const auto own = owner.unchecked<1>();
    const auto site = sites.unchecked<1>();
    const std::int64_t ngeom = m->ngeom, nsite = m->nsite, nefc = d->nefc;
    for (int k = 0; k < d->ncon; ++k)
    {
      const mjContact & con = d->contact[k];
      const std::int64_t g1 = con.geom[0], g2 = con.geom[1];
      if (g1 < 0 || g2 < 0) // a flex contact: no robot geom
        continue;
      check(g1 < ngeom && g2 < ngeom, "a contact's geom out of range", f);
      std::int64_t j = own(g1);
      double sign = -1.0;
      if (j < 0)
      {
        j = own(g2);
        sign = 1.0;
      }
      const std::int64_t a = con.efc_address;
      if (j < 0 || a < 0) // not a robot contact, or excluded (no force)
        continue;
      check(j < nc, "owner: a contact index out of range", f);
      const bool three = con.dim >= 3;
      check(a + (three ? 2 : 0) < nefc, "a contact's efc_address out of range", f);
      const double * efc = d->efc_force;
      const double f0 = efc[a], f1 = three ? efc[a + 1] : 0.0, f2 = three ? efc[a + 2] : 0.0;
      const double * r = con.frame;
      const double fx = sign * (f0 * r[0] + f1 * r[3] + f2 * r[6]);
      const double fy = sign * (f0 * r[1] + f1 * r[4] + f2 * r[7]);
      const double fz = sign * (f0 * r[2] + f1 * r[5] + f2 * r[8]);
      const std::int64_t s = site(j);
      check(s >= 0 && s < nsite, "sites: an index out of range", f);
      const double * o = d->site_xpos + 3 * s;
      const double * p = con.pos;
      const double lx = p[0] - o[0], ly = p[1] - o[1], lz = p[2] - o[2];
      out(j, 0) += fx;
      out(j, 1) += fy;
      out(j, 2) += fz;
      out(j, 3) += ly * fz - lz * fy;
      out(j, 4) += lz * fx - lx * fz;
      out(j, 5) += lx * fy - ly * fx;
    }
    return result;
  }
#endif

  // (q, v) in Pinocchio's convention from MuJoCo's (qpos, qvel) of a free-floating base: the
  // quaternion (w, x, y, z) -> (x, y, z, w) normalised by sqrt(x x + y y + z z + w w), the linear
  // velocity turned to the base frame by R(q)^T of the quaternion normalised once more.
  py::tuple mj_to_pin(const Strided<double> & qpos, const Strided<double> & qvel)
  {
    const char * f = "mj_to_pin";
    check(qpos.ndim() == 1 && qpos.shape(0) >= 7, "qpos: expected a vector of >= 7", f);
    check(qvel.ndim() == 1 && qvel.shape(0) >= 6, "qvel: expected a vector of >= 6", f);
    const py::ssize_t nq = qpos.shape(0), nv = qvel.shape(0);
    py::array_t<double> q_out(nq), v_out(nv);
    auto q = q_out.mutable_unchecked<1>();
    auto v = v_out.mutable_unchecked<1>();
    const auto qp = qpos.unchecked<1>();
    const auto qv = qvel.unchecked<1>();
    for (py::ssize_t i = 0; i < nq; ++i)
      q(i) = qp(i);
    for (py::ssize_t i = 0; i < nv; ++i)
      v(i) = qv(i);
    double w = q(3), x = q(4), y = q(5), z = q(6);
    double norm = std::sqrt(x * x + y * y + z * z + w * w);
    x = x / norm, y = y / norm, z = z / norm, w = w / norm;
    q(3) = x, q(4) = y, q(5) = z, q(6) = w;
    norm = std::sqrt(x * x + y * y + z * z + w * w);
    x = x / norm, y = y / norm, z = z / norm, w = w / norm;
    const double a = v(0), b = v(1), c = v(2);
    v(0) = (1.0 - 2.0 * (y * y + z * z)) * a + 2.0 * (x * y + z * w) * b + 2.0 * (x * z - y * w) * c;
    v(1) = 2.0 * (x * y - z * w) * a + (1.0 - 2.0 * (x * x + z * z)) * b + 2.0 * (y * z + x * w) * c;
    v(2) = 2.0 * (x * z + y * w) * a + 2.0 * (y * z - x * w) * b + (1.0 - 2.0 * (x * x + y * y)) * c;
    return py::make_tuple(q_out, v_out);
  }

  // True when some qpos[addresses[k]] <= lower[k] or >= upper[k] (a NaN is on no limit).
  bool beyond_limits(const Strided<double> & qpos, const Strided<std::int64_t> & addresses,
                     const Strided<double> & lower, const Strided<double> & upper)
  {
    const char * f = "beyond_limits";
    check(qpos.ndim() == 1 && addresses.ndim() == 1 && lower.ndim() == 1 && upper.ndim() == 1,
          "expected vectors", f);
    const py::ssize_t n = addresses.shape(0), nq = qpos.shape(0);
    check(lower.shape(0) == n && upper.shape(0) == n, "lower, upper: expected one per address", f);
    const auto qp = qpos.unchecked<1>();
    const auto at = addresses.unchecked<1>();
    const auto lo = lower.unchecked<1>();
    const auto hi = upper.unchecked<1>();
    for (py::ssize_t k = 0; k < n; ++k)
    {
      const std::int64_t a = at(k);
      check(a >= 0 && a < nq, "addresses: an index out of range", f);
      if (qp(a) <= lo(k) || qp(a) >= hi(k))
        return true;
    }
    return false;
  }
} // namespace

PYBIND11_MODULE(_sim_reads, m)
{
  m.doc() = "What wholebody.sim.simulator reads from MuJoCo every step, compiled.";
#ifdef WHOLEBODY_MUJOCO_HEADERS
  m.def("contact_wrenches_at", &contact_wrenches_at, py::arg("model_address"),
        py::arg("data_address"), py::arg("owner"), py::arg("sites"));
  m.attr("mujoco_version") = int(mjVERSION_HEADER);
#endif
  m.def("mj_to_pin", &mj_to_pin, py::arg("qpos"), py::arg("qvel"));
  m.def("beyond_limits", &beyond_limits, py::arg("qpos"), py::arg("addresses"), py::arg("lower"),
        py::arg("upper"));
}
