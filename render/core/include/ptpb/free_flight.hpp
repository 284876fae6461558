// Free flights in homogeneous media and Russian roulette (DESIGN.md §3), shared by light and camera
// tracing.
#pragma once
#include <algorithm>
#include <cmath>
#include <limits>

#include "ptpb/rng.hpp"
#include "ptpb/vec.hpp"

namespace ptpb {

// Russian roulette keeps a path with probability min(kMaxSurvival, throughput ratio) on both
// sides, as Mitsuba's volpath does: a lossless medium (albedo 1) or total internal reflection
// would otherwise keep q = 1 and a path alive without bound.
constexpr double kMaxSurvival = 0.95;

// Exponential free-flight helpers shared by light and camera tracing.
inline Vec3d transmittance(const Vec3d& sigma_t, double s) {
  return {std::exp(-sigma_t.x * s), std::exp(-sigma_t.y * s), std::exp(-sigma_t.z * s)};
}

// The throughput-weighted mixture of the path tracer (DESIGN.md §12, "Chromatic media"): channel c is picked
// with probability prob_c = w_c / (w_x + w_y + w_z), w the path's throughput, so that the sum of the
// throughput's channels never grows over a flight (sigma_s <= sigma_t): no channel can run away over many
// collisions in a medium whose extinction differs between channels.
constexpr Vec3d kUniformChannels{1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0};
inline Vec3d channel_probabilities(const Vec3d& w) {
  const double sum = w.x + w.y + w.z;
  return sum > 0 ? w / sum : kUniformChannels;
}
// The channel that a uniform u in [0, 1) picks with probabilities `prob`.
inline int pick_channel(const Vec3d& prob, double u) {
  const int channel = u < prob.x ? 0 : (u < prob.x + prob.y ? 1 : 2);
  if (!(prob[channel] > 0)) return prob.y > 0 ? 1 : 0;  // rounding at the top of the unit interval
  return channel;
}
// A channel picked with probabilities `prob`, then its exponential; infinite for a channel without
// extinction (whose second draw is then not made).
inline double sample_free_flight(const Vec3d& sigma_t, const Vec3d& prob, KeyedRng& rng) {
  const int channel = pick_channel(prob, rng.next_double());
  if (!(sigma_t[channel] > 0)) return std::numeric_limits<double>::infinity();
  return -std::log1p(-rng.next_double()) / sigma_t[channel];
}
// A free-flight distance drawn from §3's channel mixture, the channel picked uniformly.
inline double sample_free_flight(const Vec3d& sigma_t, KeyedRng& rng) {
  return sample_free_flight(sigma_t, kUniformChannels, rng);
}
inline double survival_mixture(const Vec3d& tr, const Vec3d& prob) {
  return prob.x * tr.x + prob.y * tr.y + prob.z * tr.z;
}
inline double pdf_mixture(const Vec3d& sigma_t, const Vec3d& tr, const Vec3d& prob) {
  return prob.x * sigma_t.x * tr.x + prob.y * sigma_t.y * tr.y + prob.z * sigma_t.z * tr.z;
}
// The same for §3's uniform pick, from a transmittance already computed (no further exponentials).
inline double survival_mixture(const Vec3d& tr) { return survival_mixture(tr, kUniformChannels); }
inline double pdf_mixture(const Vec3d& sigma_t, const Vec3d& tr) { return pdf_mixture(sigma_t, tr, kUniformChannels); }
// ... and at a distance s (§3's channel-average mixture).
inline double survival_mixture(const Vec3d& sigma_t, double s) { return survival_mixture(transmittance(sigma_t, s)); }
inline double pdf_mixture(const Vec3d& sigma_t, double s) { return pdf_mixture(sigma_t, transmittance(sigma_t, s)); }

// Distance at which the largest channel transmittance reaches `cutoff`.
inline double cutoff_distance(const Vec3d& sigma_t, double cutoff) {
  const double smallest = std::min(sigma_t.x, std::min(sigma_t.y, sigma_t.z));
  if (!(smallest > 0.0) || !(cutoff > 0.0)) return std::numeric_limits<double>::infinity();
  return -std::log(cutoff) / smallest;
}

}  // namespace ptpb
