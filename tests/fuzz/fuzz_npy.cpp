// libFuzzer target: the NumPy depth-stack reader (pipeline/io/npy_io.cpp): the header, then the
// first and last frame it promises.
#include "pipeline/io/npy_io.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "in.npy");
  cvd::fuzz::expect_only_cvd_errors([&] {
    const cvd::NpyStackInfo info = cvd::read_npy_stack_info(p);
    // Frames beyond a few MB are not read (the size check above already proved them present).
    if (info.frames > 0 && info.height * info.width <= (1 << 20)) {
      cvd::read_npy_frame(p, 0);
      cvd::read_npy_frame(p, info.frames - 1);
    }
  });
  return 0;
}
