// Converts the weights of an ONNX export of FlowNet2 (models/flownet2.h) into a FlowNet2.
//
// FlowNet2's three non-standard layers are custom-domain nodes, domain "cvd.flownet2" (opset
// version 1), attribute names as NVIDIA/flownet2-pytorch's layer arguments
// (tools/reference/export_flownet2_onnx.py writes them; README "FlowNet2 ONNX custom ops"):
//   Correlation(a, b) -> y     int pad_size 20, kernel_size 1, max_displacement 20, stride1 1,
//                              stride2 2, corr_multiply 1 (FlowNetC)
//   Resample2d(img, flow) -> warped   int kernel_size 1; optional int bilinear 1
//   ChannelNorm(x) -> y        int norm_deg 2
// cvd runs its own FlowNet2, whose layers implement exactly these values: every attribute is
// checked, and a missing, unknown or different one is an error naming the node and the
// attribute. The graph must have FlowNet2's 1 Correlation, 4 Resample2d and 6 ChannelNorm nodes.
// The weights are matched by tools/convert/onnx_weights.h (names first, then structure in the order of
// flownet2_onnx_execution_order); FlowNetC's conv1..conv3, run on both images, are one layer.
#pragma once
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "models/flownet2.h"
#include "tools/convert/onnx_weights.h"

namespace cvd {

inline constexpr const char* kFlowNet2OnnxDomain = "cvd.flownet2";

// FlowNet2's module prefixes in the order the reference's forward (and so its ONNX export) runs
// its weight layers: flownetc, flownets_1, flownets_2, flownets_d, flownetfusion, and inside
// each the encoder, then per level predict_flow, deconv, upsampled_flow (, inter_conv).
std::vector<std::string> flownet2_onnx_execution_order();

// The converter's description of FlowNet2: the execution order, the custom ops and their checks.
OnnxNetworkSpec flownet2_onnx_spec();

// Copies the graph's weights into `net`; Error(unsupported) for unsupported ops or custom-op
// attributes, Error(format) for weights that do not match (one message listing every problem).
OnnxConversionReport load_onnx_flownet2_weights(const OnnxModel& model, FlowNet2& net);

struct OnnxFlowNet2Conversion {
  std::unique_ptr<FlowNet2> net;
  OnnxConversionReport report;
};

// Reads `onnx_path` and converts it into a new FlowNet2 of the given width.
OnnxFlowNet2Conversion convert_onnx_flownet2(const std::filesystem::path& onnx_path, double width);

}  // namespace cvd
