// libFuzzer target: the Middlebury .flo reader (pipeline/io/flow_io.cpp).
#include "pipeline/io/flow_io.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "in.flo");
  cvd::fuzz::expect_only_cvd_errors([&] { cvd::read_flo(p); });
  return 0;
}
