// Deterministic work splitting: work is cut into fixed chunks by index, never by thread, so
// results do not depend on the thread count. Threads only decide who computes a chunk.
#pragma once
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

namespace ptpb {

// Number of worker threads to use for a request: 0 means every hardware thread.
inline int resolve_thread_count(int requested) {
  if (requested > 0) return requested;
  unsigned hw = std::thread::hardware_concurrency();
  return hw == 0 ? 1 : static_cast<int>(hw);
}

// Calls body(begin, end) for consecutive chunks of [0, n) of at most `chunk` items, on up to
// `threads` threads. The first exception thrown by any chunk is rethrown on the caller's thread
// after all workers stop; remaining chunks are skipped.
template <typename Body>
void parallel_for_chunks(std::size_t n, std::size_t chunk, int threads, Body&& body) {
  if (n == 0) return;
  chunk = std::max<std::size_t>(chunk, 1);
  const std::size_t chunk_count = (n + chunk - 1) / chunk;
  const int worker_count =
      static_cast<int>(std::min<std::size_t>(static_cast<std::size_t>(resolve_thread_count(threads)), chunk_count));
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&]() {
    for (;;) {
      const std::size_t c = next.fetch_add(1);
      if (c >= chunk_count || failed.load()) return;
      const std::size_t begin = c * chunk;
      const std::size_t end = std::min(n, begin + chunk);
      try {
        body(begin, end);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        failed.store(true);
      }
    }
  };
  if (worker_count <= 1) {
    worker();
  } else {
    std::vector<std::thread> pool;
    pool.reserve(static_cast<std::size_t>(worker_count - 1));
    try {
      for (int i = 1; i < worker_count; ++i) pool.emplace_back(worker);
    } catch (const std::system_error&) {
      // No more threads to be had: the ones started share the chunks (same result, chunks are fixed),
      // and no joinable thread is ever destroyed, which would std::terminate.
    }
    worker();
    for (auto& t : pool) t.join();
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace ptpb
