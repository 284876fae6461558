// The progressive bandwidth schedule (DESIGN.md §6).
#include "ptpb/schedule.hpp"

#include <cmath>

#include "ptpb/kernels.hpp"

namespace ptpb {

double beam_schedule_alpha(FrameMode mode, const RenderSettings& s) {
  if (s.alpha) return *s.alpha;
  return mode == FrameMode::Gate ? 2.0 / 3.0 : 4.0 / 5.0;
}

double surface_schedule_alpha(FrameMode mode, const RenderSettings& s) {
  if (s.surface_alpha) return *s.surface_alpha;
  return mode == FrameMode::Gate ? 4.0 / 7.0 : 2.0 / 3.0;
}

Schedule resolve_schedule(FrameMode mode, const RenderSettings& s) {
  Schedule r;
  r.alpha = beam_schedule_alpha(mode, s);
  r.initial_beam_radius = s.initial_beam_radius;
  r.initial_time_half_width = s.initial_time_half_width.value_or(s.initial_beam_radius);
  r.surface_alpha = surface_schedule_alpha(mode, s);
  r.initial_surface_radius = s.initial_surface_radius.value_or(s.initial_beam_radius);
  r.initial_surface_time_half_width = s.initial_surface_time_half_width.value_or(r.initial_time_half_width);
  return r;
}

void iteration_bandwidths(FrameMode mode, const Schedule& s, long iteration, double& radius, double& time_half_width) {
  const double gamma = schedule_gamma(iteration, s.alpha);
  if (mode == FrameMode::Gate) {
    radius = s.initial_beam_radius * std::sqrt(gamma);
    time_half_width = s.initial_time_half_width * std::sqrt(gamma);
  } else {
    radius = s.initial_beam_radius * gamma;
    time_half_width = s.initial_time_half_width;
  }
}

void surface_bandwidths(FrameMode mode, const Schedule& s, long iteration, double& radius, double& time_half_width) {
  const double gamma = schedule_gamma(iteration, s.surface_alpha);
  const double t0 = s.initial_surface_time_half_width;
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
