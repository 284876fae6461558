// The progressive bandwidth schedule (ptpb.md §6).
#include "ptpb/schedule.hpp"

#include <cmath>

#include "ptpb/kernels.hpp"

namespace ptpb {

void iteration_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                          double& time_half_width) {
  const double gamma = schedule_gamma(iteration, s.alpha);
  if (mode == FrameMode::Gate) {
    radius = s.initial_beam_radius * std::sqrt(gamma);
    time_half_width = s.initial_time_half_width * std::sqrt(gamma);
  } else {
    radius = s.initial_beam_radius * gamma;
    time_half_width = s.initial_time_half_width;
  }
}

double surface_schedule_alpha(FrameMode mode, const RenderSettings& s) {
  if (s.surface_alpha) return *s.surface_alpha;
  return mode == FrameMode::Gate ? 4.0 / 7.0 : 2.0 / 3.0;
}

void surface_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                        double& time_half_width) {
  const double gamma = schedule_gamma(iteration, surface_schedule_alpha(mode, s));
  const double t0 = s.initial_surface_time_half_width.value_or(s.initial_time_half_width);
  if (mode == FrameMode::Gate) {
    const double shrink = std::cbrt(gamma);
    radius = s.initial_surface_radius * shrink;
    time_half_width = t0 * shrink;
  } else {
    radius = s.initial_surface_radius * std::sqrt(gamma);
    time_half_width = t0;
  }
}

}  // namespace ptpb
