#include "tools/convert/onnx_weights.h"

#include <algorithm>
#include <cmath>

#include "engine/error.h"
#include "engine/layers.h"
#include "engine/ops.h"
#include "engine/random.h"
#include "tools/convert/onnx_weight_layers.h"

namespace cvd {

using namespace onnx_layers;

namespace {

std::string shape_text(const std::vector<int64_t>& dims) {
  return fmt::format("[{}]", fmt::join(dims, ", "));
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
