// Acceleration structures for ray–beam queries (DESIGN.md §8), rebuilt every iteration: a uniform
// grid of diced beam pieces (SmallUPBP style) and a 4-wide BVH over the same pieces (Embree's BVH
// builder, our traversal). Both run the exact closest-approach test themselves and return each beam
// that can pass it once; the caller still sorts, deduplicates and runs its own exact test.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "ptpb/beams.hpp"

namespace ptpb {

// The BVH tests pieces in float. What it reports passes the exact test once t and s are widened by
// kCandidateSlack * span / sin^2 and u by kCandidateSlack * span / sin, where span bounds the
// distance from the query's origin to the beams plus t_max and 4R; the gather's own test in double
// then decides. The grid tests in double, a hair (1e-9 of the scene) looser.
constexpr double kCandidateSlack = 1e-5;

class BeamAccel {
 public:
  virtual ~BeamAccel() = default;
  // radius: the kernel radius R_i every box is inflated by.
  virtual void build(const std::vector<Beam>& beams, double radius, int threads) = 0;
  // Appends the indices of the beams whose closest approach to origin + t dir lies within R, with t in
  // [0, t_max] and s in [0, length] (a hair looser than the exact test, never tighter: see
  // kCandidateSlack), each once, and of the near-parallel beams (sin^2 < 1e-4), possibly repeated
  // (grid); the appended indices are sorted. Thread-safe.
  virtual void query(const Vec3d& origin, const Vec3d& direction, double t_max,
                     std::vector<std::uint32_t>& candidates) const = 0;
  virtual std::uint64_t references() const = 0;  // stored cell references or pieces
  virtual double radius() const = 0;             // the radius the structure was built with
};

// grid_resolution: cells along the longest axis; dice_length: piece length for the BVH (0 = auto).
std::unique_ptr<BeamAccel> make_beam_accel(AccelKind kind, int grid_resolution, double dice_length);

}  // namespace ptpb
