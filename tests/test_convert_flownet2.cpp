// FlowNet2 ONNX conversion (tools/convert/onnx_flownet2.h, `cvd convert --arch flownet2`).
//
// Fixture: tests/data/onnx/flownet2_tiny.onnx, written by
// tools/reference/export_flownet2_onnx.py: the PyTorch reference FlowNet2 at width 1/32 with the
// weights of tests/data/models/flownet2_fixture.cvdw (the export script asserts they are equal),
// Correlation / Resample2d / ChannelNorm as custom ops of domain cvd.flownet2. The reference
// outputs are that fixture's PyTorch float64 outputs on its image pair.
//
// Tolerances: the converted network's flow vs PyTorch's, max abs error relative to the largest
// reference magnitude: f32 1e-5 (the native parity test measured 6e-7), f64 1e-11. Converted
// weights equal the fixture's exactly (both are the same f32 values).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/error.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "pipeline/io/flow_io.h"
#include "tests/onnx_anonymize.h"
#include "tests/test_support.h"
#include "tools/convert/onnx_flownet2.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

constexpr double kWidth = 1.0 / 32;  // the fixtures' width
constexpr double kF32Tol = 1e-5;
constexpr double kF64Tol = 1e-11;

fs::path onnx_file() { return test::source_dir() / "tests/data/onnx/flownet2_tiny.onnx"; }
fs::path parity_fixture() { return test::source_dir() / "tests/data/models/flownet2_fixture.cvdw"; }

double max_abs(const Tensor& t) {
  double m = 0;
  for (double v : t.to_vector()) m = std::max(m, std::abs(v));
  return m;
}

double max_abs_diff(const Tensor& a, const Tensor& b) {
  EXPECT_EQ(shape_str(a.shape()), shape_str(b.shape()));
  const auto va = a.to_vector(), vb = b.to_vector();
  if (va.size() != vb.size()) return INFINITY;
  double m = 0;
  for (size_t i = 0; i < va.size(); ++i) m = std::max(m, std::abs(va[i] - vb[i]));
  return m;
}

// Names of the network's weight modules (Conv2d / ConvTranspose2d): one layer each.
size_t weight_layer_count(const FlowNet2& net) {
  size_t n = 0;
  for (const auto& [name, m] : net.named_modules())
    n += m->type_name() == "Conv2d" || m->type_name() == "ConvTranspose2d";
  return n;
}

// The error message of `f`, which must throw a cvd::Error of category `cat`.
template <class F>
std::string error_of(F&& f, ErrorCategory cat) {
  try {
    f();
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), cat) << e.what();
    return e.what();
  }
  ADD_FAILURE() << "converted without an error";
  return {};
}

OnnxNode* nth_node(OnnxModel& m, const std::string& op_type, int n) {
  for (auto& node : m.graph.nodes)
    if (node.op_type == op_type && n-- == 0) return &node;
  return nullptr;
}

void set_int_attribute(OnnxNode& node, const std::string& name, int64_t value) {
  for (auto& a : node.attributes)
    if (a.name == name) {
      a.i = value;
      return;
    }
  ADD_FAILURE() << node.op_type << " has no attribute " << name;
}

TEST(ConvertFlowNet2, FixtureHasTheCustomOps) {
  const OnnxModel m = read_onnx(onnx_file());
  std::map<std::string, int> custom;
  for (const auto& n : m.graph.nodes)
    if (n.domain == kFlowNet2OnnxDomain) ++custom[n.op_type];
  EXPECT_EQ(custom["Correlation"], 1);
  EXPECT_EQ(custom["Resample2d"], 4);
  EXPECT_EQ(custom["ChannelNorm"], 6);
  bool imported = false;
  for (const auto& [domain, version] : m.opset_imports)
    imported = imported || (domain == kFlowNet2OnnxDomain && version == 1);
  EXPECT_TRUE(imported) << "opset import cvd.flownet2 v1";
  const OnnxNode* corr = nth_node(const_cast<OnnxModel&>(m), "Correlation", 0);
  ASSERT_NE(corr, nullptr);
  EXPECT_EQ(corr->int_attribute("max_displacement", -1), 20);
  EXPECT_EQ(corr->int_attribute("stride2", -1), 2);
}

// Names, counts and values of the converted parameters are the native network's / the fixture's.
TEST(ConvertFlowNet2, ParametersAreTheNativeNetworksWithTheFixtureWeights) {
  OnnxFlowNet2Conversion c = convert_onnx_flownet2(onnx_file(), kWidth);
  Generator gen(5);
  FlowNet2 native(kWidth, gen);
  EXPECT_EQ(c.net->parameter_count(), native.parameter_count());
  const auto converted = c.net->named_parameters();
  const auto expected = native.named_parameters();
  ASSERT_EQ(converted.size(), expected.size());
  for (size_t i = 0; i < converted.size(); ++i) EXPECT_EQ(converted[i].first, expected[i].first);

  const size_t layers = weight_layer_count(native);
  EXPECT_EQ(c.report.layers, layers);
  EXPECT_EQ(c.report.by_name, layers);
  EXPECT_EQ(c.report.shared_uses, 3u) << "FlowNetC's conv1..conv3 run on both images";
  EXPECT_EQ(c.report.tensors, native.state_dict().size());
  EXPECT_TRUE(c.report.unused_in_forward.empty());
  EXPECT_TRUE(c.report.warnings.empty()) << c.report.warnings.front();

  const CvdwReader fixture(parity_fixture());
  size_t compared = 0;
  for (const auto& [name, t] : converted) {
    EXPECT_EQ(max_abs_diff(t, fixture.tensor("param/" + name)), 0.0) << name;
    ++compared;
  }
  EXPECT_EQ(compared, converted.size());
  // The parameter count of the fixture (PyTorch's state_dict) is the converted network's.
  int64_t fixture_params = 0;
  for (const auto& e : fixture.header().tensors)
    if (e.name.rfind("param/", 0) == 0) fixture_params += fixture.tensor(e.name).numel();
  EXPECT_EQ(fixture_params, c.net->parameter_count());
}

class ConvertFlowNet2Parity : public ::testing::TestWithParam<DType> {};

// The converted network's flow on the fixture's image pair equals PyTorch's.
TEST_P(ConvertFlowNet2Parity, FlowMatchesPyTorch) {
  const DType dt = GetParam();
  OnnxFlowNet2Conversion c = convert_onnx_flownet2(onnx_file(), kWidth);
  c.net->to(dt);
  c.net->eval();
  const CvdwReader fixture(parity_fixture());
  NoGradGuard ng;
  const Tensor out =
      c.net->forward_pair(fixture.tensor("input/img0").to(dt), fixture.tensor("input/img1").to(dt));
  const Tensor ref = fixture.tensor("output").to(DType::f64);
  const double range = max_abs(ref);
  EXPECT_GT(range, 0.5) << "the reference flow should be a few pixels";
  EXPECT_LE(max_abs_diff(out, ref), (dt == DType::f32 ? kF32Tol : kF64Tol) * range);
}

INSTANTIATE_TEST_SUITE_P(DTypes, ConvertFlowNet2Parity, ::testing::Values(DType::f32, DType::f64),
                         [](const ::testing::TestParamInfo<DType>& i) {
                           return std::string(i.param == DType::f32 ? "f32" : "f64");
                         });

// With the initializer names replaced (and shuffled), the layers are matched by graph structure
// to the same tensors.
TEST(ConvertFlowNet2, AnonymousInitializersMatchByStructure) {
  OnnxModel model = read_onnx(onnx_file());
  test::anonymize_initializers(model, 11);

  Generator gen(3);
  FlowNet2 anon(kWidth, gen);
  const OnnxConversionReport r = load_onnx_flownet2_weights(model, anon);
  EXPECT_EQ(r.by_name, 0u);
  EXPECT_EQ(r.by_structure, r.layers);
  EXPECT_EQ(r.layers, weight_layer_count(anon));
  const CvdwReader fixture(parity_fixture());
  for (const auto& [name, t] : anon.named_parameters())
    EXPECT_EQ(max_abs_diff(t, fixture.tensor("param/" + name)), 0.0) << name;
}

// Custom-op attributes that cvd's FlowNet2 does not implement: one error naming each node and
// attribute.
TEST(ConvertFlowNet2, UnsupportedAttributesNameTheNodeAndAttribute) {
  OnnxModel model = read_onnx(onnx_file());
  OnnxNode* corr = nth_node(model, "Correlation", 0);
  OnnxNode* warp = nth_node(model, "Resample2d", 2);
  OnnxNode* norm = nth_node(model, "ChannelNorm", 5);
  ASSERT_TRUE(corr && warp && norm);
  corr->name = "corr";
  warp->name = "warp_sd";
  norm->name = "norm_last";
  set_int_attribute(*corr, "max_displacement", 16);
  set_int_attribute(*warp, "kernel_size", 3);
  norm->attributes.clear();  // norm_deg missing
  OnnxAttribute extra;
  extra.name = "dilation";
  extra.type = OnnxAttributeType::int64;
  extra.i = 2;
  corr->attributes.push_back(extra);

  Generator gen(1);
  FlowNet2 net(kWidth, gen);
  const std::string msg =
      error_of([&] { load_onnx_flownet2_weights(model, net); }, ErrorCategory::unsupported);
  EXPECT_NE(msg.find(onnx_file().string()), std::string::npos) << msg;
  EXPECT_NE(msg.find("cannot convert to flownet2 (4 problems)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("Correlation node 'corr': attribute max_displacement = 16 is not supported"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("Correlation node 'corr': unknown attribute 'dilation'"), std::string::npos)
      << msg;
  EXPECT_NE(msg.find("Resample2d node 'warp_sd': attribute kernel_size = 3 is not supported"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("ChannelNorm node 'norm_last': attribute norm_deg is missing"),
            std::string::npos)
      << msg;
}

// Unknown ops (a custom op of the FlowNet2 domain cvd does not know, a standard op it does not
// convert, a FlowNet2 op in another domain) are listed by name with counts.
TEST(ConvertFlowNet2, UnknownOpsAreListedByName) {
  OnnxModel model = read_onnx(onnx_file());
  OnnxNode* first_norm = nth_node(model, "ChannelNorm", 0);
  ASSERT_NE(first_norm, nullptr);
  first_norm->op_type = "FancyWarp";
  OnnxNode* last_norm = nth_node(model, "ChannelNorm", 4);
  ASSERT_NE(last_norm, nullptr);
  last_norm->domain = "com.example";
  OnnxNode* resize = nth_node(model, "Resize", 0);
  ASSERT_NE(resize, nullptr);
  resize->op_type = "GridSample";

  Generator gen(1);
  FlowNet2 net(kWidth, gen);
  const std::string msg =
      error_of([&] { load_onnx_flownet2_weights(model, net); }, ErrorCategory::unsupported);
  EXPECT_NE(msg.find("unsupported op types: "), std::string::npos) << msg;
  EXPECT_NE(msg.find("ChannelNorm (domain com.example) x1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("FancyWarp (domain cvd.flownet2) x1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("GridSample x1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("the graph has 4 ChannelNorm nodes (domain cvd.flownet2), FlowNet2 has 6"),
            std::string::npos)
      << msg;
  EXPECT_EQ(msg.find("Correlation"), std::string::npos) << "Correlation is supported: " << msg;
}

TEST(ConvertFlowNet2, WrongWidthListsShapeMismatches) {
  const std::string msg =
      error_of([] { convert_onnx_flownet2(onnx_file(), 2 * kWidth); }, ErrorCategory::format);
  EXPECT_NE(msg.find("has shape"), std::string::npos) << msg;
  EXPECT_NE(msg.find("flownetc.conv1.0.weight"), std::string::npos) << msg;
}

// A depth-network graph is not FlowNet2: its ops convert, its layers do not.
TEST(ConvertFlowNet2, DepthNetworkGraphIsRefused) {
  const fs::path midas = test::source_dir() / "tests/data/onnx/midas_small_tiny.onnx";
  const std::string msg =
      error_of([&] { convert_onnx_flownet2(midas, kWidth); }, ErrorCategory::unsupported);
  EXPECT_NE(msg.find("the graph has 0 Correlation nodes"), std::string::npos) << msg;
  EXPECT_NE(msg.find("cannot convert to flownet2"), std::string::npos) << msg;
}

std::string q(const fs::path& p) { return "'" + p.string() + "'"; }

TEST(ConvertFlowNet2Cli, ConvertWritesWeightsTheFlowEstimatorLoads) {
  test::TempDir dir;
  const fs::path out = dir / "flownet2.cvdw";
  auto r =
      test::run_cvd("convert " + q(onnx_file()) + " --arch flownet2 --width 0.03125 -o " + q(out));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("matched by name"), std::string::npos) << r.output;
  const CvdwContents w = read_cvdw(out);
  EXPECT_EQ(w.header.model, "flownet2");
  EXPECT_EQ(w.header.config.at("width").get<double>(), kWidth);
  Generator gen(2);
  FlowNet2 net(kWidth, gen);
  load_weights(net, out, /*strict=*/true);
  const CvdwReader fixture(parity_fixture());
  EXPECT_EQ(max_abs_diff(net.find_tensor("flownetc.conv3_1.0.weight"),
                         fixture.tensor("param/flownetc.conv3_1.0.weight")),
            0.0);

  // The written weights run in `cvd flow --method flownet2 --model`.
  cv::Mat a(64, 128, CV_8UC3), b;
  cv::RNG(5).fill(a, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(a, a, {0, 0}, 2.0);
  cv::warpAffine(a, b, cv::Matx23d(1, 0, 2, 0, 1, 1), a.size(), cv::INTER_LINEAR,
                 cv::BORDER_REFLECT);
  cv::imwrite((dir / "a.png").string(), a);
  cv::imwrite((dir / "b.png").string(), b);
  r = test::run_cvd("flow " + q(dir / "a.png") + " " + q(dir / "b.png") + " -o " +
                    q(dir / "f.flo") + " --method flownet2 --no-homography --model " + q(out));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const cv::Mat flow = read_flo(dir / "f.flo");
  EXPECT_EQ(flow.size(), a.size());
  EXPECT_GT(cv::norm(flow, cv::NORM_INF), 0.0);

  r = test::run_cvd("convert " + q(onnx_file()) + " --arch flownet2 -o " + q(dir / "x.cvdw"));
  EXPECT_EQ(r.exit_code, 3) << r.output;  // width 1 vs the tiny file: kExitBadInput
  EXPECT_NE(r.output.find("has shape"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "x.cvdw"));
}

}  // namespace
}  // namespace cvd
