// What the simulator reads from MuJoCo every step, compiled; each function mirrors a Python
// reference with the same operations in the same order, every result bitwise the same (built
// with -ffp-contract=off, so that no multiply-add is fused). The arrays are MuJoCo's own views
// (strided: a field of its contact structs), read in place. Usage:
//   contact_wrenches(con.geom, con.efc_address, con.dim, con.frame, con.pos, d.efc_force,
//                    d.site_xpos, owner, sites) -> (len(sites), 6)
//       reference: wholebody.sim.simulator.Simulator._contact_wrenches_reference
//   mj_to_pin(qpos, qvel) -> (q, v)
//       reference: wholebody.sim.convert.mj_to_pin
//   beyond_limits(qpos, addresses, lower, upper) -> bool
//       reference: wholebody.sim.incidents.IncidentLog._beyond_limits
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace py = pybind11;

namespace
{
  template<typename T>
  using Strided = py::array_t<T, py::array::forcecast>;

  void check(bool ok, const std::string & what, const char * function = "contact_wrenches")
  {
    if (!ok)
      throw std::invalid_argument(std::string(function) + ": " + what);
  }

  // Force on the robot and torque about each contact frame's origin (world axes), summed over
  // MuJoCo's contacts of each robot contact's geoms: ``geom`` (ncon, 2) the contact's geoms,
  // ``efc_address`` (ncon,) its first row in ``efc_force`` (< 0: excluded), ``dim`` its condim,
  // ``frame`` (ncon, 9) its frame's axes as rows (normal first), ``pos`` (ncon, 3) its point;
  // ``owner`` (ngeom,) the robot contact a geom belongs to (-1: none), ``sites`` the contacts'
  // frame sites in ``site_xpos``. geom1 the robot's: the force on it is minus MuJoCo's.
  py::array_t<double> contact_wrenches(const Strided<std::int32_t> & geom,
                                       const Strided<std::int32_t> & efc_address,
                                       const Strided<std::int32_t> & dim,
                                       const Strided<double> & frame, const Strided<double> & pos,
                                       const Strided<double> & efc_force,
                                       const Strided<double> & site_xpos,
                                       const Strided<std::int64_t> & owner,
                                       const Strided<std::int64_t> & sites)
  {
    check(geom.ndim() == 2 && geom.shape(1) == 2, "geom: expected shape (ncon, 2)");
    const py::ssize_t n = geom.shape(0);
    check(efc_address.ndim() == 1 && efc_address.shape(0) == n, "efc_address: expected (ncon,)");
    check(dim.ndim() == 1 && dim.shape(0) == n, "dim: expected (ncon,)");
    check(frame.ndim() == 2 && frame.shape(0) == n && frame.shape(1) == 9,
          "frame: expected (ncon, 9)");
    check(pos.ndim() == 2 && pos.shape(0) == n && pos.shape(1) == 3, "pos: expected (ncon, 3)");
    check(efc_force.ndim() == 1, "efc_force: expected a vector");
    check(site_xpos.ndim() == 2 && site_xpos.shape(1) == 3, "site_xpos: expected (nsite, 3)");
    check(owner.ndim() == 1 && sites.ndim() == 1, "owner, sites: expected vectors");
    const py::ssize_t nc = sites.shape(0), nefc = efc_force.shape(0), ngeom = owner.shape(0);
    py::array_t<double> result({nc, py::ssize_t(6)});
    auto out = result.mutable_unchecked<2>();
    for (py::ssize_t j = 0; j < nc; ++j)
      for (py::ssize_t c = 0; c < 6; ++c)
        out(j, c) = 0.0;
    const auto g = geom.unchecked<2>();
    const auto address = efc_address.unchecked<1>();
    const auto condim = dim.unchecked<1>();
    const auto r = frame.unchecked<2>();
    const auto p = pos.unchecked<2>();
    const auto efc = efc_force.unchecked<1>();
    const auto xpos = site_xpos.unchecked<2>();
    const auto own = owner.unchecked<1>();
    const auto site = sites.unchecked<1>();
    for (py::ssize_t k = 0; k < n; ++k)
    {
      const std::int64_t g1 = g(k, 0), g2 = g(k, 1);
      check(g1 >= 0 && g1 < ngeom && g2 >= 0 && g2 < ngeom, "geom: an index out of range");
      std::int64_t j = own(g1);
      double sign = -1.0;
      if (j < 0)
      {
        j = own(g2);
        sign = 1.0;
      }
      const std::int64_t a = address(k);
      if (j < 0 || a < 0) // not a robot contact, or excluded (no force)
        continue;
      check(j < nc, "owner: a contact index out of range");
      const bool three = condim(k) >= 3;
      check(a + (three ? 2 : 0) < nefc, "efc_address: a row out of range");
      const double f0 = efc(a), f1 = three ? efc(a + 1) : 0.0, f2 = three ? efc(a + 2) : 0.0;
      const double fx = sign * (f0 * r(k, 0) + f1 * r(k, 3) + f2 * r(k, 6));
      const double fy = sign * (f0 * r(k, 1) + f1 * r(k, 4) + f2 * r(k, 7));
      const double fz = sign * (f0 * r(k, 2) + f1 * r(k, 5) + f2 * r(k, 8));
      const std::int64_t s = site(j);
      check(s >= 0 && s < xpos.shape(0), "sites: an index out of range");
      const double lx = p(k, 0) - xpos(s, 0), ly = p(k, 1) - xpos(s, 1), lz = p(k, 2) - xpos(s, 2);
      out(j, 0) += fx;
      out(j, 1) += fy;
      out(j, 2) += fz;
      out(j, 3) += ly * fz - lz * fy;
      out(j, 4) += lz * fx - lx * fz;
      out(j, 5) += lx * fy - ly * fx;
    }
    return result;
  }

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
  m.def("contact_wrenches", &contact_wrenches, py::arg("geom"), py::arg("efc_address"),
        py::arg("dim"), py::arg("frame"), py::arg("pos"), py::arg("efc_force"),
        py::arg("site_xpos"), py::arg("owner"), py::arg("sites"));
  m.def("mj_to_pin", &mj_to_pin, py::arg("qpos"), py::arg("qvel"));
  m.def("beyond_limits", &beyond_limits, py::arg("qpos"), py::arg("addresses"), py::arg("lower"),
        py::arg("upper"));
}
