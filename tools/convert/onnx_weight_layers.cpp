#include "tools/convert/onnx_weight_layers.h"

#include <functional>
#include <map>
#include <queue>

#include "engine/error.h"
#include "engine/layers.h"

namespace cvd::onnx_layers {

const char* graph_kind_name(LayerKind k) {
  switch (k) {
    case LayerKind::conv:
      return "Conv";
    case LayerKind::conv_transpose:
      return "ConvTranspose";
    case LayerKind::batch_norm:
      return "BatchNormalization";
    case LayerKind::linear:
      return "Gemm/MatMul";
    case LayerKind::layer_norm:
      return "LayerNormalization";
  }
  return "?";
}

const char* model_kind_name(LayerKind k) {
  switch (k) {
    case LayerKind::conv:
      return "Conv2d";
    case LayerKind::conv_transpose:
      return "ConvTranspose2d";
    case LayerKind::batch_norm:
      return "BatchNorm2d";
    case LayerKind::linear:
      return "Linear";
    case LayerKind::layer_norm:
      return "LayerNorm";
  }
  return "?";
}

std::vector<size_t> topological_order(const OnnxGraph& g) {
  std::map<std::string, size_t> producer;
  for (size_t i = 0; i < g.nodes.size(); ++i)
    for (const auto& o : g.nodes[i].outputs)
      if (!o.empty()) producer.emplace(o, i);
  std::vector<std::vector<size_t>> consumers(g.nodes.size());
  std::vector<int> pending(g.nodes.size(), 0);
  for (size_t i = 0; i < g.nodes.size(); ++i)
    for (const auto& in : g.nodes[i].inputs) {
      auto it = producer.find(in);
      if (it == producer.end() || it->second == i) continue;
      consumers[it->second].push_back(i);
      ++pending[i];
    }
  std::priority_queue<size_t, std::vector<size_t>, std::greater<>> ready;
  for (size_t i = 0; i < g.nodes.size(); ++i)
    if (pending[i] == 0) ready.push(i);
  std::vector<size_t> order;
  while (!ready.empty()) {
    const size_t i = ready.top();
    ready.pop();
    order.push_back(i);
    for (size_t c : consumers[i])
      if (--pending[c] == 0) ready.push(c);
  }
  if (order.size() != g.nodes.size())
    fail(ErrorCategory::format, "the graph has a cycle ({} of {} nodes cannot be ordered)",
         g.nodes.size() - order.size(), g.nodes.size());
  return order;
}

namespace {

class GraphWeights {
 public:
  explicit GraphWeights(const OnnxGraph& g) : g_(g) {
    for (const auto& n : g.nodes) {
      if (n.op_type == "Constant" && !n.outputs.empty()) {
        if (const OnnxAttribute* a = n.attribute("value"); a && a->t)
          constants_[n.outputs[0]] = a->t.get();
      } else if (n.op_type == "Identity" && !n.inputs.empty() && !n.outputs.empty()) {
        alias_[n.outputs[0]] = n.inputs[0];
      } else if (n.op_type == "Transpose" && n.inputs.size() == 1 && !n.outputs.empty()) {
        // A 2-d weight transposed by the graph (torch.onnx's Linear without constant folding).
        const std::vector<int64_t> perm = n.ints_attribute("perm");
        if (perm.empty() || perm == std::vector<int64_t>{1, 0})
          transposed_[n.outputs[0]] = n.inputs[0];
      }
    }
  }
  // The value `value` is the graph's transpose of; empty when it is not a Transpose output.
  std::string transpose_source(const std::string& value) const {
    auto t = transposed_.find(value);
    return t == transposed_.end() ? std::string() : t->second;
  }
  GraphTensor resolve(const std::string& role, const std::string& value) const {
    GraphTensor t{role, value};
    std::string v = value;
    for (int hops = 0; hops < 64; ++hops) {
      if (const OnnxTensor* init = g_.initializer(v)) {
        t.tensor = init;
        t.initializer = true;
        t.value = v;
        return t;
      }
      if (auto c = constants_.find(v); c != constants_.end()) {
        t.tensor = c->second;
        t.value = v;
        return t;
      }
      auto a = alias_.find(v);
      if (a == alias_.end()) break;
      v = a->second;
    }
    return t;
  }

 private:
  const OnnxGraph& g_;
  std::map<std::string, const OnnxTensor*> constants_;
  std::map<std::string, std::string> alias_;
  std::map<std::string, std::string> transposed_;
};

}  // namespace

std::vector<GraphLayer> graph_layers(const OnnxGraph& g) {
  GraphWeights weights(g);
  std::map<std::string, std::vector<const OnnxNode*>> consumers;
  for (const auto& n : g.nodes)
    for (const auto& in : n.inputs) consumers[in].push_back(&n);
  std::vector<GraphLayer> layers;
  for (size_t i : topological_order(g)) {
    const OnnxNode& n = g.nodes[i];
    if (!n.domain.empty()) continue;
    auto input = [&](size_t k) { return k < n.inputs.size() ? n.inputs[k] : std::string(); };
    GraphLayer l{LayerKind::conv, n.describe(i), {}, &n};
    std::vector<std::pair<std::string, std::string>> roles;
    bool transpose = false;
    if (n.op_type == "Conv" || n.op_type == "ConvTranspose") {
      l.kind = n.op_type == "Conv" ? LayerKind::conv : LayerKind::conv_transpose;
      roles = {{"weight", input(1)}, {"bias", input(2)}};
    } else if (n.op_type == "BatchNormalization") {
      l.kind = LayerKind::batch_norm;
      roles = {{"weight", input(1)},
               {"bias", input(2)},
               {"running_mean", input(3)},
               {"running_var", input(4)}};
    } else if (n.op_type == "Gemm") {
      l.kind = LayerKind::linear;
      transpose = n.int_attribute("transB", 0) == 0;
      roles = {{"weight", input(1)}, {"bias", input(2)}};
    } else if (n.op_type == "LayerNormalization") {
      l.kind = LayerKind::layer_norm;
      roles = {{"weight", input(1)}, {"bias", input(2)}};
    } else if (n.op_type == "MatMul") {
      // x @ W with a stored W [in, out] (or Transpose(W) of a stored W [out, in]); a following
      // Add of a stored vector is the bias.
      std::string w_value = input(1);
      transpose = true;
      if (const std::string src = weights.transpose_source(w_value);
          !src.empty() && weights.resolve("weight", src).tensor) {
        w_value = src;
        transpose = false;
      }
      GraphTensor w = weights.resolve("weight", w_value);
      if (!w.tensor) continue;  // a product of two computed values: no weights
      l.kind = LayerKind::linear;
      roles = {{"weight", w_value}};
      if (!n.outputs.empty() && consumers[n.outputs[0]].size() == 1) {
        const OnnxNode* add = consumers[n.outputs[0]][0];
        if (add->op_type == "Add" && add->inputs.size() == 2) {
          const std::string& other =
              add->inputs[0] == n.outputs[0] ? add->inputs[1] : add->inputs[0];
          if (weights.resolve("bias", other).tensor) roles.emplace_back("bias", other);
        }
      }
    } else {
      continue;
    }
    for (const auto& [role, value] : roles) {
      if (value.empty()) continue;
      GraphTensor t = weights.resolve(role, value);
      t.transpose = transpose && role == "weight";
      l.tensors.push_back(t);
    }
    layers.push_back(std::move(l));
  }
  return layers;
}

void model_layers(const Module& net, const std::vector<std::string>& execution_order,
                  std::vector<ModelLayer>& used, std::vector<ModelLayer>& unused) {
  std::vector<ModelLayer> all;
  for (const auto& [name, m] : net.named_modules()) {
    ModelLayer l{LayerKind::conv, name, m, {}};
    if (dynamic_cast<const Conv2d*>(m))
      l.kind = LayerKind::conv;
    else if (dynamic_cast<const ConvTranspose2d*>(m))
      l.kind = LayerKind::conv_transpose;
    else if (dynamic_cast<const BatchNorm2d*>(m))
      l.kind = LayerKind::batch_norm;
    else if (dynamic_cast<const Linear*>(m))
      l.kind = LayerKind::linear;
    else if (dynamic_cast<const LayerNorm*>(m))
      l.kind = LayerKind::layer_norm;
    else
      continue;
    for (const auto& [role, t] : m->local_parameters()) l.tensors.emplace_back(role, t);
    for (const auto& [role, t] : m->local_buffers())
      if (role == "running_mean" || role == "running_var") l.tensors.emplace_back(role, t);
    all.push_back(std::move(l));
  }
  std::vector<bool> placed(all.size(), false);
  for (const std::string& prefix : execution_order)
    for (size_t i = 0; i < all.size(); ++i) {
      const std::string& p = all[i].prefix;
      const bool under = prefix.empty() || p == prefix ||
                         (p.size() > prefix.size() && p.compare(0, prefix.size(), prefix) == 0 &&
                          p[prefix.size()] == '.');
      if (under && !placed[i]) {
        placed[i] = true;
        used.push_back(all[i]);
      }
    }
  for (size_t i = 0; i < all.size(); ++i)
    if (!placed[i]) unused.push_back(all[i]);
}

}  // namespace cvd::onnx_layers
