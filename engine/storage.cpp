#include "engine/storage.h"

#include <cstdlib>
#include <cstring>
#include <new>

#include "engine/error.h"
#include "engine/host_block_cache.h"

namespace cvd {

namespace {

class CpuAllocator final : public Allocator {
 public:
  void* allocate(size_t nbytes) override {
    return nbytes == 0 ? nullptr : host_block_allocate(nbytes);
  }
  void deallocate(void* p, size_t nbytes) override {
    if (p) host_block_free(p, nbytes);
  }
  DeviceId device() const override { return DeviceId::cpu(); }
};

Allocator* g_device_allocators[kNumDeviceTypes] = {nullptr, nullptr};
std::atomic<uint64_t> g_next_storage_id{1};

}  // namespace

Allocator* cpu_allocator() {
  static CpuAllocator a;
  return &a;
}

Allocator* device_allocator(DeviceId d) {
  if (d.is_cpu()) return cpu_allocator();
  return g_device_allocators[static_cast<int>(d.type)];
}

void set_device_allocator(DeviceType t, Allocator* a) {
  g_device_allocators[static_cast<int>(t)] = a;
}

Storage::Storage(size_t nbytes, Allocator* alloc)
    : nbytes_(nbytes), device_(alloc->device()), alloc_(alloc), id_(g_next_storage_id++) {
  data_ = alloc->allocate(nbytes);
}

Storage::Storage(void* data, size_t nbytes, DeviceId device, std::function<void()> release)
    : data_(data),
      nbytes_(nbytes),
      device_(device),
      release_(std::move(release)),
      id_(g_next_storage_id++) {}

Storage::~Storage() {
  if (release_) {
    release_();
  } else if (alloc_ && data_) {
    alloc_->deallocate(data_, nbytes_);
  }
}

}  // namespace cvd
