// Python bindings of the PTPB renderer: scene and settings come in as plain dicts (built by
// render/ptpb/api.py; converted in convert_ptpb.cpp), images go out as NumPy arrays that own the C++
// buffers.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "convert_ptpb.hpp"
#include "ptpb/kernels.hpp"
#include "ptpb/render.hpp"
#include "ptpb/units.hpp"
#include "ptpb/validation.hpp"

namespace py = pybind11;

namespace {

using namespace ptpb;
using namespace ptpb_bindings;

py::dict render_py(const py::dict& scene_dict, const py::dict& settings_dict, const py::object& progress,
                   const py::object& resume, const py::object& checkpoint) {
  const Scene scene = parse_scene(scene_dict);
  const RenderSettings settings = parse_settings(settings_dict);
  const bool checkpointing =
      !checkpoint.is_none() && (settings.checkpoint_every_iterations > 0 || settings.checkpoint_every_s > 0);
  // Before the resume state is copied in: a film over budget must not allocate anything.
  check_memory_budget(scene, settings, !resume.is_none() || checkpointing);
  std::optional<RenderState> initial;
  if (!resume.is_none()) {
    if (!py::isinstance<py::dict>(resume)) throw std::invalid_argument("resume must be a dict (a checkpoint's state)");
    initial = parse_state(resume.cast<py::dict>());
  }
  PyCallbacks callbacks;
  ProgressCallback cb = [&](const Progress& p) {
    py::gil_scoped_acquire gil;
    // Ctrl-C: stop once the iteration under way is complete and return what we have.
    if (!callbacks.signals_allow()) return false;
    if (progress.is_none()) return true;
    return callbacks.keep_going([&] {
      py::dict info;
      info["iteration"] = p.iteration;
      info["iterations"] = p.iterations;
      info["elapsed_s"] = p.elapsed_s;
      info["radius"] = p.radius;
      info["time_half_width"] = p.time_half_width;
      info["beams"] = p.beams;
      info["surface_radius"] = p.surface_radius;
      info["surface_photons"] = p.surface_photons;
      return progress(info);
    });
  };
  CheckpointCallback save;
  if (checkpointing) {
    save = [&](const RenderState& st) {
      py::gil_scoped_acquire gil;
      return callbacks.keep_going([&] { return checkpoint(state_dict(st)); });
    };
  }
  RenderResult r;
  {
    py::gil_scoped_release release;
    r = render(scene, settings, cb, std::move(initial), save);
  }
  callbacks.rethrow_error();
  const py::ssize_t H = r.height, W = r.width, F = r.frame_count;
  py::dict out;
  if (settings.keep_sums) {
    // A shard: the undivided float64 sums, which a merge adds in shard order (DESIGN.md §9).
    out["steady_sum"] = owned_array(std::move(r.steady_sum), {H, W, 3});
    out["frames_sum"] = owned_array(std::move(r.frames_sum), {F, H, W, 3});
    out["early_sum"] = owned_array(std::move(r.early_sum), {H, W, 3});
    out["late_sum"] = owned_array(std::move(r.late_sum), {H, W, 3});
    out["stats"] = result_stats_dict(r.stats, callbacks.interrupted());
    return out;
  }
  out["steady"] = owned_array(std::move(r.steady), {H, W, 3});
  out["frames"] = owned_array(std::move(r.frames), {F, H, W, 3});
  out["early"] = owned_array(std::move(r.early), {H, W, 3});
  out["late"] = owned_array(std::move(r.late), {H, W, 3});
  py::list snaps;
  for (std::size_t i = 0; i < r.snapshots.size(); ++i)
    snaps.append(py::make_tuple(r.snapshot_iterations[i], owned_array(std::move(r.snapshots[i]), {H, W, 3})));
  out["snapshots"] = snaps;
  out["snapshot_seconds"] = py::cast(r.snapshot_seconds);
  out["stats"] = result_stats_dict(r.stats, callbacks.interrupted());
  return out;
}

double memory_bytes_py(const py::dict& scene_dict, const py::dict& settings_dict, bool state_copy) {
  return render_memory_bytes(parse_scene(scene_dict), parse_settings(settings_dict), state_copy);
}

}  // namespace

void register_ptpb(py::module_& m) {
  m.def("ptpb_render", &render_py, py::arg("scene"), py::arg("settings"), py::arg("progress") = py::none(),
        py::arg("resume") = py::none(), py::arg("checkpoint") = py::none(),
        "Render a scene dict with the PTPB renderer; returns a dict of arrays and statistics.\n"
        "The GIL is released while rendering; `progress(info) -> bool|None` is called about\n"
        "twice a second and after each iteration; returning False or Ctrl-C stops when the\n"
        "iteration under way is complete. `checkpoint(state) -> bool|None` receives the accumulated\n"
        "state (sums, stats, snapshots) every settings.checkpoint_every_iterations iterations or\n"
        "checkpoint_every_s seconds, and once more on cancellation; `resume=state` continues it.");
  m.def("ptpb_memory_bytes", &memory_bytes_py, py::arg("scene"), py::arg("settings"), py::arg("state_copy") = false,
        "Peak bytes of the render's image buffers, as checked against settings.memory_budget_gib.");
  m.def("ptpb_schedule_gamma", &schedule_gamma, py::arg("iteration"), py::arg("alpha"));
  m.def("render_settings_spec", &settings_spec_list,
        "Every setting the core parses, as render/core/include/ptpb/settings.hpp declares it: a list of dicts with\n"
        "key, kind (int, float, bool, enum, optional), default (enums by name; unset schedule values and zeros\n"
        "that mean none as None), choices, bounds ge/gt/le/lt, description and config (false: set by the API only).");
  m.attr("SPEED_OF_LIGHT") = kSpeedOfLight;
  m.attr("PS_PER_M_OPL") = kPicosecondsPerMetreOpl;
}
