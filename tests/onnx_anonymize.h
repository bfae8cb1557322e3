// Test helper: strips an ONNX model of its initializer names, so a converter can only match
// layers by graph structure.
#pragma once
#include <cstdint>

#include "tools/convert/onnx_graph.h"

namespace cvd::test {

// Renames every initializer to "w<k>" in a shuffled order (std::mt19937(seed)) and rewrites the
// node inputs that referred to them.
void anonymize_initializers(OnnxModel& model, uint32_t seed);

}  // namespace cvd::test
