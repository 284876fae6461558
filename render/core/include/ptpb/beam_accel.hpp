// Acceleration structures for ray–beam queries (ptpb.md §8), rebuilt every iteration: a uniform
// grid of diced beam pieces (SmallUPBP style) and an Embree BVH over the same pieces as user
// geometry. Both return candidate beam indices; the caller sorts, deduplicates and runs the
// exact closest-approach test.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "ptpb/beams.hpp"

namespace ptpb {

class BeamAccel {
 public:
  virtual ~BeamAccel() = default;
  // radius: the kernel radius R_i every box is inflated by.
  virtual void build(const std::vector<Beam>& beams, double radius, int threads) = 0;
  // Appends (possibly repeated) indices of beams that may lie within R of origin + t dir, t in [0, t_max].
  virtual void query(const Vec3d& origin, const Vec3d& direction, double t_max,
                     std::vector<std::uint32_t>& candidates) const = 0;
  virtual std::uint64_t references() const = 0;  // stored cell references or pieces
  virtual double radius() const = 0;             // the radius the structure was built with
};

// grid_resolution: cells along the longest axis; dice_length: piece length for the BVH (0 = auto).
std::unique_ptr<BeamAccel> make_beam_accel(AccelKind kind, int grid_resolution, double dice_length);

}  // namespace ptpb
