#include "engine/rematerialize.h"

#include <atomic>
#include <cstdlib>
#include <cstring>

#include "engine/autograd.h"

namespace cvd {

namespace {

std::atomic<bool>& enabled_flag() {
  static std::atomic<bool> flag{[] {
    const char* v = std::getenv("CVD_REMATERIALIZE");
    return !(v && std::strcmp(v, "0") == 0);
  }()};
  return flag;
}

}  // namespace

bool rematerialization_enabled() { return enabled_flag().load(std::memory_order_relaxed); }

void set_rematerialization(bool enabled) {
  enabled_flag().store(enabled, std::memory_order_relaxed);
}

void mark_rematerializable(const Tensor& t, std::function<Tensor()> compute) {
  if (!rematerialization_enabled() || !t.defined()) return;
  auto r = std::make_shared<Rematerializer>();
  r->compute = std::move(compute);
  r->version = t.version();
  t.impl()->rematerializer = std::move(r);
}

SavedTensor::SavedTensor(const Tensor& t) {
  if (!t.defined()) return;
  const auto& r = t.impl()->rematerializer;
  if (r && r->version == t.version() && rematerialization_enabled()) {
    recipe_ = r;
  } else {
    tensor_ = t.detach();
  }
}

Tensor SavedTensor::get() const {
  if (!recipe_) return tensor_;
  NoGradGuard no_grad;
  return recipe_->compute();
}

}  // namespace cvd
