// Photon beams in memory order (DESIGN.md §9): a Morton sort of their midpoints.
#include <algorithm>
#include <cstdint>
#include <limits>
#include <utility>

#include "ptpb/beams.hpp"
#include "ptpb/parallel.hpp"

namespace ptpb {

namespace {

// The 10 bits of v spread to every third bit of a 30-bit Morton code.
std::uint32_t spread_bits(std::uint32_t v) {
  v &= 0x3FFu;
  v = (v | (v << 16)) & 0x030000FFu;
  v = (v | (v << 8)) & 0x0300F00Fu;
  v = (v | (v << 4)) & 0x030C30C3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

}  // namespace

void sort_beams_spatially(std::vector<Beam>& beams, int threads) {
  const std::size_t n = beams.size();
  if (n < 2 || n > std::numeric_limits<std::uint32_t>::max()) return;
  const double inf = std::numeric_limits<double>::infinity();
  Vec3d lo{inf, inf, inf}, hi{-inf, -inf, -inf};
  auto midpoint = [](const Beam& b) { return b.origin + b.direction * (0.5 * b.length); };
  for (const Beam& b : beams) {
    const Vec3d m = midpoint(b);
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], m[a]);
      hi[a] = std::max(hi[a], m[a]);
    }
  }
  // (Morton code << 32) | index: sorting the keys sorts by code, then by the previous order.
  std::vector<std::uint64_t> keys(n);
  parallel_for_chunks(n, 8192, threads, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) {
      const Vec3d m = midpoint(beams[i]);
      std::uint32_t code = 0;
      for (int a = 0; a < 3; ++a) {
        const double extent = hi[a] - lo[a];
        const double f = extent > 0 ? (m[a] - lo[a]) / extent : 0.0;
        code |= spread_bits(static_cast<std::uint32_t>(std::clamp(f * 1024.0, 0.0, 1023.0))) << a;
      }
      keys[i] = (std::uint64_t(code) << 32) | i;
    }
  });
  std::sort(keys.begin(), keys.end());
  // Slot i receives beam keys[i]'s low half: follow each cycle of the permutation, moving one
  // record at a time; a filled slot's key is marked done.
  constexpr std::uint64_t kDone = ~std::uint64_t(0);
  for (std::size_t start = 0; start < n; ++start) {
    if (keys[start] == kDone) continue;
    std::size_t slot = start;
    Beam held = std::move(beams[start]);
    for (;;) {
      const std::size_t from = static_cast<std::uint32_t>(keys[slot]);
      keys[slot] = kDone;
      if (from == start) {
        beams[slot] = std::move(held);
        break;
      }
      beams[slot] = std::move(beams[from]);
      slot = from;
    }
  }
}

}  // namespace ptpb
