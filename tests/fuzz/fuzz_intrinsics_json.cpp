// libFuzzer target: the intrinsics JSON reader (pipeline/io/trajectory_io.cpp).
#include "pipeline/io/trajectory_io.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "intrinsics.json");
  cvd::fuzz::expect_only_cvd_errors([&] { cvd::read_intrinsics_json(p); });
  return 0;
}
