#include "tools/convert/onnx_weights.h"

#include <algorithm>
#include <cmath>
#include <queue>

#include "engine/error.h"
#include "engine/layers.h"
#include "engine/ops.h"
#include "engine/random.h"

namespace cvd {

namespace {

enum class LayerKind { conv, conv_transpose, batch_norm, linear, layer_norm };

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

std::string shape_text(const std::vector<int64_t>& dims) {
  return fmt::format("[{}]", fmt::join(dims, ", "));
}

// Nodes in topological order; ties keep the file order (which torch.onnx writes in execution
// order). Values without a producer (graph inputs, initializers) are available from the start.
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

// The network's weight layers, split into those its forward runs (in execution order) and those
// it never runs.
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

bool all_equal(const OnnxTensor& t, double value) {
  if (!t.values.defined()) return false;
  Tensor v = t.values.to(DType::f64).contiguous();
  const double* p = v.data<double>();
  for (int64_t i = 0; i < v.numel(); ++i)
    if (p[i] != value) return false;
  return true;
}

std::vector<int64_t> model_shape(const Tensor& t) { return {t.shape().begin(), t.shape().end()}; }

// Checks the node's attributes that the weights' shapes do not show.
void check_attributes(const GraphLayer& g, const ModelLayer& m,
                      std::vector<std::string>& problems) {
  const OnnxNode& n = *g.node;
  auto pair_attr = [&](const char* name) {
    std::vector<int64_t> v = n.ints_attribute(name);
    return v.size() == 2 ? std::pair<int64_t, int64_t>(v[0], v[1])
                         : std::pair<int64_t, int64_t>(1, 1);
  };
  auto check = [&](const char* what, std::pair<int64_t, int64_t> graph,
                   std::pair<int64_t, int64_t> model) {
    if (graph != model)
      problems.push_back(fmt::format(
          "{} ({}): {} {}x{} in the graph, {}x{} in the network layer '{}'", g.where, m.prefix,
          what, graph.first, graph.second, model.first, model.second, m.prefix));
  };
  if (const auto* c = dynamic_cast<const Conv2d*>(m.module)) {
    const auto& o = c->options();
    check("strides", pair_attr("strides"), {o.stride_h, o.stride_w});
    check("dilations", pair_attr("dilations"), {o.dilation_h, o.dilation_w});
    check("group", {n.int_attribute("group", 1), 1}, {o.groups, 1});
  } else if (const auto* ct = dynamic_cast<const ConvTranspose2d*>(m.module)) {
    const auto& o = ct->options();
    check("strides", pair_attr("strides"), {o.stride_h, o.stride_w});
    check("group", {n.int_attribute("group", 1), 1}, {o.groups, 1});
  } else if (const auto* ln = dynamic_cast<const LayerNorm*>(m.module)) {
    const double eps = n.float_attribute("epsilon", 1e-5f);
    if (std::abs(eps - ln->eps()) > 1e-6 * ln->eps())
      problems.push_back(
          fmt::format("{}: epsilon {:g} in the graph, {:g} in the network layer '{}'", g.where, eps,
                      ln->eps(), m.prefix));
    if (n.int_attribute("axis", -1) != -1)
      problems.push_back(fmt::format("{}: axis {} (the network normalises the last axis only)",
                                     g.where, n.int_attribute("axis", -1)));
  } else if (const auto* bn = dynamic_cast<const BatchNorm2d*>(m.module)) {
    const double eps = n.float_attribute("epsilon", 1e-5f);
    if (std::abs(eps - bn->options().eps) > 1e-6 * bn->options().eps)
      problems.push_back(
          fmt::format("{}: epsilon {:g} in the graph, {:g} in the network layer '{}'", g.where, eps,
                      bn->options().eps, m.prefix));
  }
}

// Matches one graph layer to one network layer, adding the tensors to `state`.
void match_layer(const GraphLayer& g, const ModelLayer& m, std::map<std::string, Tensor>& state,
                 std::vector<std::string>& problems) {
  if (g.kind != m.kind) {
    problems.push_back(
        fmt::format("{} has no counterpart: the network's layer at this position is "
                    "the {} '{}'",
                    g.where, model_kind_name(m.kind), m.prefix));
    return;
  }
  check_attributes(g, m, problems);
  for (const GraphTensor& t : g.tensors) {
    const Tensor* target = m.tensor(t.role);
    if (!t.tensor) {
      problems.push_back(fmt::format("{}: its {} '{}' is computed by the graph, not stored",
                                     g.where, t.role, t.value));
      continue;
    }
    if (!t.tensor->values.defined()) {
      problems.push_back(fmt::format(
          "{}: tensor '{}' has data type {} (only FLOAT and DOUBLE weights are supported)", g.where,
          t.value, onnx_data_type_name(t.tensor->data_type)));
      continue;
    }
    if (!target) {
      // PyTorch exports BatchNorm2d(affine=False) with constant scale 1 and B 0, a bias-free conv
      // may come with a zero bias.
      const double neutral = t.role == "weight" ? 1.0 : 0.0;
      if (!all_equal(*t.tensor, neutral))
        problems.push_back(
            fmt::format("{}: the graph has a non-trivial {} '{}' but the network layer "
                        "'{}' has none",
                        g.where, t.role, t.value, m.prefix));
      continue;
    }
    Tensor v = t.tensor->values;
    if (t.transpose && v.dim() == 2) v = transpose(v, 0, 1).contiguous();
    const std::vector<int64_t> vs(v.shape().begin(), v.shape().end());
    if (vs != model_shape(*target)) {
      problems.push_back(fmt::format(
          "{}: tensor '{}' has shape {} but '{}' of the network has shape {}", g.where, t.value,
          shape_text(vs), m.state_name(t.role), shape_text(model_shape(*target))));
      continue;
    }
    state[m.state_name(t.role)] = v;
  }
  for (const auto& [role, tensor] : m.tensors) {
    bool supplied = false;
    for (const GraphTensor& t : g.tensors) supplied = supplied || t.role == role;
    if (!supplied)
      problems.push_back(
          fmt::format("network tensor '{}' has no counterpart in {}", m.state_name(role), g.where));
  }
}

std::string tensor_names(const ModelLayer& m) {
  std::vector<std::string> names;
  for (const auto& [role, t] : m.tensors) names.push_back(m.state_name(role));
  return fmt::format("{}", fmt::join(names, ", "));
}

std::string tensor_names(const GraphLayer& g) {
  std::vector<std::string> names;
  for (const auto& t : g.tensors) names.push_back(t.value);
  return fmt::format("{}", fmt::join(names, ", "));
}

// The count of each kind, for the summary of a structural mismatch.
template <class Layers>
std::string kind_counts(const Layers& layers, bool graph) {
  std::map<LayerKind, int> counts;
  for (const auto& l : layers) ++counts[l.kind];
  std::vector<std::string> parts;
  for (const auto& [k, c] : counts)
    parts.push_back(fmt::format("{} {}", c, graph ? graph_kind_name(k) : model_kind_name(k)));
  return parts.empty() ? "none" : fmt::format("{}", fmt::join(parts, ", "));
}

void resize_warnings(const OnnxModel& model, const DepthNet& net, OnnxConversionReport& report) {
  int linear = 0, align_corners = 0;
  for (const auto& n : model.graph.nodes) {
    if (n.op_type != "Resize" && n.op_type != "Upsample") continue;
    const std::string mode = n.string_attribute("mode", "nearest");
    if (mode != "linear" && mode != "bilinear") continue;
    ++linear;
    if (n.string_attribute("coordinate_transformation_mode", "half_pixel") == "align_corners")
      ++align_corners;
  }
  if (linear > 0 && align_corners == 0)
    report.warnings.push_back(fmt::format(
        "none of the file's {} bilinear Resize/Upsample nodes uses align_corners, but {} "
        "upsamples with align_corners=True: the weights convert exactly, but the file's own "
        "outputs "
        "differ from the original network's and cvd's (MiDaS's published ONNX files made this "
        "change; never use them as reference outputs)",
        linear, net.arch()));
}

}  // namespace

const std::set<std::string>& onnx_supported_ops() {
  static const std::set<std::string> ops = {"Conv",
                                            "ConvTranspose",
                                            "BatchNormalization",
                                            "Relu",
                                            "Clip",
                                            "LeakyRelu",
                                            "Sigmoid",
                                            "Tanh",
                                            "Add",
                                            "Sub",
                                            "Mul",
                                            "Div",
                                            "Concat",
                                            "Resize",
                                            "Upsample",
                                            "MaxPool",
                                            "AveragePool",
                                            "Pad",
                                            "Reshape",
                                            "Squeeze",
                                            "Unsqueeze",
                                            "Gemm",
                                            "MatMul",
                                            "Identity",
                                            "Constant",
                                            "Shape",
                                            "Gather",
                                            "Cast",
                                            "Slice",
                                            "ConstantOfShape",
                                            "Exp",
                                            "Log",
                                            "Sqrt",
                                            "Pow",
                                            "ReduceMean",
                                            "Transpose",
                                            "Flatten",
                                            "LayerNormalization",
                                            "Softmax",
                                            "Erf",
                                            "Expand",
                                            "Split",
                                            "Range",
                                            "Equal",
                                            "Where"};
  return ops;
}

namespace {

// Drops the graph layers whose stored tensors are exactly an earlier layer's (a module applied
// twice, as FlowNetC's conv1..conv3 on both images); returns how many were dropped.
size_t drop_shared_layers(std::vector<GraphLayer>& layers) {
  std::set<std::string> seen;
  std::vector<GraphLayer> kept;
  size_t dropped = 0;
  for (auto& l : layers) {
    bool stored = !l.tensors.empty();
    std::string key = graph_kind_name(l.kind);
    for (const auto& t : l.tensors) {
      stored = stored && t.tensor != nullptr;
      key += "|" + t.role + "=" + t.value;
    }
    if (stored && !seen.insert(key).second) {
      ++dropped;
      continue;
    }
    kept.push_back(std::move(l));
  }
  layers = std::move(kept);
  return dropped;
}

}  // namespace

OnnxConversionReport load_onnx_weights(const OnnxModel& model, DepthNet& net) {
  OnnxNetworkSpec spec;
  spec.arch = net.arch();
  spec.execution_order = net.execution_order();
  spec.unused_in_forward = net.unused_in_forward();
  OnnxConversionReport report = load_onnx_weights(model, net, spec);
  resize_warnings(model, net, report);
  return report;
}

OnnxConversionReport load_onnx_weights(const OnnxModel& model, Module& net,
                                       const OnnxNetworkSpec& spec) {
  const std::string file = model.path.string();
  OnnxConversionReport report;

  // 1. Op types.
  std::map<std::string, int> unsupported;
  for (const auto& n : model.graph.nodes) {
    const std::string key =
        n.domain.empty() ? n.op_type : fmt::format("{} (domain {})", n.op_type, n.domain);
    ++report.op_counts[key];
    const bool supported = n.domain.empty() ? onnx_supported_ops().count(n.op_type) > 0
                                            : spec.custom_ops.count({n.domain, n.op_type}) > 0;
    if (!supported) ++unsupported[key];
  }
  std::vector<std::string> problems;
  if (!unsupported.empty()) {
    std::vector<std::string> parts;
    for (const auto& [op, count] : unsupported) parts.push_back(fmt::format("{} x{}", op, count));
    problems.push_back(fmt::format("unsupported op types: {}", fmt::join(parts, ", ")));
  }
  if (spec.check_graph) spec.check_graph(model, problems, report);
  const bool refused_as_unsupported = !problems.empty();

  // 2. Layers on both sides.
  std::vector<GraphLayer> graph;
  try {
    graph = graph_layers(model.graph);
  } catch (const Error& e) {
    fail(ErrorCategory::format, "{}: {}", file, e.what());
  }
  report.shared_uses = drop_shared_layers(graph);
  std::vector<ModelLayer> used, unused;
  model_layers(net, spec.execution_order, used, unused);
  for (const auto& l : unused)
    for (const auto& [role, t] : l.tensors) report.unused_in_forward.push_back(l.state_name(role));

  int graph_bn = 0, model_bn = 0;
  for (const auto& l : graph) graph_bn += l.kind == LayerKind::batch_norm;
  for (const auto& l : used) model_bn += l.kind == LayerKind::batch_norm;
  if (graph_bn == 0 && model_bn > 0)
    problems.push_back(fmt::format(
        "the graph has no BatchNormalization nodes but {} has {} BatchNorm2d layers: the file was "
        "exported with BatchNorm folded into the convolutions (eval mode with constant folding), "
        "which loses gamma, beta and the running statistics that test-time training needs; "
        "re-export with torch.onnx.export(..., training=torch.onnx.TrainingMode.TRAINING, "
        "do_constant_folding=False, opset_version=14)",
        spec.arch, model_bn));

  // 3. By name: graph layers whose stored tensors carry the network's state names.
  std::map<std::string, std::pair<size_t, std::string>> by_state;  // state name -> (layer, role)
  for (size_t i = 0; i < used.size(); ++i)
    for (const auto& [role, t] : used[i].tensors) by_state[used[i].state_name(role)] = {i, role};
  std::vector<int> graph_to_model(graph.size(), -1);
  std::vector<bool> model_taken(used.size(), false);
  for (size_t gi = 0; gi < graph.size(); ++gi) {
    int target = -1;
    bool consistent = true;
    for (const GraphTensor& t : graph[gi].tensors) {
      if (!t.initializer) continue;
      auto it = by_state.find(t.value);
      if (it == by_state.end() || it->second.second != t.role) continue;
      const int mi = static_cast<int>(it->second.first);
      if (target >= 0 && target != mi) consistent = false;
      target = mi;
    }
    if (target >= 0 && consistent && !model_taken[target]) {
      graph_to_model[gi] = target;
      model_taken[target] = true;
      ++report.by_name;
    }
  }

  // 4. By structure: the remaining layers of both sides in order.
  std::vector<size_t> rest_graph, rest_model;
  for (size_t gi = 0; gi < graph.size(); ++gi)
    if (graph_to_model[gi] < 0) rest_graph.push_back(gi);
  for (size_t mi = 0; mi < used.size(); ++mi)
    if (!model_taken[mi]) rest_model.push_back(mi);
  if (rest_graph.size() != rest_model.size() && !rest_graph.empty() && !rest_model.empty()) {
    std::vector<GraphLayer> rg;
    std::vector<ModelLayer> rm;
    for (size_t gi : rest_graph) rg.push_back(graph[gi]);
    for (size_t mi : rest_model) rm.push_back(used[mi]);
    problems.push_back(fmt::format(
        "{} graph weight layers ({}) have no network layer by name and {} network layers ({}) are "
        "left to match them by position: wrong --arch or --width?",
        rg.size(), kind_counts(rg, true), rm.size(), kind_counts(rm, false)));
  }
  const size_t paired = std::min(rest_graph.size(), rest_model.size());
  for (size_t k = 0; k < paired; ++k) {
    graph_to_model[rest_graph[k]] = static_cast<int>(rest_model[k]);
    model_taken[rest_model[k]] = true;
    ++report.by_structure;
  }
  // Every unmatched tensor, in one entry per side.
  std::vector<std::string> unmatched;
  for (size_t k = paired; k < rest_graph.size(); ++k)
    unmatched.push_back(
        fmt::format("{} ({})", tensor_names(graph[rest_graph[k]]), graph[rest_graph[k]].where));
  if (!unmatched.empty())
    problems.push_back(
        fmt::format("graph tensors with no network counterpart: {}", fmt::join(unmatched, "; ")));
  unmatched.clear();
  for (size_t k = paired; k < rest_model.size(); ++k)
    unmatched.push_back(tensor_names(used[rest_model[k]]));
  if (!unmatched.empty())
    problems.push_back(fmt::format("network tensors with no counterpart in the graph: {}",
                                   fmt::join(unmatched, ", ")));

  // 5. Tensors.
  std::map<std::string, Tensor> state;
  for (size_t gi = 0; gi < graph.size(); ++gi)
    if (graph_to_model[gi] >= 0) match_layer(graph[gi], used[graph_to_model[gi]], state, problems);

  // 6. Parameters outside the weight layers, by name.
  std::set<std::string> in_layers;
  for (const auto* side : {&used, &unused})
    for (const ModelLayer& l : *side)
      for (const auto& [role, t] : l.tensors) in_layers.insert(l.state_name(role));
  auto never_read = [&](const std::string& name) {
    for (const std::string& u : spec.unused_in_forward)
      if (name == u || name.rfind(u + ".", 0) == 0) return true;
    return false;
  };
  for (const auto& [name, t] : net.named_parameters()) {
    if (in_layers.count(name)) continue;
    if (never_read(name)) {
      report.unused_in_forward.push_back(name);
      continue;
    }
    const OnnxTensor* init = model.graph.initializer(name);
    if (!init) {
      problems.push_back(fmt::format(
          "network tensor '{}' has no initializer of that name in the graph (export with "
          "do_constant_folding=False keeps the state names)",
          name));
      continue;
    }
    if (!init->values.defined()) {
      problems.push_back(fmt::format("initializer '{}' has data type {} (only FLOAT and DOUBLE)",
                                     name, onnx_data_type_name(init->data_type)));
      continue;
    }
    const std::vector<int64_t> vs(init->values.shape().begin(), init->values.shape().end());
    if (vs != model_shape(t)) {
      problems.push_back(fmt::format("initializer '{}' has shape {} but the network's has {}", name,
                                     shape_text(vs), shape_text(model_shape(t))));
      continue;
    }
    state[name] = init->values;
    ++report.by_name_tensors;
  }

  if (!problems.empty()) {
    constexpr size_t kMaxListed = 100;
    std::string list;
    for (size_t i = 0; i < problems.size() && i < kMaxListed; ++i) list += "\n  - " + problems[i];
    if (problems.size() > kMaxListed)
      list += fmt::format("\n  ... and {} more", problems.size() - kMaxListed);
    fail(refused_as_unsupported ? ErrorCategory::unsupported : ErrorCategory::format,
         "{}: cannot convert to {} ({} problem{}):{}", file, spec.arch, problems.size(),
         problems.size() == 1 ? "" : "s", list);
  }
  const LoadStateReport loaded = net.load_state(state, /*strict=*/false);
  CVD_ASSERT(loaded.unexpected.empty());
  report.tensors = loaded.loaded;
  report.layers = report.by_name + report.by_structure;
  return report;
}

OnnxConversion convert_onnx(const std::filesystem::path& onnx_path, const std::string& arch,
                            double width) {
  OnnxModel model = read_onnx(onnx_path);
  Generator gen(0);
  OnnxConversion c;
  c.net = create_depth_net(arch, width, gen);
  c.report = load_onnx_weights(model, *c.net);
  return c;
}

}  // namespace cvd
