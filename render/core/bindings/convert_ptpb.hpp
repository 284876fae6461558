// Conversions between the Python dicts of render/ptpb/api.py and the core's structs (convert_ptpb.cpp).
// Each raises std::invalid_argument (ValueError in Python) naming the key that is wrong.
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <memory>
#include <utility>
#include <vector>

#include "ptpb/render.hpp"
#include "ptpb/scene.hpp"
#include "ptpb/settings.hpp"

namespace ptpb_bindings {

namespace py = pybind11;

ptpb::Scene parse_scene(const py::dict& d);
// The settings by the keys of ptpb::for_each_setting; a key left out keeps its default.
ptpb::RenderSettings parse_settings(const py::dict& d);
// The settings as for_each_setting declares them, one dict each in its order: key; kind (int, float, bool, enum,
// or optional: a float or None); default (enums by name; unset optionals and zeros that mean none as None);
// choices (an enum's names, else None); ge, gt, le, lt (bounds or None); description; config (false: API only).
py::list settings_spec_list();

// The counters and timings a result's "stats" dict and a checkpoint state carry.
py::dict stats_dict(const ptpb::RenderStats& s);
// A result's "stats": stats_dict, whether the run was cancelled or interrupted (Ctrl-C), the
// fractions of the energy before and after the frame window, and the resolved schedule (alpha,
// surface_alpha, initial_beam_radius_m, initial_time_half_width_m, initial_surface_radius_m,
// initial_surface_time_half_width_m).
py::dict result_stats_dict(const ptpb::RenderStats& s, bool interrupted);

// The checkpoint dict: the state's sums copied out (steady, early, late float64; frames and their
// remainders float32) as arrays the callback may keep; and back (refusing other precisions).
py::dict state_dict(const ptpb::RenderState& st);
ptpb::RenderState parse_state(const py::dict& d);

// Python callbacks (progress, checkpoint) called from a core loop that runs without the GIL (DESIGN.md §9). Each
// call takes the GIL itself. Ctrl-C, or a KeyboardInterrupt a callback raises, stops the loop and marks the run
// interrupted; any other exception stops it and is raised again once the loop has returned (rethrow_error).
class PyCallbacks {
 public:
  // With the GIL held: false, to stop, when a signal handler raised (Ctrl-C) or an error is kept.
  bool signals_allow() {
    if (PyErr_CheckSignals() == 0) return true;
    if (PyErr_ExceptionMatches(PyExc_KeyboardInterrupt)) {
      PyErr_Clear();
      interrupted_ = true;
    } else if (!error_) {
      error_ = std::make_unique<py::error_already_set>();
    }
    return false;
  }
  // With the GIL held: call() returns the callback's answer; None or a true value goes on.
  template <typename Call>
  bool keep_going(Call&& call) {
    try {
      py::object answer = call();
      return answer.is_none() || answer.cast<bool>();
    } catch (py::error_already_set& e) {
      if (e.matches(PyExc_KeyboardInterrupt))
        interrupted_ = true;
      else if (!error_)
        error_ = std::make_unique<py::error_already_set>(std::move(e));
      return false;
    }
  }
  // After the loop, with the GIL back: raise the first exception a callback raised, if any.
  void rethrow_error() {
    if (error_) throw std::move(*error_);
  }
  bool interrupted() const { return interrupted_; }

 private:
  bool interrupted_ = false;
  std::unique_ptr<py::error_already_set> error_;
};

// NumPy array that takes ownership of a vector's buffer (no copy).
template <typename T>
py::array_t<T> owned_array(std::vector<T>&& v, std::vector<py::ssize_t> shape);

}  // namespace ptpb_bindings
