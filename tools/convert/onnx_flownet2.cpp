#include "tools/convert/onnx_flownet2.h"

#include <fmt/format.h>

#include <map>

#include "engine/error.h"
#include "engine/random.h"

namespace cvd {

namespace {

// One attribute of a custom op: its name, the only value cvd implements, and whether a node
// may leave it out.
struct AttributeRule {
  const char* name;
  int64_t value;
  bool required;
};

struct CustomOpRule {
  const char* op_type;
  size_t inputs;
  int expected_nodes;  // in FlowNet2
  std::vector<AttributeRule> attributes;
};

// What models/flownet2 implements (FlowNetC's Correlation, flownet2's Resample2d / ChannelNorm).
const std::vector<CustomOpRule>& custom_op_rules() {
  static const std::vector<CustomOpRule> rules = {
      {"Correlation",
       2,
       1,
       {{"pad_size", 20, true},
        {"kernel_size", 1, true},
        {"max_displacement", 20, true},
        {"stride1", 1, true},
        {"stride2", 2, true},
        {"corr_multiply", 1, true}}},
      {"Resample2d", 2, 4, {{"kernel_size", 1, true}, {"bilinear", 1, false}}},
      {"ChannelNorm", 1, 6, {{"norm_deg", 2, true}}},
  };
  return rules;
}

void check_custom_node(const OnnxNode& n, size_t index, const CustomOpRule& rule,
                       std::vector<std::string>& problems) {
  const std::string where = n.describe(index);
  if (n.inputs.size() != rule.inputs || n.outputs.size() != 1)
    problems.push_back(fmt::format("{}: {} inputs and {} outputs, FlowNet2's {} has {} and 1",
                                   where, n.inputs.size(), n.outputs.size(), rule.op_type,
                                   rule.inputs));
  for (const AttributeRule& r : rule.attributes) {
    const OnnxAttribute* a = n.attribute(r.name);
    if (!a) {
      if (r.required)
        problems.push_back(fmt::format("{}: attribute {} is missing (cvd implements {} = {})",
                                       where, r.name, r.name, r.value));
      continue;
    }
    if (a->type != OnnxAttributeType::int64) {
      problems.push_back(fmt::format("{}: attribute {} is not an int (attribute type {})", where,
                                     r.name, static_cast<int>(a->type)));
      continue;
    }
    if (a->i != r.value)
      problems.push_back(
          fmt::format("{}: attribute {} = {} is not supported (cvd's FlowNet2 implements {} = {})",
                      where, r.name, a->i, r.name, r.value));
  }
  for (const OnnxAttribute& a : n.attributes) {
    bool known = false;
    for (const AttributeRule& r : rule.attributes) known = known || a.name == r.name;
    if (!known)
      problems.push_back(fmt::format("{}: unknown attribute '{}' (cvd's {} knows {})", where,
                                     a.name, rule.op_type, [&] {
                                       std::vector<std::string> names;
                                       for (const auto& r : rule.attributes)
                                         names.emplace_back(r.name);
                                       return fmt::format("{}", fmt::join(names, ", "));
                                     }()));
  }
}

void check_flownet2_graph(const OnnxModel& model, std::vector<std::string>& problems,
                          OnnxConversionReport& report) {
  std::map<std::string, int> seen;
  int linear = 0, nearest = 0, linear_not_half_pixel = 0;
  for (size_t i = 0; i < model.graph.nodes.size(); ++i) {
    const OnnxNode& n = model.graph.nodes[i];
    if (n.domain == kFlowNet2OnnxDomain) {
      for (const CustomOpRule& rule : custom_op_rules())
        if (n.op_type == rule.op_type) {
          ++seen[rule.op_type];
          check_custom_node(n, i, rule, problems);
        }
    } else if (n.domain.empty() && (n.op_type == "Resize" || n.op_type == "Upsample")) {
      const std::string mode = n.string_attribute("mode", "nearest");
      if (mode == "linear" || mode == "bilinear") {
        ++linear;
        const std::string ct = n.string_attribute("coordinate_transformation_mode", "half_pixel");
        if (n.op_type == "Resize" && ct != "half_pixel" && ct != "pytorch_half_pixel")
          ++linear_not_half_pixel;
      } else {
        ++nearest;
      }
    }
  }
  for (const CustomOpRule& rule : custom_op_rules())
    if (seen[rule.op_type] != rule.expected_nodes)
      problems.push_back(fmt::format("the graph has {} {} node{} (domain {}), FlowNet2 has {}",
                                     seen[rule.op_type], rule.op_type,
                                     seen[rule.op_type] == 1 ? "" : "s", kFlowNet2OnnxDomain,
                                     rule.expected_nodes));
  // The graph is not executed, so upsampling modes that differ from FlowNet2's (bilinear with
  // align_corners=False after FlowNetC and FlowNetS 1, nearest after FlowNetS 2 and FlowNetSD)
  // only mean that the file's own outputs are not the network's.
  if (linear != 2 || nearest != 2 || linear_not_half_pixel > 0)
    report.warnings.push_back(fmt::format(
        "the graph upsamples with {} bilinear ({} of them not align_corners=False) and {} nearest "
        "Resize/Upsample nodes where FlowNet2 has 2 bilinear (align_corners=False) and 2 "
        "nearest: the weights convert, but the file's own outputs differ from cvd's FlowNet2",
        linear, linear_not_half_pixel, nearest));
}

}  // namespace

std::vector<std::string> flownet2_onnx_execution_order() {
  std::vector<std::string> order;
  auto add = [&](const std::string& net, std::initializer_list<const char*> names) {
    for (const char* n : names) order.push_back(net + "." + n);
  };
  auto decoder = [&](const std::string& net) {
    add(net, {"conv4", "conv4_1", "conv5", "conv5_1", "conv6", "conv6_1", "predict_flow6",
              "deconv5", "upsampled_flow6_to_5", "predict_flow5", "deconv4", "upsampled_flow5_to_4",
              "predict_flow4", "deconv3", "upsampled_flow4_to_3", "predict_flow3", "deconv2",
              "upsampled_flow3_to_2", "predict_flow2"});
  };
  add("flownetc", {"conv1", "conv2", "conv3", "conv_redir", "conv3_1"});
  decoder("flownetc");
  for (const char* s : {"flownets_1", "flownets_2"}) {
    add(s, {"conv1", "conv2", "conv3", "conv3_1"});
    decoder(s);
  }
  add("flownets_d", {"conv0",       "conv1",         "conv1_1", "conv2",
                     "conv2_1",     "conv3",         "conv3_1", "conv4",
                     "conv4_1",     "conv5",         "conv5_1", "conv6",
                     "conv6_1",     "predict_flow6", "deconv5", "upsampled_flow6_to_5",
                     "inter_conv5", "predict_flow5", "deconv4", "upsampled_flow5_to_4",
                     "inter_conv4", "predict_flow4", "deconv3", "upsampled_flow4_to_3",
                     "inter_conv3", "predict_flow3", "deconv2", "upsampled_flow3_to_2",
                     "inter_conv2", "predict_flow2"});
  add("flownetfusion", {"conv0", "conv1", "conv1_1", "conv2", "conv2_1", "predict_flow2", "deconv1",
                        "upsampled_flow2_to_1", "inter_conv1", "predict_flow1", "deconv0",
                        "upsampled_flow1_to_0", "inter_conv0", "predict_flow0"});
  return order;
}

OnnxNetworkSpec flownet2_onnx_spec() {
  OnnxNetworkSpec spec;
  spec.arch = "flownet2";
  spec.execution_order = flownet2_onnx_execution_order();
  for (const CustomOpRule& rule : custom_op_rules())
    spec.custom_ops.emplace(kFlowNet2OnnxDomain, rule.op_type);
  spec.check_graph = check_flownet2_graph;
  return spec;
}

OnnxConversionReport load_onnx_flownet2_weights(const OnnxModel& model, FlowNet2& net) {
  return load_onnx_weights(model, net, flownet2_onnx_spec());
}

OnnxFlowNet2Conversion convert_onnx_flownet2(const std::filesystem::path& onnx_path, double width) {
  OnnxModel model = read_onnx(onnx_path);
  Generator gen(0);
  OnnxFlowNet2Conversion c;
  c.net = std::make_unique<FlowNet2>(width, gen);
  c.report = load_onnx_flownet2_weights(model, *c.net);
  return c;
}

}  // namespace cvd
