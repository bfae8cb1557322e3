// The published Depth Anything V2 configurations at full size (ViT-S 24.8 M, ViT-B 97.5 M, ViT-L
// 335.3 M parameters), each built from its architecture-table row at width 1: the reference
// definition's parameter count and state names and shapes, in order
// (tools/reference/gen_depth_anything_fixture.py --states-only). Labelled slow: building ViT-L's
// random weights takes ~30 s.
//
// Optional, full-size conversion parity: where /usr/bin/python3 has torch and onnx
// (CVD_WITH_PYTHON=1 scripts/install-deps.sh), the published network with seeded random weights
// is exported to ONNX at 518 x 518 (tools/reference/export_depth_anything_onnx.py --random-seed
// --expected), converted, and run: every output within 1e-4 of the output range of PyTorch's
// float64 forward in f32. Encoders: CVD_DA2_FULL_SIZE_ENCODERS (default "vits"; "vits vitb vitl"
// for all three, ~4 GB and minutes). Without Python it skips, saying why (CI has no torch).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "models/depth_net_architectures.h"
#include "tests/test_support.h"
#include "tools/convert/onnx_graph.h"
#include "tools/convert/onnx_weights.h"

namespace cvd {
namespace {

void expect_reference_state(const std::string& arch, const std::string& encoder) {
  const auto path =
      test::source_dir() / ("tests/data/models/depth_anything_v2_" + encoder + "_state.json");
  std::ifstream in(path);
  ASSERT_TRUE(in) << path;
  const nlohmann::json ref = nlohmann::json::parse(in);
  Generator gen(0);
  const auto net = create_depth_net(arch, 1.0, gen);
  EXPECT_EQ(net->arch(), arch);
  EXPECT_EQ(net->parameter_count(), ref.at("parameters").get<int64_t>());
  const NamedTensors state = net->named_state();
  ASSERT_EQ(state.size(), ref.at("state").size());
  for (size_t i = 0; i < state.size(); ++i) {
    EXPECT_EQ(state[i].first, ref["state"][i][0].get<std::string>()) << i;
    EXPECT_EQ(state[i].second.shape(), ref["state"][i][1].get<Shape>()) << state[i].first;
  }
}

TEST(DepthAnythingV2, FullSizeViTSMatchesTheReferenceState) {
  expect_reference_state("depth_anything_v2", "vits");
}

TEST(DepthAnythingV2, FullSizeViTBMatchesTheReferenceState) {
  expect_reference_state("depth_anything_v2_vitb", "vitb");
}

TEST(DepthAnythingV2, FullSizeViTLMatchesTheReferenceState) {
  expect_reference_state("depth_anything_v2_vitl", "vitl");
}

TEST(DepthAnythingV2FullSize, ExportConvertsAndReproducesPyTorch) {
  if (std::system("/usr/bin/python3 -c 'import torch, onnx' > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "needs /usr/bin/python3 with torch and onnx (CVD_WITH_PYTHON=1 "
                    "scripts/install-deps.sh) to export the full-size network";
  const char* env = std::getenv("CVD_DA2_FULL_SIZE_ENCODERS");
  std::istringstream encoders(env && *env ? env : "vits");
  for (std::string encoder; encoders >> encoder;) {
    SCOPED_TRACE(encoder);
    const std::string arch =
        encoder == "vits" ? "depth_anything_v2" : "depth_anything_v2_" + encoder;
    test::TempDir dir;
    const auto onnx_path = dir / "da2.onnx", expected_path = dir / "expected.cvdw";
    const auto export_run = test::run_command(
        "OMP_NUM_THREADS=2 /usr/bin/python3 " +
        test::shell_quoted(test::source_dir() / "tools/reference/export_depth_anything_onnx.py") +
        " --random-seed 7 --encoder " + encoder + " -o " + test::shell_quoted(onnx_path) +
        " --expected " + test::shell_quoted(expected_path));
    ASSERT_EQ(export_run.exit_code, 0) << export_run.output;
    OnnxConversion c = convert_onnx(onnx_path, arch, 1.0);
    EXPECT_EQ(c.report.by_structure, 0u) << "every layer matched by name";
    CvdwReader expected(expected_path);
    NoGradGuard ng;
    c.net->eval();
    const auto got = c.net->forward_raw(expected.tensor("input")).to_vector();
    const auto ref = expected.tensor("output").to_vector();
    ASSERT_EQ(got.size(), ref.size());
    const auto [lo, hi] = std::minmax_element(ref.begin(), ref.end());
    ASSERT_GT(*hi - *lo, 0) << "a constant reference output checks nothing";
    double err = 0;
    for (size_t i = 0; i < ref.size(); ++i) err = std::max(err, std::abs(ref[i] - got[i]));
    EXPECT_LE(err, 1e-4 * (*hi - *lo)) << "output range [" << *lo << ", " << *hi << "]";
  }
}

}  // namespace
}  // namespace cvd
