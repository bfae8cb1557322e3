// libFuzzer target: the KITTI trajectory reader (pipeline/io/trajectory_io.cpp).
#include "pipeline/io/trajectory_io.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "poses_kitti.txt");
  cvd::fuzz::expect_only_cvd_errors([&] { cvd::read_kitti_trajectory(p); });
  return 0;
}
