// Normalised density-estimation kernels and the progressive bandwidth schedule (DESIGN.md §4–§7).
#pragma once
#include <cmath>
#include <stdexcept>

#include "ptpb/sampling.hpp"

namespace ptpb {

enum class SpatialKernel { Box, Epanechnikov };
enum class TemporalKernel { Box, Epanechnikov, Quintic };

// 1D kernel over the signed distance u in [-R, R]; integrates to 1.
inline double spatial_kernel_1d(SpatialKernel k, double u, double radius) {
  const double x = std::fabs(u) / radius;
  if (!(x <= 1.0)) return 0.0;
  if (k == SpatialKernel::Box) return 0.5 / radius;
  return 0.75 / radius * (1.0 - x * x);
}

// 2D disk kernel of the distance rho in [0, r]; integrates to 1 over the disk.
inline double spatial_kernel_2d(SpatialKernel k, double rho, double radius) {
  const double x = rho / radius;
  if (!(x <= 1.0)) return 0.0;
  if (k == SpatialKernel::Box) return 1.0 / (kPi * radius * radius);
  return 2.0 / (kPi * radius * radius) * (1.0 - x * x);
}

// Two-sided temporal kernel of the OPL offset delta with half-width T; integrates to 1.
inline double temporal_kernel(TemporalKernel k, double delta, double half_width) {
  const double x = std::fabs(delta) / half_width;
  if (!(x <= 1.0)) return 0.0;
  switch (k) {
    case TemporalKernel::Box: return 0.5 / half_width;
    case TemporalKernel::Epanechnikov: return 0.75 / half_width * (1.0 - x * x);
    case TemporalKernel::Quintic: {
      const double x3 = x * x * x;
      return (1.0 - 6.0 * x3 * x * x + 15.0 * x3 * x - 10.0 * x3) / half_width;
    }
  }
  return 0.0;
}

// Kernel-volume factor gamma_i = prod_{k=1..i} (k + alpha) / (k + 1), gamma_0 = 1 (§6).
inline double schedule_gamma(long iteration, double alpha) {
  if (iteration < 0) throw std::invalid_argument("schedule_gamma: iteration must be >= 0");
  if (!(alpha > 0.0 && alpha <= 1.0)) throw std::invalid_argument("alpha must lie in (0, 1]");
  // lgamma closed form keeps large i exact to ~1e-13 without a product over i terms.
  return std::exp(std::lgamma(iteration + 1.0 + alpha) - std::lgamma(1.0 + alpha) - std::lgamma(iteration + 2.0));
}

}  // namespace ptpb
