// `cvd convert` for Depth Anything V2: an opset-17 ONNX export of the reduced network
// (tools/reference/export_depth_anything_onnx.py: LayerNormalization nodes, Linear layers as
// MatMul of a transposed weight, the class token, position embedding and LayerScale gammas as
// named initializers) converts completely, and the converted network reproduces PyTorch's output
// on the export's input (float64: max error 1e-9 of the output range; float32: 1e-4).
#include <gtest/gtest.h>

#include <algorithm>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/ops.h"
#include "models/depth_anything_v2.h"
#include "tests/depth_anything_test_config.h"
#include "tests/test_support.h"
#include "tools/convert/onnx_graph.h"
#include "tools/convert/onnx_weights.h"

namespace cvd {
namespace {

const std::filesystem::path kDir = test::source_dir() / "tests/data/onnx";

TEST(ConvertDepthAnything, TinyExportConvertsAndReproducesPyTorch) {
  CvdwReader expected(kDir / "depth_anything_v2_tiny.expected.cvdw");
  const OnnxModel model = read_onnx(kDir / "depth_anything_v2_tiny.onnx");
  Generator gen(3);
  DepthAnythingV2Net net(
      test::depth_anything_config_from(expected.header().config.at("dav2_config")), gen);
  const OnnxConversionReport r = load_onnx_weights(model, net);
  EXPECT_GT(r.layers, 20u);
  EXPECT_EQ(r.by_name_tensors, 2u + 2 * 4u) << "cls_token, pos_embed and 2 gammas per block";
  // mask_token and refinenet4.resConfUnit1 (4 tensors) are never read by the forward.
  EXPECT_EQ(r.unused_in_forward.size(), 5u);
  for (DType dtype : {DType::f64, DType::f32}) {
    net.to(dtype);
    NoGradGuard ng;
    const Tensor out = net.forward_raw(expected.tensor("input").to(dtype));
    const auto ref = expected.tensor("output").to_vector();
    const auto got = out.to_vector();
    ASSERT_EQ(ref.size(), got.size());
    const auto [lo, hi] = std::minmax_element(ref.begin(), ref.end());
    double err = 0;
    for (size_t i = 0; i < ref.size(); ++i) err = std::max(err, std::abs(ref[i] - got[i]));
    EXPECT_LE(err, (dtype == DType::f64 ? 1e-9 : 1e-4) * (*hi - *lo));
  }
}

TEST(ConvertDepthAnything, WrongConfigurationIsOneErrorListingTheMismatches) {
  const OnnxModel model = read_onnx(kDir / "depth_anything_v2_tiny.onnx");
  Generator gen(3);
  DepthAnythingConfig c = DepthAnythingConfig::vits_scaled(1.0 / 16);  // 12 blocks, not 4
  DepthAnythingV2Net net(c, gen);
  try {
    load_onnx_weights(model, net);
    FAIL() << "a 4-block export cannot fill a 12-block network";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::format);
    EXPECT_NE(std::string(e.what()).find("depth_anything_v2_tiny.onnx"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("shape"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace cvd
