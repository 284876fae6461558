// The beam structures' factory (DESIGN.md §8): one structure per source file, beam_grid.cpp and
// beam_bvh.cpp, behind the BeamAccel interface (as pbrt-v4's CreateAccelerator).
#include "ptpb/beam_accel.hpp"

#include "beam_accel_shared.hpp"

namespace ptpb {

std::unique_ptr<BeamAccel> make_beam_accel(AccelKind kind, int grid_resolution, double dice_length) {
  if (kind == AccelKind::Embree) return accel_detail::make_beam_bvh(dice_length);
  return accel_detail::make_beam_grid(grid_resolution);
}

}  // namespace ptpb
