// The beam structures against brute force (DESIGN.md §8): every beam that passes the gather's exact
// test of §4 is reported, once, in ascending order, and nothing that fails it by more than the
// documented slack.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "check.hpp"
#include "ptpb/beam_accel.hpp"
#include "ptpb/beam_geometry.hpp"
#include "ptpb/gather.hpp"
#include "ptpb/rng.hpp"
#include "ptpb/sampling.hpp"

using namespace ptpb;

namespace {

// The gather's acceptance test (gather.hpp), with the structures' near-parallel bound as its guard:
// below it they report beams untested.
bool exact_pair(const Vec3d& o, const Vec3d& d, double t_max, const Beam& b, double radius) {
  const ClosestApproach ca = closest_approach(o, d, b.origin, b.direction);
  return test_beam_pair(ca, t_max, b.length, radius, 1e-4) == PairTest::Inside;
}

std::vector<Beam> random_beams(KeyedRng& rng, int count, double extent, double max_length) {
  std::vector<Beam> beams(count);
  for (Beam& b : beams) {
    b.origin = {extent * rng.next_double(), extent * rng.next_double(), extent * rng.next_double()};
    b.direction = sample_uniform_sphere(rng.next_double(), rng.next_double());
    b.length = max_length * rng.next_double();
  }
  return beams;
}

// Checks every structure on `rays` random segments: complete against brute force, no repeats apart
// from near-parallel beams, and every report within the structure's slack of the exact test: 1e-6
// for the grid (double), and for the BVH's float test the documented bound of kCandidateSlack
// (beam_accel.hpp), its span taken as the query origin's distance to the beams' box centre plus the
// box's half diagonal, t_max and 4R.
void check_structures(const std::vector<Beam>& beams, double radius, int rays, std::uint64_t seed,
                      const std::string& what, const Vec3d& offset = {0, 0, 0}) {
  KeyedRng rng(seed, 0, StreamDomain::Test, 7);
  std::vector<std::unique_ptr<BeamAccel>> accels;
  accels.push_back(make_beam_accel(AccelKind::Embree, 32, 0.0));
  accels.push_back(make_beam_accel(AccelKind::Embree, 32, 3.0 * radius));
  accels.push_back(make_beam_accel(AccelKind::Grid, 16, 0.0));
  accels.push_back(make_beam_accel(AccelKind::Grid, 64, 0.0));
  const std::size_t float_tested = 2;  // the first two: the BVH
  Vec3d lo{1e300, 1e300, 1e300}, hi = lo * -1.0;
  for (const Beam& b : beams)
    for (const Vec3d& p : {b.origin, b.origin + b.direction * b.length})
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], p[a]);
        hi[a] = std::max(hi[a], p[a]);
      }
  const Vec3d centre = (lo + hi) * 0.5;
  const double half_diagonal = 0.5 * length(hi - lo);
  for (auto& accel : accels) {
    accel->build(beams, radius, 2);
    CHECK(accel->radius() == radius);
  }
  int missing = 0, repeated = 0, loose = 0, unsorted = 0, pairs = 0;
  std::vector<std::uint32_t> cand;
  for (int r = 0; r < rays; ++r) {
    const Vec3d o =
        offset + Vec3d{1.2 * rng.next_double() - 0.1, 1.2 * rng.next_double() - 0.1, 1.2 * rng.next_double() - 0.1};
    Vec3d d = sample_uniform_sphere(rng.next_double(), rng.next_double());
    if (r % 7 == 0) d = Vec3d{0, 0, r % 2 ? 1.0 : -1.0};  // axis-parallel rays: zero direction components
    const double t_max = 1.5 * rng.next_double();
    std::vector<std::uint32_t> truth;
    for (std::size_t i = 0; i < beams.size(); ++i)
      if (exact_pair(o, d, t_max, beams[i], radius)) truth.push_back(static_cast<std::uint32_t>(i));
    pairs += int(truth.size());
    const double float_margin = kCandidateSlack * (length(o - centre) + half_diagonal + t_max + 4.0 * radius);
    for (std::size_t k = 0; k < accels.size(); ++k) {
      cand.clear();
      accels[k]->query(o, d, t_max, cand);
      if (!std::is_sorted(cand.begin(), cand.end())) ++unsorted;
      std::vector<std::uint32_t> sorted = cand;
      std::sort(sorted.begin(), sorted.end());
      for (std::size_t i = 1; i < sorted.size(); ++i)
        if (sorted[i] == sorted[i - 1]) {
          const ClosestApproach ca = closest_approach(o, d, beams[sorted[i]].origin, beams[sorted[i]].direction);
          if (ca.sin2 >= 1e-4) ++repeated;
        }
      for (std::uint32_t i : truth)
        if (!std::binary_search(sorted.begin(), sorted.end(), i)) ++missing;
      for (std::uint32_t i : sorted) {
        const ClosestApproach ca = closest_approach(o, d, beams[i].origin, beams[i].direction);
        const double range = k < float_tested ? float_margin / ca.sin2 : 1e-6;
        const double across = k < float_tested ? float_margin / std::sqrt(ca.sin2) : 1e-6 * radius;
        if (ca.sin2 >= 1e-4 && (ca.u > radius + across || ca.t < -range || ca.t > t_max + range || ca.s < -range ||
                                ca.s > beams[i].length + range))
          ++loose;
      }
    }
  }
  if (missing || repeated || loose)
    std::fprintf(stderr, "%s: %d missing, %d repeated, %d loose candidates (%d true pairs)\n", what.c_str(), missing,
                 repeated, loose, pairs);
  CHECK(missing == 0);
  CHECK(repeated == 0);
  CHECK(loose == 0);
  CHECK(unsorted == 0);
  if (pairs == 0) std::fprintf(stderr, "%s: no true pairs to check\n", what.c_str());
  CHECK(pairs > 0);
}

}  // namespace

TEST_CASE("beam structures report exactly the pairs of the exact test, each once") {
  KeyedRng rng(5, 0, StreamDomain::Test, 1);
  check_structures(random_beams(rng, 3000, 1.0, 0.6), 0.03, 400, 1, "random beams");
}

TEST_CASE("queries starting inside a beam's capsule and short queries inside it") {
  // Beams through one point; query segments that start within R of all of them, some shorter than R.
  std::vector<Beam> beams;
  KeyedRng rng(9, 0, StreamDomain::Test, 2);
  for (int i = 0; i < 200; ++i) {
    Beam b;
    b.direction = sample_uniform_sphere(rng.next_double(), rng.next_double());
    b.origin = Vec3d{0.5, 0.5, 0.5} - b.direction * 0.3;
    b.length = 0.6;
    beams.push_back(b);
  }
  const double radius = 0.05;
  auto accel = make_beam_accel(AccelKind::Embree, 32, 0.0);
  auto grid = make_beam_accel(AccelKind::Grid, 16, 0.0);
  accel->build(beams, radius, 1);
  grid->build(beams, radius, 1);
  std::vector<std::uint32_t> cand;
  for (int r = 0; r < 100; ++r) {
    const Vec3d d = sample_uniform_sphere(rng.next_double(), rng.next_double());
    const Vec3d o =
        Vec3d{0.5, 0.5, 0.5} + sample_uniform_sphere(rng.next_double(), rng.next_double()) * (0.01 * rng.next_double());
    const double t_max = r % 2 ? 0.02 : 0.3;
    for (BeamAccel* a : {accel.get(), grid.get()}) {
      cand.clear();
      a->query(o, d, t_max, cand);
      std::sort(cand.begin(), cand.end());
      for (std::size_t i = 0; i < beams.size(); ++i)
        if (exact_pair(o, d, t_max, beams[i], radius))
          CHECK(std::binary_search(cand.begin(), cand.end(), std::uint32_t(i)));
    }
  }
}

TEST_CASE("degenerate beams: identical, zero length, axis-aligned, far from the origin") {
  std::vector<Beam> beams;
  for (int i = 0; i < 5000; ++i) {  // one beam repeated: no SAH split separates them
    Beam b;
    b.origin = {0.2, 0.3, 0.4};
    b.direction = {1, 0, 0};
    b.length = 0.5;
    beams.push_back(b);
  }
  Beam point;
  point.origin = {0.5, 0.5, 0.5};
  point.direction = {0, 1, 0};
  point.length = 0.0;
  beams.push_back(point);
  check_structures(beams, 0.1, 300, 3, "identical beams");
  KeyedRng rng(21, 0, StreamDomain::Test, 4);
  check_structures(random_beams(rng, 500, 1.0, 0.5), 0.01, 200, 4, "small radius");
  // 1 km from the origin: float boxes and rays lose 6e-5 m there, which the box margin must cover.
  std::vector<Beam> far = random_beams(rng, 1000, 1.0, 0.5);
  const Vec3d offset{1000.0, -700.0, 300.0};
  for (Beam& b : far) b.origin = b.origin + offset;
  check_structures(far, 0.01, 200, 5, "far from the origin", offset);
}

TEST_CASE("automatic dicing: a few R, but about two pieces a beam at most") {
  KeyedRng rng(31, 0, StreamDomain::Test, 6);
  // Long beams at a small R (the cube of DESIGN.md §10 test 4): 6R would cut each into ~13 pieces.
  std::vector<Beam> beams = random_beams(rng, 2000, 1.0, 1.6);  // mean length 0.8 m
  auto accel = make_beam_accel(AccelKind::Embree, 32, 0.0);
  accel->build(beams, 0.01, 2);
  const double per_beam = double(accel->references()) / beams.size();
  std::fprintf(stderr, "long beams: %.2f pieces a beam\n", per_beam);
  CHECK(per_beam >= 1.0 && per_beam <= 3.0);  // ceil(L / (mean L / 2)) averages 2.5 here
  // An explicit piece length is kept: 3R = 3 cm gives ~27 pieces a beam.
  auto fine = make_beam_accel(AccelKind::Embree, 32, 0.03);
  fine->build(beams, 0.01, 2);
  CHECK(double(fine->references()) / beams.size() > 20.0);
  // Short beams at a large R keep one piece each.
  std::vector<Beam> short_beams = random_beams(rng, 2000, 1.0, 0.1);
  accel->build(short_beams, 0.05, 2);
  CHECK(accel->references() == short_beams.size());
  check_structures(beams, 0.01, 200, 8, "long beams, automatic pieces");
}

TEST_CASE("empty structures answer nothing") {
  for (AccelKind kind : {AccelKind::Embree, AccelKind::Grid}) {
    auto accel = make_beam_accel(kind, 8, 0.0);
    accel->build({}, 0.1, 1);
    std::vector<std::uint32_t> cand;
    accel->query({0, 0, 0}, {1, 0, 0}, 1.0, cand);
    CHECK(cand.empty());
    CHECK(accel->references() == 0);
  }
}

PTPB_TEST_MAIN()
