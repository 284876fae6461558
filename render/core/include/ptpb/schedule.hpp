// The progressive bandwidth schedule (ptpb.md §6): the kernel radii and temporal half-widths of
// iteration i, for beams and for surface photons.
#pragma once
#include "ptpb/scene.hpp"
#include "ptpb/settings.hpp"

namespace ptpb {

// Bandwidths of iteration i for a film mode (§6): gate shrinks R and T with gamma^(1/2),
// bins/steady shrink R with gamma.
void iteration_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                          double& time_half_width);

// The surface photons' schedule parameter: surface_alpha, or alpha* = 4/(d + 4) for the disk
// (d = 2) in bins/steady and the disk x time kernel (d = 3) in gate mode (§6).
double surface_schedule_alpha(FrameMode mode, const RenderSettings& s);

// Surface bandwidths of iteration i (§6): the kernel volume r^2 (bins/steady) or r^2 T (gate)
// follows gamma_i, so r_i = r_0 gamma^(1/2) in bins/steady, and r_i = r_0 gamma^(1/3),
// T_i = T_0 gamma^(1/3) in gate mode, where space and time shrink at the same rate.
void surface_bandwidths(FrameMode mode, const RenderSettings& s, long iteration, double& radius,
                        double& time_half_width);

}  // namespace ptpb
