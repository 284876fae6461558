// The progressive bandwidth schedule (DESIGN.md §6): the kernel radii and temporal half-widths of
// iteration i, for beams and for surface photons.
#pragma once
#include "ptpb/scene.hpp"
#include "ptpb/settings.hpp"

namespace ptpb {

// The bandwidth schedule with every default resolved: what a render runs and reports in its stats.
// The core owns these defaults; callers leave a setting unset to get them.
struct Schedule {
  double alpha = 0.0;                            // beams' kernel-volume parameter
  double initial_beam_radius = 0.0;              // R_0, m
  double initial_time_half_width = 0.0;          // T_0, m of OPL (gate mode)
  double surface_alpha = 0.0;                    // surface photons' kernel-volume parameter
  double initial_surface_radius = 0.0;           // r_0, m
  double initial_surface_time_half_width = 0.0;  // m of OPL (gate mode)
};

// The beams' schedule parameter: alpha, or alpha* = 4/(d + 4) for the 1-D kernel across a beam
// (d = 1) in bins/steady and that kernel x time (d = 2) in gate mode: 4/5 and 2/3 (§6).
double beam_schedule_alpha(FrameMode mode, const RenderSettings& s);

// The surface photons' schedule parameter: surface_alpha, or alpha* = 4/(d + 4) for the disk
// (d = 2) in bins/steady and the disk x time kernel (d = 3) in gate mode (§6).
double surface_schedule_alpha(FrameMode mode, const RenderSettings& s);

// Every default of the schedule resolved for a film mode: the alphas above; T_0 and r_0 fall back to
// R_0, and the surfaces' T_0 to the beams' T_0.
Schedule resolve_schedule(FrameMode mode, const RenderSettings& s);

// Bandwidths of iteration i for a film mode (§6): gate shrinks R and T with gamma^(1/2),
// bins/steady shrink R with gamma.
void iteration_bandwidths(FrameMode mode, const Schedule& s, long iteration, double& radius, double& time_half_width);

// Surface bandwidths of iteration i (§6): the kernel volume r^2 (bins/steady) or r^2 T (gate)
// follows gamma_i, so r_i = r_0 gamma^(1/2) in bins/steady, and r_i = r_0 gamma^(1/3),
// T_i = T_0 gamma^(1/3) in gate mode, where space and time shrink at the same rate.
void surface_bandwidths(FrameMode mode, const Schedule& s, long iteration, double& radius, double& time_half_width);

}  // namespace ptpb
