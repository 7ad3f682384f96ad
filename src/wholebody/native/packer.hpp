// The per-cycle copy of task parameters into a program's arrays (wholebody.cycle), compiled.
//
// A source is one parameter (or a task's weight) as wholebody.tasks.schema declares it: where its
// value comes from (the task's attribute, an attribute path through objects the task holds — a
// tuple of names —, or a ``get(task, layout, state)`` function), the view
// of the program array it goes to, its form, and ``assign(value)``: the Python function that
// writes a value of any other kind (and names the task's field when it cannot). The common values
// — a Python or numpy float or int, a float64 array of exactly the view's entries (for a matrix:
// C-contiguous, any shape), or of one entry — are written here; everything else goes through
// ``assign``, so the Python writers stay the reference for what a value means. A matrix also
// takes a Fortran-order 2-D array (a rotation from Pinocchio), written in C order. A per-contact
// source with a ``mapping`` (wholebody.tasks.schema.Param.mapping) is read from the task's dict
// (contact name -> k values) here, the layout's contacts' entries stacked; where it cannot be
// (a missing entry without a default, an entry of another kind, not a dict) its ``get`` decides.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

namespace wholebody_native
{
  namespace py = pybind11;

  class ParameterPacker
  {
  public:
    enum class Form { Vector, Diagonal, Matrix, Flag };

    explicit ParameterPacker(const py::list & sources)
    {
      for (const py::handle item : sources)
      {
        auto t = py::reinterpret_borrow<py::tuple>(item);
        if (t.size() != 9)
          throw std::invalid_argument("ParameterPacker: a source is (task, name, get, layout, "
                                      "state, view, form, assign, mapping)");
        Source s;
        s.task = t[0];
        s.name = t[1];
        if (py::isinstance<py::tuple>(s.name))
        {
          for (const py::handle part : s.name)
          {
            if (!py::isinstance<py::str>(part))
              throw std::invalid_argument("ParameterPacker: an attribute path is a tuple of names");
            s.path.push_back(py::reinterpret_borrow<py::object>(part));
          }
          if (s.path.empty())
            throw std::invalid_argument("ParameterPacker: an attribute path is a tuple of names");
        }
        s.get = t[2];
        s.layout = t[3];
        s.state = t[4];
        s.assign = t[7];
        py::object view = t[5];
        if (!py::isinstance<py::array_t<double>>(view))
          throw std::invalid_argument("ParameterPacker: a view must be a float64 array");
        auto arr = py::reinterpret_borrow<py::array_t<double>>(view);
        if (arr.ndim() != 1 || !(arr.flags() & py::array::c_style) || !arr.writeable())
          throw std::invalid_argument("ParameterPacker: a view must be a writable contiguous vector");
        s.view = view;
        s.data = arr.mutable_data();
        s.size = arr.size();
        const std::string form = t[6].cast<std::string>();
        if (form == "vector")
          s.form = Form::Vector;
        else if (form == "diagonal")
          s.form = Form::Diagonal;
        else if (form == "matrix")
          s.form = Form::Matrix;
        else if (form == "flag")
          s.form = Form::Flag;
        else
          throw std::invalid_argument("ParameterPacker: unknown form '" + form + "'");
        if (s.get.is_none() == s.name.is_none())
          throw std::invalid_argument("ParameterPacker: a source has a name or a get, not both");
        if (!t[8].is_none())
          take_mapping(s, t[8]);
        sources_.push_back(std::move(s));
      }
    }

    // Every source's current value into its view (Python errors, e.g. assign's, propagate).
    void pack()
    {
      for (Source & s : sources_)
      {
        if (s.mapped && write_mapping(s))
          continue;
        PyObject * value = !s.get.is_none()  ? call_get(s)
                           : s.path.empty() ? PyObject_GetAttr(s.task.ptr(), s.name.ptr())
                                            : get_path(s);
        if (value == nullptr)
          throw py::error_already_set();
        py::object owned = py::reinterpret_steal<py::object>(value);
        if (!write(s, value))
          s.assign(owned);
      }
    }

    py::ssize_t size() const { return static_cast<py::ssize_t>(sources_.size()); }

  private:
    struct Source
    {
      py::object task, name, get, layout, state, view, assign;
      std::vector<py::object> path; // an attribute path's names (empty: ``name`` itself)
      double * data = nullptr;
      py::ssize_t size = 0;
      Form form = Form::Vector;
      // a mapping source: the task's attribute, the keys in order, entries per key, the default
      bool mapped = false;
      py::object map_name;
      std::vector<py::object> keys;
      py::ssize_t per_key = 0;
      std::vector<double> fallback; // the default entry (empty: none)
    };

    // (attribute, keys, k, default or None) of a mapping source (Param.source).
    static void take_mapping(Source & s, const py::handle spec)
    {
      auto t = py::reinterpret_borrow<py::tuple>(spec);
      if (t.size() != 4 || s.get.is_none() || s.form != Form::Vector)
        throw std::invalid_argument("ParameterPacker: a mapping is (attribute, keys, k, default) "
                                    "of a vector source with a get");
      s.mapped = true;
      s.map_name = t[0];
      for (const py::handle key : t[1])
        s.keys.push_back(py::reinterpret_borrow<py::object>(key));
      s.per_key = t[2].cast<py::ssize_t>();
      if (s.per_key * static_cast<py::ssize_t>(s.keys.size()) != s.size)
        throw std::invalid_argument("ParameterPacker: a mapping's keys x k must fill its view");
      if (!t[3].is_none())
      {
        s.fallback = t[3].cast<std::vector<double>>();
        if (static_cast<py::ssize_t>(s.fallback.size()) != s.per_key)
          throw std::invalid_argument("ParameterPacker: a mapping's default has k entries");
      }
    }

    // The mapping's entries for the keys into the view (true), or false: left to ``get``.
    static bool write_mapping(Source & s)
    {
      PyObject * map = PyObject_GetAttr(s.task.ptr(), s.map_name.ptr());
      if (map == nullptr)
      {
        PyErr_Clear(); // ``get`` says what is wrong
        return false;
      }
      const py::object owned = py::reinterpret_steal<py::object>(map);
      if (!PyDict_Check(map))
        return false;
      const std::size_t k = static_cast<std::size_t>(s.per_key);
      double * out = s.data;
      for (const py::object & key : s.keys)
      {
        PyObject * entry = PyDict_GetItemWithError(map, key.ptr()); // borrowed
        if (entry == nullptr)
        {
          if (PyErr_Occurred() || s.fallback.empty())
          {
            PyErr_Clear();
            return false;
          }
          std::copy(s.fallback.begin(), s.fallback.end(), out);
        }
        else
        {
          if (!py::array_t<double>::check_(entry))
            return false;
          auto arr = py::reinterpret_borrow<py::array_t<double>>(entry);
          if (arr.ndim() != 1 || !(arr.flags() & py::array::c_style)
              || arr.size() != s.per_key)
            return false;
          std::memcpy(out, arr.data(), sizeof(double) * k);
        }
        out += k;
      }
      return true;
    }

    // The task's attribute at the end of the path (a new reference, or null with the error set).
    static PyObject * get_path(const Source & s)
    {
      PyObject * value = s.task.ptr();
      Py_INCREF(value);
      for (const py::object & part : s.path)
      {
        PyObject * next = PyObject_GetAttr(value, part.ptr());
        Py_DECREF(value);
        if (next == nullptr)
          return nullptr;
        value = next;
      }
      return value;
    }

    static PyObject * call_get(const Source & s)
    {
      PyObject * args[] = {s.task.ptr(), s.layout.ptr(), s.state.ptr()};
      return PyObject_Vectorcall(s.get.ptr(), args, 3, nullptr);
    }

    // The value written here (true), or left to ``assign`` (false): anything but the common kinds.
    static bool write(Source & s, PyObject * value)
    {
      if (s.form == Form::Flag)
      {
        if (value != Py_True && value != Py_False)
          return false;
        s.data[0] = value == Py_True ? 1.0 : 0.0;
        return true;
      }
      if (PyFloat_Check(value) || (PyLong_Check(value) && !PyBool_Check(value)))
      {
        const double d = PyFloat_AsDouble(value);
        if (d == -1.0 && PyErr_Occurred())
        {
          PyErr_Clear(); // e.g. an int too large: assign says what numpy says
          return false;
        }
        std::fill(s.data, s.data + s.size, d);
        return true;
      }
      if (!py::array_t<double>::check_(value))
        return false;
      auto arr = py::reinterpret_borrow<py::array_t<double>>(value);
      const py::ssize_t n = arr.size();
      // a vector or a gain takes a vector of its entries (a matrix is assign's to refuse); a
      // matrix takes its entries in C order, whatever the shape
      if (s.form != Form::Matrix && arr.ndim() != 1)
        return false;
      if (arr.flags() & py::array::c_style)
      {
        if (n == s.size)
          std::memcpy(s.data, arr.data(), sizeof(double) * static_cast<std::size_t>(n));
        else if (n == 1)
          std::fill(s.data, s.data + s.size, *arr.data());
        else
          return false;
        return true;
      }
      // a Fortran-order matrix (Pinocchio's rotations): its entries in C order (as np.ravel)
      if (s.form != Form::Matrix || arr.ndim() != 2 || n != s.size
          || !(arr.flags() & py::array::f_style))
        return false;
      const py::ssize_t rows = arr.shape(0), cols = arr.shape(1);
      const double * d = arr.data();
      for (py::ssize_t i = 0; i < rows; ++i)
        for (py::ssize_t j = 0; j < cols; ++j)
          s.data[i * cols + j] = d[j * rows + i];
      return true;
    }

    std::vector<Source> sources_;
  };
} // namespace wholebody_native
