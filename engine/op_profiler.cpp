#include "engine/op_profiler.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>

#include <fmt/format.h>

namespace cvd::op_profiler {

namespace {

bool env_enabled() {
  const char* v = std::getenv("CVD_PROFILE");
  return v != nullptr && *v != '\0' && std::strcmp(v, "0") != 0;
}

struct Totals {
  std::array<std::atomic<int64_t>, kNumOps> ns{};
  std::array<std::atomic<int64_t>, kNumOps> calls{};
};

Totals& store() {
  static Totals t;
  return t;
}

// Prints the table at exit in a process started with CVD_PROFILE set.
struct ExitReport {
  ~ExitReport() {
    if (env_enabled() && !totals().empty()) std::fputs(report().c_str(), stderr);
  }
};

std::atomic<bool>& flag() {
  static std::atomic<bool> on{[] {
    (void)store();  // constructed before at_exit, so destroyed after its report
    static ExitReport at_exit;
    return env_enabled();
  }()};
  return on;
}

thread_local bool t_timing = false;  // an op is being timed on this thread

int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

bool enabled() { return flag().load(std::memory_order_relaxed); }
void set_enabled(bool on) { flag().store(on, std::memory_order_relaxed); }

void record(OpId op, int64_t nanoseconds) {
  const int i = static_cast<int>(op);
  if (i < 0 || i >= kNumOps) return;
  store().ns[i].fetch_add(nanoseconds, std::memory_order_relaxed);
  store().calls[i].fetch_add(1, std::memory_order_relaxed);
}

const char* op_family(OpId op) {
  switch (op) {
    case OpId::conv2d:
    case OpId::conv2d_backward_data:
    case OpId::conv2d_backward_weight:
    case OpId::conv_transpose2d:
    case OpId::conv_transpose2d_backward_data:
    case OpId::conv_transpose2d_backward_weight:
      return "conv";
    case OpId::batch_norm:
    case OpId::batch_norm_backward:
      return "batch_norm";
    case OpId::max_pool2d:
    case OpId::max_pool2d_backward:
    case OpId::avg_pool2d:
    case OpId::avg_pool2d_backward:
      return "pool";
    case OpId::upsample_bilinear2d:
    case OpId::upsample_bilinear2d_backward:
    case OpId::upsample_nearest2d:
    case OpId::upsample_nearest2d_backward:
    case OpId::upsample_bicubic2d:
    case OpId::upsample_bicubic2d_backward:
      return "resample";
    case OpId::layer_norm:
    case OpId::layer_norm_backward:
      return "layer_norm";
    case OpId::softmax:
    case OpId::softmax_backward:
      return "softmax";
    case OpId::matmul:
      return "matmul";
    case OpId::unary:
    case OpId::unary_backward:
    case OpId::binary:
    case OpId::where:
    case OpId::fill:
      return "elementwise";
    case OpId::reduce_sum:
      return "reduce";
    case OpId::copy:
    case OpId::concat:
    case OpId::pad:
      return "layout";
    case OpId::adam_update:
    case OpId::sgd_update:
      return "optimizer";
    case OpId::grid_sample:
    case OpId::grid_sample_backward:
      return "grid_sample";
    case OpId::correlation:
    case OpId::correlation_backward:
    case OpId::channel_norm:
    case OpId::channel_norm_backward:
      return "flow";
    case OpId::count:
      break;
  }
  return "other";
}

std::vector<OpTotal> totals() {
  std::vector<OpTotal> out;
  for (int i = 0; i < kNumOps; ++i) {
    const int64_t calls = store().calls[i].load(std::memory_order_relaxed);
    if (calls == 0) continue;
    out.push_back({static_cast<OpId>(i), calls,
                   static_cast<double>(store().ns[i].load(std::memory_order_relaxed)) * 1e-9});
  }
  std::sort(out.begin(), out.end(),
            [](const OpTotal& a, const OpTotal& b) { return a.seconds > b.seconds; });
  return out;
}

void reset() {
  for (int i = 0; i < kNumOps; ++i) {
    store().ns[i].store(0, std::memory_order_relaxed);
    store().calls[i].store(0, std::memory_order_relaxed);
  }
}

std::string report(double wall_seconds) {
  const std::vector<OpTotal> ops = totals();
  double kernel_s = 0.0;
  std::map<std::string, OpTotal> families;
  for (const OpTotal& t : ops) {
    kernel_s += t.seconds;
    OpTotal& f = families[op_family(t.op)];
    f.calls += t.calls;
    f.seconds += t.seconds;
  }
  std::vector<std::pair<std::string, OpTotal>> by_family(families.begin(), families.end());
  std::sort(by_family.begin(), by_family.end(),
            [](const auto& a, const auto& b) { return a.second.seconds > b.second.seconds; });
  const double total = std::max(wall_seconds, kernel_s);
  const auto share = [&](double s) { return total > 0 ? 100.0 * s / total : 0.0; };
  std::string r = fmt::format("# op profile (CVD_PROFILE): kernel time {:.3f} s", kernel_s);
  if (wall_seconds > 0) r += fmt::format(" of {:.3f} s wall", wall_seconds);
  r += fmt::format("\n{:<34} {:>8} {:>10} {:>7}\n", "family", "calls", "seconds", "share");
  for (const auto& [name, t] : by_family) {
    r += fmt::format("{:<34} {:>8} {:>10.3f} {:>6.1f}%\n", name, t.calls, t.seconds,
                     share(t.seconds));
  }
  if (wall_seconds > kernel_s) {
    r += fmt::format("{:<34} {:>8} {:>10.3f} {:>6.1f}%\n", "outside kernels", "-",
                     wall_seconds - kernel_s, share(wall_seconds - kernel_s));
  }
  r += fmt::format("{:<34} {:>8} {:>10} {:>7}\n", "op", "calls", "seconds", "share");
  for (const OpTotal& t : ops) {
    r += fmt::format("{:<34} {:>8} {:>10.3f} {:>6.1f}%\n", op_name(t.op), t.calls, t.seconds,
                     share(t.seconds));
  }
  return r;
}

ScopedOpTimer::ScopedOpTimer(OpId op) : op_(op) {
  if (!enabled() || t_timing) return;
  t_timing = true;
  start_ns_ = now_ns();
}

ScopedOpTimer::~ScopedOpTimer() {
  if (start_ns_ < 0) return;
  record(op_, now_ns() - start_ns_);
  t_timing = false;
}

}  // namespace cvd::op_profiler
