// Python bindings of the grain tracer (grains.hpp): a packing of ice spheres against a homogeneous half-space,
// with the same receivers. Arrays out own the C++ buffers; the GIL is released while tracing.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <memory>
#include <string>
#include <vector>

#include "convert_ptpb.hpp"
#include "ptpb/grains.hpp"

namespace py = pybind11;

namespace {

using namespace ptpb;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

GrainTraceSettings trace_settings(std::uint64_t photons, std::uint64_t seed, double start_opl, double bin_width_opl,
                                  int temporal_bins, double cone_half_angle, double depth_bin_width, int depth_bins,
                                  double max_path, int threads) {
  GrainTraceSettings s;
  s.photons = photons;
  s.seed = seed;
  s.start_opl = start_opl;
  s.bin_width_opl = bin_width_opl;
  s.temporal_bins = temporal_bins;
  s.cone_half_angle = cone_half_angle;
  s.depth_bin_width = depth_bin_width;
  s.depth_bins = depth_bins;
  s.max_path = max_path;
  s.threads = threads;
  return s;
}

// Runs `trace` without the GIL; progress(done, total) -> bool|None and Ctrl-C are checked between groups
// of photons (the same contract as ptpb_render, DESIGN.md §9).
template <typename Trace>
py::dict run_traced(const py::object& progress, Trace&& trace) {
  ptpb_bindings::PyCallbacks callbacks;
  GrainProgress cb = [&](std::uint64_t done, std::uint64_t total) {
    py::gil_scoped_acquire gil;
    if (!callbacks.signals_allow()) return false;
    if (progress.is_none()) return true;
    return callbacks.keep_going([&] { return progress(done, total); });
  };
  GrainTraceResult r;
  {
    py::gil_scoped_release release;
    r = trace(cb);
  }
  callbacks.rethrow_error();
  using ptpb_bindings::owned_array;
  const auto bins = static_cast<py::ssize_t>(r.time_flux.size());
  const auto depth = static_cast<py::ssize_t>(r.absorbed_depth.size());
  py::dict out;
  out["time_flux"] = owned_array(std::move(r.time_flux), {bins});
  out["time_cone"] = owned_array(std::move(r.time_cone), {bins});
  out["air_by_bin"] = owned_array(std::move(r.air_by_bin), {bins});
  out["ice_by_bin"] = owned_array(std::move(r.ice_by_bin), {bins});
  out["absorbed_depth"] = owned_array(std::move(r.absorbed_depth), {depth});
  out["albedo"] = r.albedo;
  out["cone_fraction"] = r.cone_fraction;
  out["absorbed"] = r.absorbed;
  out["truncated"] = r.truncated;
  out["early"] = r.early;
  out["late"] = r.late;
  out["exit_opl"] = r.exit_opl;
  out["air_path"] = r.air_path;
  out["ice_path"] = r.ice_path;
  out["exit_air_path"] = r.exit_air_path;
  out["exit_ice_path"] = r.exit_ice_path;
  out["sphere_hits"] = r.sphere_hits;
  out["interactions"] = r.interactions;
  out["total_internal_reflections"] = r.total_internal_reflections;
  out["photons_done"] = r.photons_done;
  out["cancelled"] = r.cancelled || callbacks.interrupted();
  return out;
}

}  // namespace

void register_grains(py::module_& m) {
  m.def(
      "grains_trace_packing",
      [](const DoubleArray& centres, const DoubleArray& radii, double cell_size, double ice_index,
         double ice_group_index, double ice_absorption, std::uint64_t photons, std::uint64_t seed, double start_opl,
         double bin_width_opl, int temporal_bins, double cone_half_angle, double depth_bin_width, int depth_bins,
         double max_path, int threads, const py::object& progress) {
        if (centres.ndim() != 2 || centres.shape(1) != 3 || radii.ndim() != 1 || radii.shape(0) != centres.shape(0))
          throw py::value_error("centres must have shape (N, 3) and radii shape (N,)");
        GrainPacking p;
        p.cell_size = cell_size;
        p.centres.assign(centres.data(), centres.data() + centres.size());
        p.radii.assign(radii.data(), radii.data() + radii.size());
        GrainOptics o;
        o.ice_index = ice_index;
        o.ice_group_index = ice_group_index;
        o.ice_absorption = ice_absorption;
        const GrainTraceSettings s = trace_settings(photons, seed, start_opl, bin_width_opl, temporal_bins,
                                                    cone_half_angle, depth_bin_width, depth_bins, max_path, threads);
        return run_traced(progress, [&](const GrainProgress& cb) { return trace_packing(p, o, s, cb); });
      },
      py::arg("centres"), py::arg("radii"), py::arg("cell_size"), py::arg("ice_index"), py::arg("ice_group_index"),
      py::arg("ice_absorption"), py::arg("photons"), py::arg("seed"), py::arg("start_opl"), py::arg("bin_width_opl"),
      py::arg("temporal_bins"), py::arg("cone_half_angle"), py::arg("depth_bin_width"), py::arg("depth_bins"),
      py::arg("max_path"), py::arg("threads") = 0, py::arg("progress") = py::none(),
      "Trace a nadir beam into a periodic packing of ice spheres (grains.hpp); returns a dict of per-photon sums.");
  m.def(
      "grains_trace_homogeneous",
      [](double scattering, double absorption, double asymmetry, double time_index, std::uint64_t photons,
         std::uint64_t seed, double start_opl, double bin_width_opl, int temporal_bins, double cone_half_angle,
         double depth_bin_width, int depth_bins, double max_path, int threads, const py::object& progress) {
        HomogeneousMedium med;
        med.scattering = scattering;
        med.absorption = absorption;
        med.asymmetry = asymmetry;
        med.time_index = time_index;
        const GrainTraceSettings s = trace_settings(photons, seed, start_opl, bin_width_opl, temporal_bins,
                                                    cone_half_angle, depth_bin_width, depth_bins, max_path, threads);
        return run_traced(progress, [&](const GrainProgress& cb) { return trace_homogeneous(med, s, cb); });
      },
      py::arg("scattering"), py::arg("absorption"), py::arg("asymmetry"), py::arg("time_index"), py::arg("photons"),
      py::arg("seed"), py::arg("start_opl"), py::arg("bin_width_opl"), py::arg("temporal_bins"),
      py::arg("cone_half_angle"), py::arg("depth_bin_width"), py::arg("depth_bins"), py::arg("max_path"),
      py::arg("threads") = 0, py::arg("progress") = py::none(),
      "The same beam and receivers in a homogeneous Henyey–Greenstein half-space (index matched).");
  m.def(
      "grains_scatter_sphere",
      [](double radius, double ice_index, double ice_absorption, std::uint64_t rays, std::uint64_t seed) {
        GrainOptics o;
        o.ice_index = ice_index;
        o.ice_absorption = ice_absorption;
        SphereScatter s;
        {
          py::gil_scoped_release release;
          s = scatter_sphere(radius, o, rays, seed);
        }
        py::dict out;
        out["absorbed"] = s.absorbed;
        out["mean_ice_path"] = s.mean_ice_path;
        out["mean_cos"] = s.mean_cos;
        out["energy_out"] = s.energy_out;
        out["total_internal_reflections"] = s.total_internal_reflections;
        return out;
      },
      py::arg("radius"), py::arg("ice_index"), py::arg("ice_absorption"), py::arg("rays"), py::arg("seed") = 0,
      "One sphere lit over its cross-section: absorbed fraction, ice path and asymmetry g (geometric optics).");
}
