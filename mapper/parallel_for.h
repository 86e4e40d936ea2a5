// A fixed-partition parallel loop of the mapper: which thread runs which index depends only on
// the index, the block and the thread count, and every result goes to its own slot, so results
// do not depend on the thread count.
#pragma once

#include <algorithm>
#include <cstddef>
#include <exception>
#include <thread>
#include <vector>

namespace evloc::mapper {

// Runs body(begin, end) over [0, count) in blocks of `block` indices dealt round-robin to
// min(num_threads, count) threads (interleaved blocks balance unevenly spread work); rethrows the
// first worker's exception after all have joined.
template <typename Body>
void ParallelFor(size_t count, int num_threads, const Body& body, size_t block = 64) {
  const size_t threads = std::max<size_t>(1, std::min<size_t>(num_threads, count));
  if (threads <= 1) {
    body(size_t{0}, count);
    return;
  }
  block = std::max<size_t>(1, block);
  std::vector<std::thread> workers;
  std::vector<std::exception_ptr> errors(threads);
  for (size_t worker = 0; worker < threads; ++worker) {
    workers.emplace_back([&, worker] {
      try {
        for (size_t begin = worker * block; begin < count; begin += threads * block) {
          body(begin, std::min(count, begin + block));
        }
      } catch (...) {
        errors[worker] = std::current_exception();
      }
    });
  }
  for (std::thread& worker : workers) worker.join();
  for (const std::exception_ptr& error : errors) {
    if (error) std::rethrow_exception(error);
  }
}

}  // namespace evloc::mapper
