// Conversions between the Python dicts of render/ptpb/api.py and the core's structs: scene, settings,
// stats and checkpoint states. Registration lives in register_ptpb.cpp.
#include "convert_ptpb.hpp"

#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "ptpb/kernels.hpp"

namespace py = pybind11;

namespace ptpb_bindings {

using namespace ptpb;

namespace {

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
std::string name_of(E value) {
  for (const auto& [name, e] : choices(value))
    if (e == value) return name;
  throw std::logic_error("an enum value without a name in choices() (ptpb/settings.hpp)");
}

// The enum that ``value`` names among ``options`` (a braced list of name, enum pairs, or choices(E{})).
template <typename E, typename Options = std::initializer_list<std::pair<const char*, E>>>
E choose(const std::string& value, const Options& options, const std::string& key) {
  std::string names;
  for (const auto& [name, e] : options) {
    if (value == name) return e;
    names += std::string(names.empty() ? "" : ", ") + name;
  }
  throw std::invalid_argument(key + " must be one of " + names + ", got '" + value + "'");
}

template <typename T>
struct IsOptional : std::false_type {};
template <typename T>
struct IsOptional<std::optional<T>> : std::true_type {};

// A number that may be missing or None: then unset, and the core resolves its default.
std::optional<double> optional_number(const py::dict& d, const char* key, const std::string& where) {
  if (!d.contains(key) || d[key].is_none()) return std::nullopt;
  return get<double>(d, key, 0.0, where);
}

std::vector<py::dict> dict_list(const py::dict& d, const char* key) {
  std::vector<py::dict> out;
  if (!d.contains(key) || d[key].is_none()) return out;
  const py::object items = d[key];
  if (!py::isinstance<py::list>(items) && !py::isinstance<py::tuple>(items))
    throw std::invalid_argument(std::string("scene.") + key + " must be a list of dicts");
  int i = 0;
  for (const auto& item : items) {
    if (!py::isinstance<py::dict>(item))
      throw std::invalid_argument(std::string("scene.") + key + "[" + std::to_string(i) + "] must be a dict");
    out.push_back(item.cast<py::dict>());
    ++i;
  }
  return out;
}

// An (N, 3) array of a shape's mesh; a missing key, another shape or a non-numeric value names the key.
template <typename T>
py::array_t<T, py::array::c_style | py::array::forcecast> mesh_array(const py::dict& s, const char* key,
                                                                     const std::string& where) {
  if (!s.contains(key)) throw std::invalid_argument(where + "." + key + " is required");
  const auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(s[key]);  // null if not numeric
  if (!a) throw std::invalid_argument(where + "." + key + " must be an array of numbers");
  if (a.ndim() != 2 || a.shape(1) != 3)
    throw std::invalid_argument(where + "." + key +
                                (a.ndim() == 1 && a.shape(0) == 0 ? " is empty" : " must be (N, 3)"));
  return a;
}

// Visits every RenderStats field that a result's "stats" dict and a resume state carry, with its
// dict key: one list for both directions.
template <typename Stats, typename Visit>
void for_each_stat(Stats& s, Visit&& visit) {
  visit("iterations", s.iterations_done);
  visit("light_paths", s.light_paths);
  visit("beams", s.beams);
  visit("queries", s.queries);
  visit("candidates", s.candidates);
  visit("pair_evaluations", s.pair_evaluations);
  visit("parallel_rejected", s.parallel_rejected);
  visit("false_positives", s.false_positives);
  visit("accel_references", s.accel_references);
  visit("time_light_s", s.time_light_s);
  visit("time_build_s", s.time_build_s);
  visit("time_camera_s", s.time_camera_s);
  visit("time_total_s", s.time_total_s);
  visit("final_radius", s.final_radius);
  visit("final_time_half_width", s.final_time_half_width);
  visit("surface_photons", s.surface_photons);
  visit("surface_queries", s.surface_queries);
  visit("surface_pairs", s.surface_pairs);
  visit("time_surface_build_s", s.time_surface_build_s);
  visit("final_surface_radius", s.final_surface_radius);
  visit("final_surface_time_half_width", s.final_surface_time_half_width);
  visit("path_vertices", s.path_vertices);
  visit("path_connections", s.path_connections);
  visit("path_clearance_queries", s.path_clearance_queries);
  visit("path_clear_flights", s.path_clear_flights);
  visit("path_splits", s.path_splits);
  visit("path_hops", s.path_hops);
  visit("path_hop_scatterings", s.path_hop_scatterings);
  visit("path_media", s.path_media);
  visit("specular_beams", s.specular_beams);
  visit("specular_pairs", s.specular_pairs);
  visit("final_specular_radius", s.final_specular_radius);
}

RenderStats parse_stats(const py::dict& d) {
  const std::string w = "resume.stats";
  RenderStats s;
  for_each_stat(s,
                [&](const char* key, auto& value) { value = require_key<std::decay_t<decltype(value)>>(d, key, w); });
  return s;
}

template <typename T>
py::array_t<T> copy_array(const T* data, std::vector<py::ssize_t> shape) {
  py::array_t<T> a(shape);
  std::copy(data, data + a.size(), a.mutable_data());
  return a;
}

template <typename T>
std::vector<T> state_array(const py::dict& d, const char* key, std::vector<py::ssize_t> shape) {
  if (!d.contains(key)) throw std::invalid_argument(std::string("resume.") + key + " is required");
  // A sum of another precision would resume rounded, not bit-identically: refuse it.
  const py::array given = py::array::ensure(d[key]);
  if (given && !given.dtype().is(py::dtype::of<T>()))
    throw std::invalid_argument(std::string("resume.") + key + " must be " + (sizeof(T) == 4 ? "float32" : "float64") +
                                ", got " + std::string(py::str(given.dtype())) + " (a state from another version?)");
  const auto a = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(d[key]);
  if (!a) throw std::invalid_argument(std::string("resume.") + key + " must be an array of numbers");
  bool same = a.ndim() == py::ssize_t(shape.size());
  for (std::size_t k = 0; same && k < shape.size(); ++k) same = a.shape(k) == shape[k];
  if (!same) throw std::invalid_argument(std::string("resume.") + key + " does not have the shape of the state's film");
  return std::vector<T>(a.data(), a.data() + a.size());
}

}  // namespace

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
    const auto verts = mesh_array<float>(s, "vertices", w);
    // Faces go through int64 first: a negative index must be refused, not wrapped to a huge one.
    const auto faces = mesh_array<std::int64_t>(s, "faces", w);
    sh.vertices.assign(verts.data(), verts.data() + verts.size());
    sh.faces.resize(std::size_t(faces.size()));
    for (py::ssize_t k = 0; k < faces.size(); ++k) {
      const std::int64_t index = faces.data()[k];
      if (index < 0 || index > 0xFFFFFFFELL)
        throw std::invalid_argument(w + ".faces[" + std::to_string(k / 3) + "] has vertex index " +
                                    std::to_string(index) + ", outside [0, 2^32 - 1)");
      sh.faces[std::size_t(k)] = static_cast<std::uint32_t>(index);
    }
    sh.kind = choose<SurfaceKind>(
        get<std::string>(s, "kind", "null", w),
        {{"null", SurfaceKind::Null}, {"dielectric", SurfaceKind::Dielectric}, {"diffuse", SurfaceKind::Diffuse}},
        w + ".kind");
    sh.interior = get<int>(s, "interior", kVacuum, w);
    sh.exterior = get<int>(s, "exterior", kVacuum, w);
    sh.albedo = vec3(s, "albedo", {0, 0, 0}, w);
    sh.radiance = vec3(s, "radiance", {0, 0, 0}, w);
    if (s.contains("offsets") && !s["offsets"].is_none()) {
      const auto offsets = mesh_array<double>(s, "offsets", w);
      sh.offsets.assign(offsets.data(), offsets.data() + offsets.size());
    }
    sc.shapes.push_back(std::move(sh));
  }
  i = 0;
  for (const py::dict& l : dict_list(d, "point_lights")) {
    const std::string w = "point_lights[" + std::to_string(i++) + "]";
    sc.point_lights.push_back(
        {vec3(l, "position", {0, 0, 0}, w), vec3(l, "intensity", {0, 0, 0}, w), get<int>(l, "medium", kVacuum, w)});
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
    dl.beam_radius = get<double>(l, "beam_radius", 0.0, w);
    dl.beam_center = vec3(l, "beam_center", dl.reference_point, w);
    sc.directional_lights.push_back(dl);
  }
  sc.environment_radiance = vec3(d, "environment_radiance", {0, 0, 0}, "scene");
  sc.environment_up = vec3(d, "environment_up", {0, 0, 0}, "scene");
  sc.ambient_ior = get<double>(d, "ambient_ior", 1.0, "scene");
  const py::dict cam = require_key<py::dict>(d, "camera", "scene");
  sc.camera.origin = vec3(cam, "origin", {0, 0, 0}, "camera");
  sc.camera.target = vec3(cam, "target", {0, 0, 1}, "camera");
  sc.camera.up = vec3(cam, "up", {0, 1, 0}, "camera");
  sc.camera.projection = choose<Projection>(
      get<std::string>(cam, "projection", "perspective", "camera"),
      {{"perspective", Projection::Perspective}, {"orthographic", Projection::Orthographic}}, "camera.projection");
  if (sc.camera.projection == Projection::Orthographic) {
    sc.camera.ortho_width = require_key<double>(cam, "ortho_width", "camera");
    sc.camera.fov_deg = get<double>(cam, "fov", sc.camera.fov_deg, "camera");
  } else {
    sc.camera.fov_deg = require_key<double>(cam, "fov", "camera");
  }
  sc.camera.fov_axis = get<std::string>(cam, "fov_axis", "x", "camera");
  sc.camera.width = require_key<int>(cam, "width", "camera");
  sc.camera.height = require_key<int>(cam, "height", "camera");
  sc.camera.medium = get<int>(cam, "medium", kVacuum, "camera");
  const py::dict film = require_key<py::dict>(d, "film", "scene");
  sc.film.mode = choose<FrameMode>(
      require_key<std::string>(film, "frame_mode", "film"),
      {{"steady", FrameMode::Steady}, {"bins", FrameMode::Bins}, {"gate", FrameMode::Gate}}, "film.frame_mode");
  sc.film.temporal_bins = get<int>(film, "temporal_bins", 0, "film");
  sc.film.start_opl = get<double>(film, "start_opl", 0.0, "film");
  sc.film.bin_width_opl = get<double>(film, "bin_width_opl", 0.003, "film");
  sc.film.window_first = get<int>(film, "window_first", 0, "film");
  sc.film.window_count = get<int>(film, "window_count", -1, "film");
  return sc;
}

RenderSettings parse_settings(const py::dict& d) {
  const std::string w = "settings";
  // Every length of the schedule follows from R_0, and no default of it would suit a caller's scene.
  if (!d.contains("initial_beam_radius")) throw std::invalid_argument(w + ".initial_beam_radius is required");
  RenderSettings s;
  for_each_setting(s, [&](const char* key, auto& value, const SettingInfo& info) {
    using T = std::decay_t<decltype(value)>;
    if constexpr (std::is_arithmetic_v<T>) {
      if (info.zero_means_none && d.contains(key) && d[key].is_none()) {
        value = T{0};
        return;
      }
    }
    if constexpr (IsOptional<T>::value) {
      // The schedule's defaults belong to the core (resolve_schedule): None leaves them unset.
      if (d.contains(key)) value = optional_number(d, key, w);
    } else if constexpr (std::is_enum_v<T>) {
      value = choose<T>(get<std::string>(d, key, name_of(value), w), choices(T{}), key);
    } else {
      value = get<T>(d, key, value, w);
    }
  });
  return s;
}

namespace {

// A bound as Python writes it: a whole number as an int (the schema's messages then read "greater than 0").
py::object bound(const std::optional<double>& b) {
  if (!b) return py::none();
  if (std::floor(*b) == *b) return py::int_(static_cast<long long>(*b));
  return py::float_(*b);
}

// What a setting's value is, in the schema's words: int, float, bool, enum, or optional (a float or None).
template <typename T>
const char* kind_of(const SettingInfo& info) {
  if constexpr (IsOptional<T>::value) {
    return "optional";
  } else if constexpr (std::is_same_v<T, bool>) {
    return "bool";
  } else if constexpr (std::is_enum_v<T>) {
    return "enum";
  } else if constexpr (std::is_integral_v<T>) {
    return "int";
  } else {
    return info.zero_means_none ? "optional" : "float";
  }
}

}  // namespace

py::list settings_spec_list() {
  const RenderSettings s;
  py::list out;
  for_each_setting(s, [&](const char* key, const auto& value, const SettingInfo& info) {
    using T = std::decay_t<decltype(value)>;
    py::dict spec;
    spec["key"] = key;
    spec["kind"] = kind_of<T>(info);
    py::list names;
    if constexpr (std::is_enum_v<T>) {
      spec["default"] = name_of(value);
      for (const auto& [name, e] : choices(value)) names.append(name);
    } else if constexpr (std::is_arithmetic_v<T>) {
      spec["default"] = info.zero_means_none && value == T{0} ? py::none() : py::cast(value);
    } else {
      spec["default"] = py::cast(value);  // an unset optional is None
    }
    spec["choices"] = names.empty() ? py::object(py::none()) : py::object(names);
    spec["ge"] = bound(info.ge);
    spec["gt"] = bound(info.gt);
    spec["le"] = bound(info.le);
    spec["lt"] = bound(info.lt);
    spec["description"] = info.description;
    spec["config"] = !info.api_only;
    out.append(spec);
  });
  return out;
}

py::dict stats_dict(const RenderStats& s) {
  py::dict st;
  for_each_stat(s, [&](const char* key, const auto& value) { st[key] = value; });
  return st;
}

py::dict result_stats_dict(const RenderStats& s, bool interrupted) {
  py::dict st = stats_dict(s);
  st["cancelled"] = s.cancelled;
  st["interrupted"] = interrupted;
  const double all = s.steady_total;
  st["out_of_window_fraction"] = all > 0 ? (s.early_total + s.late_total) / all : 0.0;
  st["early_fraction"] = all > 0 ? s.early_total / all : 0.0;
  st["late_fraction"] = all > 0 ? s.late_total / all : 0.0;
  // The schedule the core resolved from the settings and their defaults.
  st["alpha"] = s.schedule.alpha;
  st["surface_alpha"] = s.schedule.surface_alpha;
  st["initial_beam_radius_m"] = s.schedule.initial_beam_radius;
  st["initial_time_half_width_m"] = s.schedule.initial_time_half_width;
  st["initial_surface_radius_m"] = s.schedule.initial_surface_radius;
  st["initial_surface_time_half_width_m"] = s.schedule.initial_surface_time_half_width;
  return st;
}

// The checkpoint dict: the state's sums copied out (steady, early, late float64; frames and their
// remainders float32) as arrays the callback may keep.
py::dict state_dict(const RenderState& st) {
  const py::ssize_t H = st.height, W = st.width, F = st.frame_count, S = py::ssize_t(st.snapshots.size());
  py::dict out;
  out["width"] = st.width;
  out["height"] = st.height;
  out["frame_count"] = st.frame_count;
  out["seed"] = st.seed;
  out["steady"] = copy_array(st.steady.data(), {H, W, 3});
  out["early"] = copy_array(st.early.data(), {H, W, 3});
  out["late"] = copy_array(st.late.data(), {H, W, 3});
  out["frames"] = copy_array(st.frames.data(), {F, H, W, 3});
  if (!st.frames_carry.empty()) out["frames_carry"] = copy_array(st.frames_carry.data(), {F, H, W, 3});
  out["stats"] = stats_dict(st.stats);
  out["snapshot_iterations"] = py::cast(st.snapshot_iterations);
  out["snapshot_seconds"] = py::cast(st.snapshot_seconds);
  py::array_t<float> snaps({S, H, W, py::ssize_t(3)});
  for (py::ssize_t k = 0; k < S; ++k)
    std::copy(st.snapshots[k].begin(), st.snapshots[k].end(), snaps.mutable_data() + k * H * W * 3);
  out["snapshots"] = snaps;
  return out;
}

RenderState parse_state(const py::dict& d) {
  const std::string w = "resume";
  RenderState st;
  st.width = require_key<int>(d, "width", w);
  st.height = require_key<int>(d, "height", w);
  st.frame_count = require_key<int>(d, "frame_count", w);
  st.seed = require_key<std::uint64_t>(d, "seed", w);
  if (st.width < 1 || st.height < 1 || st.frame_count < 0)
    throw std::invalid_argument("resume: film size out of range");
  const py::ssize_t H = st.height, W = st.width, F = st.frame_count;
  st.steady = state_array<double>(d, "steady", {H, W, 3});
  st.early = state_array<double>(d, "early", {H, W, 3});
  st.late = state_array<double>(d, "late", {H, W, 3});
  st.frames = state_array<float>(d, "frames", {F, H, W, 3});
  if (d.contains("frames_carry")) st.frames_carry = state_array<float>(d, "frames_carry", {F, H, W, 3});
  st.stats = parse_stats(require_key<py::dict>(d, "stats", w));
  st.snapshot_iterations = get<std::vector<int>>(d, "snapshot_iterations", {}, w);
  st.snapshot_seconds = get<std::vector<double>>(d, "snapshot_seconds", {}, w);
  const py::ssize_t S = py::ssize_t(st.snapshot_iterations.size());
  const std::vector<float> snaps = S > 0 ? state_array<float>(d, "snapshots", {S, H, W, 3}) : std::vector<float>{};
  for (py::ssize_t k = 0; k < S; ++k)
    st.snapshots.emplace_back(snaps.begin() + k * H * W * 3, snaps.begin() + (k + 1) * H * W * 3);
  return st;
}

// NumPy array that takes ownership of a vector's buffer (no copy).
template <typename T>
py::array_t<T> owned_array(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
  auto* holder = new std::vector<T>(std::move(v));
  py::capsule free_when_done(holder, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, holder->data(), free_when_done);
}

template py::array_t<float> owned_array(std::vector<float>&&, std::vector<py::ssize_t>);
template py::array_t<double> owned_array(std::vector<double>&&, std::vector<py::ssize_t>);

}  // namespace ptpb_bindings
