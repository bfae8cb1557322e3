// libFuzzer target: the ONNX protobuf reader (models/onnx_graph.cpp), from a file as the CLI reads
// it (external-data references resolve next to the scratch file, where none exist).
#include "models/onnx_graph.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "in.onnx");
  cvd::fuzz::expect_only_cvd_errors([&] { cvd::read_onnx(p); });
  return 0;
}
