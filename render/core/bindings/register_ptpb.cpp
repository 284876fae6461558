// Python bindings of the PTPB renderer: scene and settings come in as plain dicts (built by
// render/ptpb.py), images go out as NumPy arrays that own the C++ buffers.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "ptpb/kernels.hpp"
#include "ptpb/render.hpp"
#include "ptpb/units.hpp"

namespace py = pybind11;

namespace {

using namespace ptpb;

template <typename T>
T get(const py::dict& d, const char* key, const T& fallback, const std::string& where) {
  if (!d.contains(key)) return fallback;
  try {
    return d[key].cast<T>();
  } catch (const py::cast_error&) {
    throw std::invalid_argument(where + "." + key + " has the wrong type");
  }
}

template <typename T>
T require_key(const py::dict& d, const char* key, const std::string& where) {
  if (!d.contains(key)) throw std::invalid_argument(where + "." + key + " is required");
  return get<T>(d, key, T{}, where);
}

Vec3d vec3(const py::dict& d, const char* key, const Vec3d& fallback, const std::string& where) {
  if (!d.contains(key)) return fallback;
  std::vector<double> v;
  try {
    v = d[key].cast<std::vector<double>>();
  } catch (const py::cast_error&) {
    throw std::invalid_argument(where + "." + key + " must be a sequence of 3 numbers");
  }
  if (v.size() != 3) throw std::invalid_argument(where + "." + key + " must have 3 components");
  return {v[0], v[1], v[2]};
}

template <typename E>
E choose(const std::string& value, std::initializer_list<std::pair<const char*, E>> options, const std::string& key) {
  std::string names;
  for (const auto& [name, e] : options) {
    if (value == name) return e;
    names += std::string(names.empty() ? "" : ", ") + name;
  }
  throw std::invalid_argument(key + " must be one of " + names + ", got '" + value + "'");
}

std::vector<py::dict> dict_list(const py::dict& d, const char* key) {
  std::vector<py::dict> out;
  if (!d.contains(key)) return out;
  for (const auto& item : d[key].cast<py::list>()) out.push_back(item.cast<py::dict>());
  return out;
}

Scene parse_scene(const py::dict& d) {
  Scene sc;
  int i = 0;
  for (const py::dict& m : dict_list(d, "media")) {
    const std::string w = "media[" + std::to_string(i++) + "]";
    Medium med;
    med.sigma_s = vec3(m, "sigma_s", {0, 0, 0}, w);
    med.sigma_a = vec3(m, "sigma_a", {0, 0, 0}, w);
    med.g = get<double>(m, "g", 0.0, w);
    med.ior = get<double>(m, "ior", 1.0, w);
    sc.media.push_back(med);
  }
  i = 0;
  for (const py::dict& s : dict_list(d, "shapes")) {
    const std::string w = "shapes[" + std::to_string(i++) + "]";
    Shape sh;
    auto verts = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(s["vertices"]);
    auto faces = py::array_t<std::uint32_t, py::array::c_style | py::array::forcecast>::ensure(s["faces"]);
    if (!verts || verts.ndim() != 2 || verts.shape(1) != 3) throw std::invalid_argument(w + ".vertices must be (N, 3)");
    if (!faces || faces.ndim() != 2 || faces.shape(1) != 3) throw std::invalid_argument(w + ".faces must be (M, 3)");
    sh.vertices.assign(verts.data(), verts.data() + verts.size());
    sh.faces.assign(faces.data(), faces.data() + faces.size());
    sh.kind = choose<SurfaceKind>(get<std::string>(s, "kind", "null", w),
                                  {{"null", SurfaceKind::Null}, {"dielectric", SurfaceKind::Dielectric},
                                   {"diffuse", SurfaceKind::Diffuse}}, w + ".kind");
    sh.interior = get<int>(s, "interior", kVacuum, w);
    sh.exterior = get<int>(s, "exterior", kVacuum, w);
    sh.albedo = vec3(s, "albedo", {0, 0, 0}, w);
    sh.radiance = vec3(s, "radiance", {0, 0, 0}, w);
    sc.shapes.push_back(std::move(sh));
  }
  i = 0;
  for (const py::dict& l : dict_list(d, "point_lights")) {
    const std::string w = "point_lights[" + std::to_string(i++) + "]";
    sc.point_lights.push_back({vec3(l, "position", {0, 0, 0}, w), vec3(l, "intensity", {0, 0, 0}, w),
                               get<int>(l, "medium", kVacuum, w)});
  }
  i = 0;
  for (const py::dict& l : dict_list(d, "directional_lights")) {
    const std::string w = "directional_lights[" + std::to_string(i++) + "]";
    DirectionalLight dl;
    dl.to_sun = vec3(l, "to_sun", {0, 0, 1}, w);
    dl.irradiance = vec3(l, "irradiance", {0, 0, 0}, w);
    if (l.contains("reference_point") && !l["reference_point"].is_none()) {
      dl.has_reference_point = true;
      dl.reference_point = vec3(l, "reference_point", {0, 0, 0}, w);
    }
    sc.directional_lights.push_back(dl);
  }
  sc.environment_radiance = vec3(d, "environment_radiance", {0, 0, 0}, "scene");
  sc.ambient_ior = get<double>(d, "ambient_ior", 1.0, "scene");
  const py::dict cam = require_key<py::dict>(d, "camera", "scene");
  sc.camera.origin = vec3(cam, "origin", {0, 0, 0}, "camera");
  sc.camera.target = vec3(cam, "target", {0, 0, 1}, "camera");
  sc.camera.up = vec3(cam, "up", {0, 1, 0}, "camera");
  sc.camera.fov_deg = require_key<double>(cam, "fov", "camera");
  sc.camera.fov_axis = get<std::string>(cam, "fov_axis", "x", "camera");
  sc.camera.width = require_key<int>(cam, "width", "camera");
  sc.camera.height = require_key<int>(cam, "height", "camera");
  sc.camera.medium = get<int>(cam, "medium", kVacuum, "camera");
  const py::dict film = require_key<py::dict>(d, "film", "scene");
  sc.film.mode = choose<FrameMode>(require_key<std::string>(film, "frame_mode", "film"),
                                   {{"steady", FrameMode::Steady}, {"bins", FrameMode::Bins}, {"gate", FrameMode::Gate}},
                                   "film.frame_mode");
  sc.film.temporal_bins = get<int>(film, "temporal_bins", 0, "film");
  sc.film.start_opl = get<double>(film, "start_opl", 0.0, "film");
  sc.film.bin_width_opl = get<double>(film, "bin_width_opl", 0.003, "film");
  return sc;
}

RenderSettings parse_settings(const py::dict& d) {
  const std::string w = "settings";
  RenderSettings s;
  s.iterations = get<int>(d, "iterations", s.iterations, w);
  s.time_budget_s = get<double>(d, "time_budget_s", 0.0, w);
  s.light_paths_per_iteration = get<std::uint64_t>(d, "light_paths_per_iteration", s.light_paths_per_iteration, w);
  s.alpha = get<double>(d, "alpha", s.alpha, w);
  s.initial_beam_radius = require_key<double>(d, "initial_beam_radius", w);
  s.initial_time_half_width = get<double>(d, "initial_time_half_width", s.initial_beam_radius, w);
  // Surface photons (§7): without their own keys they start from the beams' bandwidths.
  s.initial_surface_radius = get<double>(d, "initial_surface_radius", s.initial_beam_radius, w);
  if (d.contains("initial_surface_time_half_width") && !d["initial_surface_time_half_width"].is_none())
    s.initial_surface_time_half_width = get<double>(d, "initial_surface_time_half_width", 0.0, w);
  if (d.contains("surface_alpha") && !d["surface_alpha"].is_none()) s.surface_alpha = get<double>(d, "surface_alpha", 0.0, w);
  s.surface_normal_cos = get<double>(d, "surface_normal_cos", s.surface_normal_cos, w);
  s.spatial_kernel = choose<SpatialKernel>(get<std::string>(d, "spatial_kernel", "epanechnikov", w),
                                           {{"box", SpatialKernel::Box}, {"epanechnikov", SpatialKernel::Epanechnikov}},
                                           "spatial_kernel");
  s.temporal_kernel = choose<TemporalKernel>(
      get<std::string>(d, "temporal_kernel", "epanechnikov", w),
      {{"box", TemporalKernel::Box}, {"epanechnikov", TemporalKernel::Epanechnikov}, {"quintic", TemporalKernel::Quintic}},
      "temporal_kernel");
  s.photon_beam_kind = choose<BeamKind>(get<std::string>(d, "photon_beam_kind", "long", w),
                                        {{"long", BeamKind::Long}, {"short", BeamKind::Short}}, "photon_beam_kind");
  s.query_beam_kind = choose<BeamKind>(get<std::string>(d, "query_beam_kind", "long", w),
                                       {{"long", BeamKind::Long}, {"short", BeamKind::Short}}, "query_beam_kind");
  s.parallel_guard_sin2 = get<double>(d, "parallel_guard_sin2", s.parallel_guard_sin2, w);
  s.max_depth = get<int>(d, "max_depth", s.max_depth, w);
  s.rr_depth = get<int>(d, "rr_depth", s.rr_depth, w);
  s.seed = get<std::uint64_t>(d, "seed", 0, w);
  s.threads = get<int>(d, "threads", 0, w);
  s.accel = choose<AccelKind>(get<std::string>(d, "accel", "embree", w),
                              {{"grid", AccelKind::Grid}, {"embree", AccelKind::Embree}}, "accel");
  s.grid_resolution = get<int>(d, "grid_resolution", s.grid_resolution, w);
  s.dice_length = get<double>(d, "dice_length", 0.0, w);
  s.jitter = get<bool>(d, "jitter", true, w);
  s.camera_unwarp = get<bool>(d, "camera_unwarp", false, w);
  s.transmittance_cutoff = get<double>(d, "transmittance_cutoff", s.transmittance_cutoff, w);
  s.tile_size = get<int>(d, "tile_size", s.tile_size, w);
  s.snapshot_every = get<int>(d, "snapshot_every", 0, w);
  return s;
}

// NumPy array that takes ownership of a vector's buffer (no copy).
py::array_t<float> owned_array(std::vector<float>&& v, std::vector<py::ssize_t> shape) {
  auto* holder = new std::vector<float>(std::move(v));
  py::capsule free_when_done(holder, [](void* p) { delete static_cast<std::vector<float>*>(p); });
  return py::array_t<float>(shape, holder->data(), free_when_done);
}

py::dict render_py(const py::dict& scene_dict, const py::dict& settings_dict, const py::object& progress) {
  const Scene scene = parse_scene(scene_dict);
  const RenderSettings settings = parse_settings(settings_dict);
  bool interrupted = false;
  std::unique_ptr<py::error_already_set> callback_error;
  ProgressCallback cb = [&](const Progress& p) {
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) {
      // Ctrl-C: stop after the last complete iteration and return what we have.
      if (PyErr_ExceptionMatches(PyExc_KeyboardInterrupt)) {
        PyErr_Clear();
        interrupted = true;
      } else {
        callback_error = std::make_unique<py::error_already_set>();
      }
      return false;
    }
    if (progress.is_none()) return true;
    try {
      py::dict info;
      info["iteration"] = p.iteration;
      info["iterations"] = p.iterations;
      info["elapsed_s"] = p.elapsed_s;
      info["radius"] = p.radius;
      info["time_half_width"] = p.time_half_width;
      info["beams"] = p.beams;
      info["surface_radius"] = p.surface_radius;
      info["surface_photons"] = p.surface_photons;
      py::object keep_going = progress(info);
      return keep_going.is_none() || keep_going.cast<bool>();
    } catch (py::error_already_set& e) {
      if (e.matches(PyExc_KeyboardInterrupt)) {
        interrupted = true;
      } else {
        callback_error = std::make_unique<py::error_already_set>(std::move(e));
      }
      return false;
    }
  };
  RenderResult r;
  {
    py::gil_scoped_release release;
    r = render(scene, settings, cb);
  }
  if (callback_error) throw std::move(*callback_error);
  const py::ssize_t H = r.height, W = r.width, F = r.frame_count;
  py::dict out;
  out["steady"] = owned_array(std::move(r.steady), {H, W, 3});
  out["frames"] = owned_array(std::move(r.frames), {F, H, W, 3});
  out["early"] = owned_array(std::move(r.early), {H, W, 3});
  out["late"] = owned_array(std::move(r.late), {H, W, 3});
  py::list snaps;
  for (std::size_t i = 0; i < r.snapshots.size(); ++i)
    snaps.append(py::make_tuple(r.snapshot_iterations[i], owned_array(std::move(r.snapshots[i]), {H, W, 3})));
  out["snapshots"] = snaps;
  out["snapshot_seconds"] = py::cast(r.snapshot_seconds);
  const RenderStats& s = r.stats;
  py::dict st;
  st["iterations"] = s.iterations_done;
  st["cancelled"] = s.cancelled;
  st["interrupted"] = interrupted;
  st["light_paths"] = s.light_paths;
  st["beams"] = s.beams;
  st["queries"] = s.queries;
  st["candidates"] = s.candidates;
  st["pair_evaluations"] = s.pair_evaluations;
  st["parallel_rejected"] = s.parallel_rejected;
  st["false_positives"] = s.false_positives;
  st["accel_references"] = s.accel_references;
  st["time_light_s"] = s.time_light_s;
  st["time_build_s"] = s.time_build_s;
  st["time_camera_s"] = s.time_camera_s;
  st["time_total_s"] = s.time_total_s;
  st["final_radius"] = s.final_radius;
  st["final_time_half_width"] = s.final_time_half_width;
  st["surface_photons"] = s.surface_photons;
  st["surface_queries"] = s.surface_queries;
  st["surface_pairs"] = s.surface_pairs;
  st["time_surface_build_s"] = s.time_surface_build_s;
  st["final_surface_radius"] = s.final_surface_radius;
  st["final_surface_time_half_width"] = s.final_surface_time_half_width;
  const double all = s.steady_total;
  st["out_of_window_fraction"] = all > 0 ? (s.early_total + s.late_total) / all : 0.0;
  st["early_fraction"] = all > 0 ? s.early_total / all : 0.0;
  st["late_fraction"] = all > 0 ? s.late_total / all : 0.0;
  out["stats"] = st;
  return out;
}

}  // namespace

void register_ptpb(py::module_& m) {
  m.def("ptpb_render", &render_py, py::arg("scene"), py::arg("settings"), py::arg("progress") = py::none(),
        "Render a scene dict with the PTPB renderer; returns a dict of arrays and statistics.\n"
        "The GIL is released while rendering; `progress(info) -> bool|None` is called about\n"
        "twice a second and after each iteration; returning False or Ctrl-C stops after the\n"
        "last complete iteration.");
  m.def("ptpb_schedule_gamma", &schedule_gamma, py::arg("iteration"), py::arg("alpha"));
  m.attr("SPEED_OF_LIGHT") = kSpeedOfLight;
  m.attr("PS_PER_M_OPL") = kPicosecondsPerMetreOpl;
}
