// A 64-byte aligned float buffer that grows on demand (contents not kept across growth, not
// initialised): the work space of the hand-written AVX-512 kernels (depthwise, pointwise).
#pragma once
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>

namespace cvd::cpu {

class AlignedFloatBuffer {
 public:
  float* get(int64_t floats) {
    if (floats > size_) {
      const size_t bytes = (static_cast<size_t>(floats) * sizeof(float) + 63) / 64 * 64;
      data_.reset(static_cast<float*>(std::aligned_alloc(64, bytes)));
      if (!data_) throw std::bad_alloc();
      size_ = floats;
    }
    return data_.get();
  }

 private:
  struct Free {
    void operator()(float* p) const { std::free(p); }
  };
  std::unique_ptr<float, Free> data_;
  int64_t size_ = 0;
};

}  // namespace cvd::cpu
