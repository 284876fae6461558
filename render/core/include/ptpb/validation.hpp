// Checks before a render (DESIGN.md §9): settings and resume states that would fail, and films whose
// image buffers would not fit the memory budget. Each refusal is a std::invalid_argument that names
// the parameter and how to fix it.
#pragma once
#include "ptpb/render.hpp"

namespace ptpb {

// Throws std::invalid_argument naming the first setting out of range.
void validate_settings(const RenderSettings& settings);

// A resume state must belong to this film (W x H, F frames), seed and bandwidth schedule.
void validate_resume(const RenderState& state, const Scene& scene, const RenderSettings& settings, int W, int H, int F);

// Peak bytes of render()'s image buffers (§9 "Memory"): the double sums of steady, early and late
// (H W 3 each), the float32 frame sums (F H W 3; twice that with the remainders of a run past
// settings.compensated_sums_from iterations or on a time budget), one tile buffer per thread, the float32
// results (the frames are scaled in place, not copied) and the float32 steady snapshots. With
// `state_copy` (a checkpoint callback or a resume state) one more copy of the sums and snapshots.
// Frames are never split into chunks: every ray-beam pair splats into all the frames its kernel
// covers within one pass, so a film that does not fit is refused instead.
double render_memory_bytes(const Scene& scene, const RenderSettings& settings, bool state_copy);

// Throws std::invalid_argument, naming the keys that shrink the film or raise the budget, when
// render_memory_bytes exceeds settings.memory_budget_gib; render() calls it before allocating.
void check_memory_budget(const Scene& scene, const RenderSettings& settings, bool state_copy);

}  // namespace ptpb
