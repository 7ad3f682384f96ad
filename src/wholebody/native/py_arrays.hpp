// Checked views of Python arrays, Python-owned buffers and spec access, shared by every compiled
// extension that takes arrays from Python (pybind11 and the standard library only: the Eigen-only
// estimator includes it as the Pinocchio cycles do, through native_common.hpp).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace py = pybind11;

namespace wholebody_native
{
  template<typename T>
  using InputArray = py::array_t<T, py::array::c_style | py::array::forcecast>;
  using DoubleArray = InputArray<double>;

  inline std::string shape_of(const py::array & a)
  {
    std::string s = "(";
    for (py::ssize_t i = 0; i < a.ndim(); ++i)
      s += (i ? ", " : "") + std::to_string(a.shape(i));
    return s + (a.ndim() == 1 ? ",)" : ")");
  }

  // A read-only view of an input of exactly ``size`` values; ValueError naming ``field``; with
  // ``finite`` (a floating type only) also one that holds NaN or inf.
  template<typename T>
  const T * input(const InputArray<T> & a, py::ssize_t size, const char * field,
                  bool finite = std::is_floating_point<T>::value)
  {
    if (a.size() != size)
      throw std::invalid_argument(
        std::string(field) + ": expected " + std::to_string(size) + " values, got shape "
        + shape_of(a));
    const T * p = a.data();
    if constexpr (std::is_floating_point<T>::value)
      if (finite)
        for (py::ssize_t i = 0; i < size; ++i)
          if (!std::isfinite(p[i]))
            throw std::invalid_argument(
              std::string(field) + ": contains NaN or inf at index " + std::to_string(i));
    return p;
  }

  // A writable, C-contiguous buffer owned by Python, kept alive by the holder.
  template<typename T>
  T * buffer(const py::dict & buffers, const char * name, py::ssize_t size, std::vector<py::object> & keep)
  {
    if (!buffers.contains(name))
      throw std::invalid_argument(std::string("bind: missing buffer '") + name + "'");
    py::object obj = buffers[name];
    if (!py::isinstance<py::array_t<T>>(obj))
      throw std::invalid_argument(std::string("bind: buffer '") + name + "' has the wrong dtype");
    auto arr = py::reinterpret_borrow<py::array_t<T>>(obj);
    if (arr.size() != size || !(arr.flags() & py::array::c_style) || !arr.writeable())
      throw std::invalid_argument(
        std::string("bind: buffer '") + name + "' must be a writable C-contiguous array of "
        + std::to_string(size) + " values, got shape " + shape_of(arr));
    keep.push_back(obj);
    return arr.mutable_data();
  }

  template<typename T>
  T get(const py::dict & spec, const char * key)
  {
    if (!spec.contains(key))
      throw std::invalid_argument(std::string("spec: missing key '") + key + "'");
    return spec[key].cast<T>();
  }
} // namespace wholebody_native
