// The two sides the ONNX weight converter (tools/convert/onnx_weights.h) matches: the weight
// layers of a graph, in topological order, with where each weight tensor comes from
// (initializer, Constant node, through Identity / Transpose nodes), and the weight layers of a
// network, in its execution order.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "engine/module.h"
#include "tools/convert/onnx_graph.h"

namespace cvd::onnx_layers {

enum class LayerKind { conv, conv_transpose, batch_norm, linear, layer_norm };

// "Conv", "BatchNormalization", ... (the graph's op names) and "Conv2d", "BatchNorm2d", ... (the
// network's module names).
const char* graph_kind_name(LayerKind k);
const char* model_kind_name(LayerKind k);

// Where a weight input of a graph node comes from.
struct GraphTensor {
  std::string role;                    // "weight", "bias", "running_mean", "running_var"
  std::string value;                   // the node's input name
  const OnnxTensor* tensor = nullptr;  // null: computed by the graph
  bool initializer = false;            // false: a Constant node
  bool transpose = false;              // the network stores the transpose (MatMul, Gemm transB=0)
};

struct GraphLayer {
  LayerKind kind;
  std::string where;  // "Conv node 'x'" for messages
  std::vector<GraphTensor> tensors;
  const OnnxNode* node = nullptr;
};

struct ModelLayer {
  LayerKind kind;
  std::string prefix;
  const Module* module = nullptr;
  std::vector<std::pair<std::string, Tensor>> tensors;  // role -> tensor
  std::string state_name(const std::string& role) const {
    return prefix.empty() ? role : prefix + "." + role;
  }
  const Tensor* tensor(const std::string& role) const {
    for (const auto& [r, t] : tensors)
      if (r == role) return &t;
    return nullptr;
  }
};

// Nodes in topological order; ties keep the file order (which torch.onnx writes in execution
// order). Values without a producer (graph inputs, initializers) are available from the start.
std::vector<size_t> topological_order(const OnnxGraph& g);

// The graph's weight layers (Conv, ConvTranspose, BatchNormalization, Gemm, MatMul with a stored
// weight and its following Add of a stored bias, LayerNormalization) in topological order.
std::vector<GraphLayer> graph_layers(const OnnxGraph& g);

// The network's weight layers, split into those its forward runs (in execution order) and those
// it never runs.
void model_layers(const Module& net, const std::vector<std::string>& execution_order,
                  std::vector<ModelLayer>& used, std::vector<ModelLayer>& unused);

}  // namespace cvd::onnx_layers
