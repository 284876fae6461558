// The private extension module render._core. Each topic registers itself from its own file.
#include <pybind11/pybind11.h>

namespace py = pybind11;

void register_raytrace(py::module_& m);
void register_ptpb(py::module_& m);
void register_grains(py::module_& m);

PYBIND11_MODULE(_core, m) {
  m.doc() = "C++ core of the penitentes renderer: Embree ray engine and the PTPB renderer.";
  register_raytrace(m);
  register_ptpb(m);
  register_grains(m);
}
