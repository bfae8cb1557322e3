// libFuzzer target: the PFM reader (pipeline/io/pfm_io.cpp).
#include "pipeline/io/pfm_io.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "in.pfm");
  cvd::fuzz::expect_only_cvd_errors([&] { cvd::read_pfm(p); });
  return 0;
}
