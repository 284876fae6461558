// Python bindings of the Embree ray engine: batched intersect/occluded on numpy arrays.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>

#include "ptpb/ray_engine.hpp"

namespace py = pybind11;

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using IndexArray = py::array_t<std::uint32_t, py::array::c_style | py::array::forcecast>;

void require_n_by_3(const py::array& a, const char* name) {
  if (a.ndim() != 2 || a.shape(1) != 3) {
    throw py::value_error(std::string(name) + " must have shape (N, 3), got ndim=" + std::to_string(a.ndim()));
  }
}

struct RayBatch {
  FloatArray origins, directions, tfar;
  std::size_t n = 0;
  bool has_tfar = false;
};

RayBatch check_rays(const FloatArray& origins, const FloatArray& directions, const py::object& tfar) {
  require_n_by_3(origins, "origins");
  require_n_by_3(directions, "directions");
  if (origins.shape(0) != directions.shape(0)) {
    throw py::value_error("origins and directions must have the same number of rows (" +
                          std::to_string(origins.shape(0)) + " vs " + std::to_string(directions.shape(0)) + ")");
  }
  RayBatch batch{origins, directions, FloatArray(), static_cast<std::size_t>(origins.shape(0))};
  if (!tfar.is_none()) {
    batch.tfar = tfar.cast<FloatArray>();
    if (batch.tfar.ndim() != 1 || static_cast<std::size_t>(batch.tfar.shape(0)) != batch.n) {
      throw py::value_error("tfar must have shape (N,) matching the rays");
    }
    batch.has_tfar = true;
  }
  return batch;
}

}  // namespace

void register_raytrace(py::module_& m) {
  py::class_<ptpb::RayScene>(m, "RayScene", "Triangle meshes traced by Embree 3. Add meshes, commit, then query.")
      .def(py::init<>())
      .def(
          "add_mesh",
          [](ptpb::RayScene& self, const FloatArray& vertices, const IndexArray& faces, std::uint32_t mesh_id) {
            require_n_by_3(vertices, "vertices");
            require_n_by_3(faces, "faces");
            self.add_mesh(vertices.data(), static_cast<std::size_t>(vertices.shape(0)), faces.data(),
                          static_cast<std::size_t>(faces.shape(0)), mesh_id);
          },
          py::arg("vertices"), py::arg("faces"), py::arg("mesh_id"))
      .def(
          "add_instanced_mesh",
          [](ptpb::RayScene& self, const FloatArray& vertices, const IndexArray& faces,
             const py::array_t<double, py::array::c_style | py::array::forcecast>& offsets, std::uint32_t mesh_id) {
            require_n_by_3(vertices, "vertices");
            require_n_by_3(faces, "faces");
            require_n_by_3(offsets, "offsets");
            self.add_instanced_mesh(vertices.data(), static_cast<std::size_t>(vertices.shape(0)), faces.data(),
                                    static_cast<std::size_t>(faces.shape(0)), offsets.data(),
                                    static_cast<std::size_t>(offsets.shape(0)), mesh_id);
          },
          py::arg("vertices"), py::arg("faces"), py::arg("offsets"), py::arg("mesh_id"))
      .def("commit", &ptpb::RayScene::commit, py::call_guard<py::gil_scoped_release>())
      .def_property_readonly("committed", &ptpb::RayScene::committed)
      .def_property_readonly("mesh_count", &ptpb::RayScene::mesh_count)
      .def_property_readonly("triangle_count", &ptpb::RayScene::triangle_count)
      .def_property_readonly("placed_triangle_count", &ptpb::RayScene::placed_triangle_count)
      .def_property_readonly("bounds",
                             [](const ptpb::RayScene& self) {
                               const auto b = self.bounds();
                               return py::make_tuple(py::make_tuple(b.lower.x, b.lower.y, b.lower.z),
                                                     py::make_tuple(b.upper.x, b.upper.y, b.upper.z));
                             })
      .def(
          "intersect",
          [](const ptpb::RayScene& self, const FloatArray& origins, const FloatArray& directions, float tnear,
             const py::object& tfar, int threads) {
            if (!self.committed()) throw std::logic_error("commit() the scene before intersect()");
            RayBatch batch = check_rays(origins, directions, tfar);
            const auto n = static_cast<py::ssize_t>(batch.n);
            FloatArray t_out(n);
            IndexArray prim_out(n), mesh_out(n);
            FloatArray normal_out({n, static_cast<py::ssize_t>(3)});
            float* t_ptr = t_out.mutable_data();
            std::uint32_t* prim_ptr = prim_out.mutable_data();
            std::uint32_t* mesh_ptr = mesh_out.mutable_data();
            float* normal_ptr = normal_out.mutable_data();
            {
              py::gil_scoped_release release;
              self.intersect_batch(batch.origins.data(), batch.directions.data(), batch.n, tnear,
                                   batch.has_tfar ? batch.tfar.data() : nullptr, t_ptr, prim_ptr, mesh_ptr, normal_ptr,
                                   threads);
            }
            return py::make_tuple(t_out, prim_out, mesh_out, normal_out);
          },
          py::arg("origins"), py::arg("directions"), py::arg("tnear") = 0.0f, py::arg("tfar") = py::none(),
          py::arg("threads") = 0)
      .def(
          "occluded",
          [](const ptpb::RayScene& self, const FloatArray& origins, const FloatArray& directions, float tnear,
             const py::object& tfar, int threads) {
            if (!self.committed()) throw std::logic_error("commit() the scene before occluded()");
            RayBatch batch = check_rays(origins, directions, tfar);
            py::array_t<bool> out(static_cast<py::ssize_t>(batch.n));
            bool* out_ptr = out.mutable_data();
            {
              py::gil_scoped_release release;
              self.occluded_batch(batch.origins.data(), batch.directions.data(), batch.n, tnear,
                                  batch.has_tfar ? batch.tfar.data() : nullptr, out_ptr, threads);
            }
            return out;
          },
          py::arg("origins"), py::arg("directions"), py::arg("tnear") = 0.0f, py::arg("tfar") = py::none(),
          py::arg("threads") = 0);
  m.attr("INVALID_ID") = ptpb::kInvalidId;
}
