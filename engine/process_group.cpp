#include "engine/process_group.h"

#include <cstdlib>
#include <mutex>

#include "engine/autograd.h"
#include "engine/error.h"
#include "engine/module.h"

namespace cvd {

namespace {

class SingleProcess final : public ProcessGroup {
 public:
  int rank() const override { return 0; }
  int size() const override { return 1; }
  std::string name() const override { return "single process"; }
  void all_reduce_sum(float*, size_t) override {}
  void all_reduce_sum(double*, size_t) override {}
  void broadcast(void*, size_t, int) override {}
  void barrier() override {}
  [[noreturn]] void abort(int exit_code) override { std::exit(exit_code); }
};

std::mutex g_mutex;
std::shared_ptr<ProcessGroup> g_group;
bool g_sync_batch_norm = false;

// Sums a CPU tensor over the processes; returns a new contiguous tensor.
Tensor reduced_copy(const Tensor& x) {
  CVD_CHECK(x.device().is_cpu(), "all_reduce_sum: {} is not on the CPU", x.str());
  CVD_CHECK(x.dtype() == DType::f32 || x.dtype() == DType::f64,
            "all_reduce_sum: {} must be f32 or f64", x.str());
  Tensor y = x.detach().clone();
  if (x.dtype() == DType::f32)
    process_group().all_reduce_sum(y.data<float>(), static_cast<size_t>(y.numel()));
  else
    process_group().all_reduce_sum(y.data<double>(), static_cast<size_t>(y.numel()));
  return y;
}

}  // namespace

ProcessGroup& process_group() {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (!g_group) g_group = std::make_shared<SingleProcess>();
  return *g_group;
}

std::shared_ptr<ProcessGroup> current_process_group() {
  process_group();
  std::lock_guard<std::mutex> lock(g_mutex);
  return g_group;
}

void set_process_group(std::shared_ptr<ProcessGroup> group) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_group = std::move(group);
}

SyncBatchNormScope::SyncBatchNormScope(bool enabled) : prev_(g_sync_batch_norm) {
  g_sync_batch_norm = enabled;
}
SyncBatchNormScope::~SyncBatchNormScope() { g_sync_batch_norm = prev_; }

bool sync_batch_norm_active() { return g_sync_batch_norm && process_group().size() > 1; }

Tensor all_reduce_sum(const Tensor& x) {
  Tensor y = reduced_copy(x);
  if (!any_requires_grad({x})) return y;
  return record("all_reduce_sum", y, {x}, [](const Tensor& g, const std::vector<bool>&) {
    return std::vector<Tensor>{reduced_copy(g)};
  });
}

std::string broadcast_string(const std::string& s, int root) {
  ProcessGroup& pg = process_group();
  if (pg.size() == 1) return s;
  uint64_t n = s.size();
  pg.broadcast(&n, sizeof n, root);
  std::string r = pg.rank() == root ? s : std::string(n, '\0');
  if (n > 0) pg.broadcast(r.data(), n, root);
  return r;
}

void broadcast_tensors(const std::vector<Tensor>& tensors, int root) {
  ProcessGroup& pg = process_group();
  if (pg.size() == 1) return;
  for (const Tensor& t : tensors) {
    CVD_CHECK(t.device().is_cpu() && t.is_contiguous(),
              "broadcast_tensors: {} must be a contiguous CPU tensor", t.str());
    pg.broadcast(t.data_ptr(), t.nbytes(), root);
    t.bump_version();
  }
}

void broadcast_module(const Module& m, int root) {
  std::vector<Tensor> all = m.parameters();
  for (const auto& [name, b] : m.named_buffers()) all.push_back(b);
  broadcast_tensors(all, root);
}

namespace {

template <class T>
size_t reduce_gradients(const std::vector<Tensor>& params) {
  // Layout: every parameter's gradient, then one "defined" count per parameter.
  size_t n = 0;
  for (const Tensor& p : params) n += static_cast<size_t>(p.numel());
  std::vector<T> bucket(n + params.size(), T(0));
  size_t at = 0;
  for (size_t k = 0; k < params.size(); ++k) {
    const Tensor& p = params[k];
    const Tensor g = p.grad();
    if (g.defined()) {
      Tensor gc = g.to(dtype_of<T>::value).contiguous();
      std::copy_n(gc.data<T>(), p.numel(), bucket.data() + at);
      bucket[n + k] = T(1);
    }
    at += static_cast<size_t>(p.numel());
  }
  process_group().all_reduce_sum(bucket.data(), bucket.size());
  at = 0;
  for (size_t k = 0; k < params.size(); ++k) {
    const Tensor& p = params[k];
    if (bucket[n + k] > T(0)) {
      Tensor g = Tensor::empty(p.shape(), dtype_of<T>::value);
      std::copy_n(bucket.data() + at, p.numel(), g.data<T>());
      p.set_grad(p.dtype() == g.dtype() ? g : g.to(p.dtype()));
    }
    at += static_cast<size_t>(p.numel());
  }
  return bucket.size() * sizeof(T);
}

}  // namespace

size_t all_reduce_gradients(const std::vector<Tensor>& params) {
  if (process_group().size() == 1) return 0;
  bool any_f64 = false;
  for (const Tensor& p : params) {
    CVD_CHECK(p.device().is_cpu(), "all_reduce_gradients: {} is not on the CPU", p.str());
    any_f64 |= p.dtype() == DType::f64;
  }
  return any_f64 ? reduce_gradients<double>(params) : reduce_gradients<float>(params);
}

}  // namespace cvd
