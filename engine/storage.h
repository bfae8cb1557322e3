// Storage: a refcounted block of device memory shared by a tensor and its views.
#pragma once
#include <atomic>
#include <cstddef>
#include <functional>
#include <memory>

#include "engine/dtype.h"

namespace cvd {

class Allocator {
 public:
  virtual ~Allocator() = default;
  virtual void* allocate(size_t nbytes) = 0;
  virtual void deallocate(void* p, size_t nbytes) = 0;
  virtual DeviceId device() const = 0;
};

// 64-byte aligned host memory.
Allocator* cpu_allocator();
// Registered by the CUDA backend when compiled in; nullptr otherwise.
Allocator* device_allocator(DeviceId d);
void set_device_allocator(DeviceType t, Allocator* a);

class Storage {
 public:
  // Owns nbytes from `alloc`.
  Storage(size_t nbytes, Allocator* alloc);
  // Wraps foreign memory (e.g. an mmap'd weight file) with a custom release function.
  Storage(void* data, size_t nbytes, DeviceId device, std::function<void()> release);
  ~Storage();
  Storage(const Storage&) = delete;
  Storage& operator=(const Storage&) = delete;

  void* data() const { return data_; }
  size_t nbytes() const { return nbytes_; }
  DeviceId device() const { return device_; }
  // Bumped by every in-place write; lets caches (e.g. oneDNN weight reorders) and autograd
  // notice that saved data changed.
  uint64_t version() const { return version_.load(std::memory_order_relaxed); }
  void bump_version() { version_.fetch_add(1, std::memory_order_relaxed); }
  // Unique id of this storage for caches keyed by identity.
  uint64_t id() const { return id_; }

 private:
  void* data_ = nullptr;
  size_t nbytes_ = 0;
  DeviceId device_;
  Allocator* alloc_ = nullptr;
  std::function<void()> release_;
  std::atomic<uint64_t> version_{0};
  uint64_t id_;
};

}  // namespace cvd
