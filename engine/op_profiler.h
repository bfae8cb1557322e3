// Per-op kernel time profile of dispatch(): when enabled (environment CVD_PROFILE=1 at start-up,
// or set_enabled(true)), every outermost kernel call through dispatch() adds its wall time and a
// call count to its OpId's totals; a process that ran with CVD_PROFILE=1 prints the table to
// stderr at exit. Off (the default) it costs one relaxed atomic load per dispatch.
//
// Times are wall time of the kernel call on the calling thread: exact for the CPU kernels (they
// return when done), launch time only for asynchronous CUDA kernels. A kernel that dispatches
// other kernels is counted once, as a whole (nested calls are not recorded).
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "engine/dispatch.h"

namespace cvd::op_profiler {

bool enabled();
void set_enabled(bool on);

// Adds one call of `op` taking `nanoseconds` (dispatch() calls this; thread-safe).
void record(OpId op, int64_t nanoseconds);

// The family an op is reported under: "conv", "batch_norm", "pool", "resample", "matmul",
// "elementwise" (unary, binary, where, fill), "reduce", "layout" (copy, concat, pad), "optimizer",
// "grid_sample", "flow" (correlation, channel_norm).
const char* op_family(OpId op);

struct OpTotal {
  OpId op;
  int64_t calls = 0;
  double seconds = 0.0;
};

// Ops with at least one call, most time first.
std::vector<OpTotal> totals();
void reset();

// The totals as two text tables (by family, then by op) with each row's share of the kernel
// time; wall_seconds > 0 adds a row "outside kernels" (autograd, allocation, Python-free glue)
// for the time not spent in kernels.
std::string report(double wall_seconds = 0.0);

// Times the enclosing scope as one call of `op` when profiling is on and no other op is being
// timed on this thread.
class ScopedOpTimer {
 public:
  explicit ScopedOpTimer(OpId op);
  ~ScopedOpTimer();
  ScopedOpTimer(const ScopedOpTimer&) = delete;
  ScopedOpTimer& operator=(const ScopedOpTimer&) = delete;

 private:
  OpId op_;
  int64_t start_ns_ = -1;  // -1: not timing
};

}  // namespace cvd::op_profiler
