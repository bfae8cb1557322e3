// libFuzzer target: the ONNX protobuf reader (tools/convert/onnx_graph.cpp), from a file as the CLI reads
// it (external-data references resolve next to the scratch file, where none exist).
#include "tests/fuzz/fuzz_support.h"
#include "tools/convert/onnx_graph.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto p = cvd::fuzz::input_file(data, size, "in.onnx");
  cvd::fuzz::expect_only_cvd_errors([&] { cvd::read_onnx(p); });
  return 0;
}
