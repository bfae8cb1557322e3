// libFuzzer target: the .cvdw weights reader (engine/cvdw.cpp): header validation, then every
// tensor loaded with and without mmap (CRC checked), as `cvd inspect` and load_weights do.
#include "engine/cvdw.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "in.cvdw");
  for (bool mmap : {true, false}) {
    cvd::fuzz::expect_only_cvd_errors([&] {
      cvd::CvdwReadOptions o;
      o.use_mmap = mmap;
      cvd::CvdwReader r(p, o);
      for (size_t i = 0; i < r.header().tensors.size(); ++i) (void)r.computed_crc32(i);
      (void)r.tensors();
    });
  }
  return 0;
}
