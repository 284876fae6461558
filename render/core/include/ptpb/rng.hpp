// Keyed counter-based random streams: every stream is a pure function of (seed, iteration,
// domain, index), so results never depend on threads or on the order of work (DESIGN.md §9).
#pragma once
#include <cstdint>

namespace ptpb {

enum class StreamDomain : std::uint32_t {
  LightPath = 1,
  CameraPixel = 2,
  Test = 3,
  PathSplit = 4,
  HopTable = 5,
  Grains = 6
};

// SplitMix64 finaliser: a bijective avalanche mix, used to hash the key into a PCG state.
inline std::uint64_t mix64(std::uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// PCG32 (XSH-RR) whose state and stream increment are hashes of the key.
class KeyedRng {
 public:
  KeyedRng(std::uint64_t seed, std::uint64_t iteration, StreamDomain domain, std::uint64_t index) {
    const std::uint64_t k1 = mix64(seed ^ mix64(iteration + 0x632BE59BD9B4E019ull));
    const std::uint64_t k2 = mix64(k1 ^ mix64((static_cast<std::uint64_t>(domain) << 56) ^ index));
    inc_ = (mix64(k2 ^ 0xD1B54A32D192ED03ull) << 1u) | 1u;
    state_ = 0;
    next_u32();
    state_ += k2;
    next_u32();
  }

  std::uint32_t next_u32() {
    const std::uint64_t old = state_;
    state_ = old * 6364136223846793005ull + inc_;
    const auto xorshifted = static_cast<std::uint32_t>(((old >> 18u) ^ old) >> 27u);
    const auto rot = static_cast<std::uint32_t>(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
  }

  // 64 random bits: the key of a stream derived from this one (a split path's copy, DESIGN.md §12).
  std::uint64_t next_u64() {
    const std::uint64_t hi = next_u32(), lo = next_u32();
    return (hi << 32) | lo;
  }

  // Uniform double in [0, 1) with 53 random bits.
  double next_double() {
    const std::uint64_t hi = next_u32(), lo = next_u32();
    return static_cast<double>(((hi << 32) | lo) >> 11) * (1.0 / 9007199254740992.0);
  }

 private:
  std::uint64_t state_ = 0, inc_ = 1;
};

}  // namespace ptpb
