// Converts the weights of an ONNX graph (tools/convert/onnx_graph.h) into a DepthNet's parameters and
// buffers. The graph is not executed: cvd runs its own implementation of the architecture, so the
// converter only has to find, for every weight layer of the network, the graph's tensors.
//
// Weight layers of the graph, walked in topological order: Conv / ConvTranspose (weight, bias),
// BatchNormalization (scale, B, mean, var), Gemm / MatMul (weight, bias). Each is matched to a
// layer of the network (Conv2d, ConvTranspose2d, BatchNorm2d, Linear):
//   1. by name: initializer names equal to the network's state names (torch.onnx.export keeps
//      them with training=TrainingMode.TRAINING and do_constant_folding=False);
//   2. by structure, for the rest: the i-th remaining graph layer is the i-th remaining network
//      layer in execution order (DepthNet::execution_order).
// LayerNormalization (opset 17) matches LayerNorm. Parameters outside these layers (a ViT's class
// token, position embedding, LayerScale gammas) are taken by name only, from initializers of the
// same name; those the forward never reads (DepthNet::unused_in_forward) are left as they are.
// Every shape, layer kind, BatchNorm epsilon and conv group / stride / dilation is checked. A
// BatchNormalization whose scale / B are constants of 1 / 0 (PyTorch's export of affine=False)
// matches a BatchNorm2d without affine parameters.
//
// A file that cannot be converted is refused with ONE Error that lists every unsupported op type
// (with counts) and every unmatched or mismatched tensor.
//
// Weights shared by several nodes (FlowNetC runs conv1..conv3 on both images) are one layer: a
// weight layer whose stored tensors are exactly those of an earlier one is not matched again.
// Networks other than DepthNets (FlowNet2: tools/convert/onnx_flownet2.h) describe themselves with an
// OnnxNetworkSpec, which also accepts and checks their custom-domain ops.
#pragma once
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "models/depth_net.h"
#include "tools/convert/onnx_graph.h"

namespace cvd {

struct OnnxConversionReport {
  size_t layers = 0;           // weight layers matched
  size_t by_name = 0;          // layers matched by initializer names
  size_t by_structure = 0;     // layers matched by graph position
  size_t tensors = 0;          // tensors copied into the network
  size_t by_name_tensors = 0;  // parameters outside weight layers, taken by initializer name
  // Network tensors its forward never uses (DepthNet::execution_order), left as initialised.
  std::vector<std::string> unused_in_forward;
  std::vector<std::string> warnings;     // e.g. Resize modes that differ from the network's
  std::map<std::string, int> op_counts;  // op type -> nodes
  size_t shared_uses = 0;                // weight nodes reusing an earlier layer's tensors
};

// What the converter needs to know about a network besides its modules.
struct OnnxNetworkSpec {
  std::string arch;  // for messages
  // Module prefixes in the order the graph runs them (DepthNet::execution_order semantics).
  std::vector<std::string> execution_order{""};
  // State names or module prefixes the forward never reads (DepthNet::unused_in_forward).
  std::vector<std::string> unused_in_forward;
  // The custom-domain ops (domain, op type) the network implements; others are unsupported.
  std::set<std::pair<std::string, std::string>> custom_ops;
  // Checks the graph's network-specific nodes (e.g. custom-op attributes): each problem is a
  // message naming the node; they make the conversion fail as unsupported.
  std::function<void(const OnnxModel&, std::vector<std::string>& problems,
                     OnnxConversionReport& report)>
      check_graph;
};

// The standard (default-domain) op types the converter accepts.
const std::set<std::string>& onnx_supported_ops();

// Copies the graph's weights into `net` (converting dtype). Throws Error(unsupported) when the
// graph has unsupported ops, Error(format) when its weights do not match the network; the one
// message names the file and lists every problem.
OnnxConversionReport load_onnx_weights(const OnnxModel& model, DepthNet& net);

// The same for any network described by `spec`.
OnnxConversionReport load_onnx_weights(const OnnxModel& model, Module& net,
                                       const OnnxNetworkSpec& spec);

struct OnnxConversion {
  std::unique_ptr<DepthNet> net;
  OnnxConversionReport report;
};

// Reads `onnx_path` and converts it into a new `arch` network of the given width.
OnnxConversion convert_onnx(const std::filesystem::path& onnx_path, const std::string& arch,
                            double width);

}  // namespace cvd
