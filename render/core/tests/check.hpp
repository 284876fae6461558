// A minimal test harness for the core's ctest executables: CHECK macros that count failures and
// print where they happened, and a main() epilogue that turns failures into an exit code.
#pragma once
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace ptpb_test {

inline int& failure_count() {
  static int n = 0;
  return n;
}
inline std::vector<std::pair<std::string, std::function<void()>>>& registry() {
  static std::vector<std::pair<std::string, std::function<void()>>> r;
  return r;
}
struct Register {
  Register(const char* name, std::function<void()> fn) { registry().emplace_back(name, std::move(fn)); }
};
inline void fail(const char* file, int line, const std::string& what) {
  ++failure_count();
  std::fprintf(stderr, "%s:%d: FAILED: %s\n", file, line, what.c_str());
}
inline bool close_rel(double a, double b, double rel) {
  return std::fabs(a - b) <= rel * std::max(std::fabs(a), std::fabs(b)) || a == b;
}

}  // namespace ptpb_test

#define PTPB_CONCAT2(a, b) a##b
#define PTPB_CONCAT(a, b) PTPB_CONCAT2(a, b)
#define TEST_CASE(name)                                                                               \
  static void PTPB_CONCAT(test_fn_, __LINE__)();                                                      \
  static ptpb_test::Register PTPB_CONCAT(test_reg_, __LINE__)(name, PTPB_CONCAT(test_fn_, __LINE__)); \
  static void PTPB_CONCAT(test_fn_, __LINE__)()

#define CHECK(cond)                                          \
  do {                                                       \
    if (!(cond)) ptpb_test::fail(__FILE__, __LINE__, #cond); \
  } while (0)
#define CHECK_CLOSE(a, b, rel)                                                                             \
  do {                                                                                                     \
    const double va_ = (a), vb_ = (b);                                                                     \
    if (!ptpb_test::close_rel(va_, vb_, (rel)))                                                            \
      ptpb_test::fail(__FILE__, __LINE__,                                                                  \
                      std::string(#a " ~ " #b ": ") + std::to_string(va_) + " vs " + std::to_string(vb_)); \
  } while (0)
#define CHECK_NEAR(a, b, abs_tol)                                                                          \
  do {                                                                                                     \
    const double va_ = (a), vb_ = (b);                                                                     \
    if (!(std::fabs(va_ - vb_) <= (abs_tol)))                                                              \
      ptpb_test::fail(__FILE__, __LINE__,                                                                  \
                      std::string(#a " ~ " #b ": ") + std::to_string(va_) + " vs " + std::to_string(vb_)); \
  } while (0)
#define CHECK_THROWS(expr)                                                             \
  do {                                                                                 \
    bool threw_ = false;                                                               \
    try {                                                                              \
      (void)(expr);                                                                    \
    } catch (...) {                                                                    \
      threw_ = true;                                                                   \
    }                                                                                  \
    if (!threw_) ptpb_test::fail(__FILE__, __LINE__, "expected an exception: " #expr); \
  } while (0)

#define PTPB_TEST_MAIN()                                                                              \
  int main() {                                                                                        \
    for (auto& [name, fn] : ptpb_test::registry()) {                                                  \
      const int before = ptpb_test::failure_count();                                                  \
      try {                                                                                           \
        fn();                                                                                         \
      } catch (const std::exception& e) {                                                             \
        ptpb_test::fail(__FILE__, __LINE__, std::string("exception: ") + e.what());                   \
      }                                                                                               \
      std::printf("[%s] %s\n", ptpb_test::failure_count() == before ? "pass" : "FAIL", name.c_str()); \
    }                                                                                                 \
    return ptpb_test::failure_count() == 0 ? 0 : 1;                                                   \
  }
