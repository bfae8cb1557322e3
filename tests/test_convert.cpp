// ONNX -> cvd conversion (tools/convert/onnx_graph.h, tools/convert/onnx_weights.h) and the `cvd convert` /
// `cvd depth` commands. Fixtures: tests/data/onnx/, written by tools/reference/export_onnx.py
// (tiny-width PyTorch reference networks exported with BatchNorm kept, and PyTorch's own float64
// outputs for the same weights).
#include <gtest/gtest.h>
#include <onnx/onnx_pb.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/error.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "pipeline/io/image_io.h"
#include "pipeline/io/pfm_io.h"
#include "pipeline/run/run_stages.h"
#include "tests/onnx_anonymize.h"
#include "tests/test_support.h"
#include "tools/convert/onnx_weights.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

fs::path onnx_dir() { return test::source_dir() / "tests" / "data" / "onnx"; }

struct Fixture {
  fs::path onnx;
  CvdwContents expected;
  double width = 1;
  Tensor tensor(const std::string& name) const {
    for (const auto& [n, t] : expected.tensors)
      if (n == name) return t;
    throw std::runtime_error("fixture tensor missing: " + name);
  }
};

// The exported network of `arch` and PyTorch's outputs, or empty when not generated.
std::optional<Fixture> fixture(const std::string& arch) {
  Fixture f;
  f.onnx = onnx_dir() / (arch + "_tiny.onnx");
  const fs::path expected = onnx_dir() / (arch + "_tiny.expected.cvdw");
  if (!fs::exists(f.onnx) || !fs::exists(expected)) return std::nullopt;
  f.expected = read_cvdw(expected);
  f.width = f.expected.header.config.at("width").get<double>();
  return f;
}

#define REQUIRE_FIXTURE(var, arch)                  \
  const std::optional<Fixture> var = fixture(arch); \
  if (!var)                                         \
    GTEST_SKIP() << "no ONNX fixture for " << arch  \
                 << " in tests/data/onnx (run tools/reference/export_onnx.py)";

double max_abs(const Tensor& t) {
  Tensor c = t.to(DType::f64).contiguous();
  double m = 0;
  for (int64_t i = 0; i < c.numel(); ++i) m = std::max(m, std::abs(c.data<double>()[i]));
  return m;
}

double max_abs_diff(const Tensor& a, const Tensor& b) {
  EXPECT_EQ(a.numel(), b.numel());
  Tensor x = a.to(DType::f64).contiguous(), y = b.to(DType::f64).contiguous();
  double m = 0;
  for (int64_t i = 0; i < std::min(x.numel(), y.numel()); ++i)
    m = std::max(m, std::abs(x.data<double>()[i] - y.data<double>()[i]));
  return m;
}

// Raw network output for the fixture's input, in `dtype`, BN in eval or train mode.
Tensor raw_output(DepthNet& net, const Tensor& input, DType dtype, bool train) {
  net.to(dtype);
  net.train(train);
  NoGradGuard no_grad;
  return net.forward_raw(net.normalize_input(input.to(dtype)));
}

class ConvertParity : public ::testing::TestWithParam<std::string> {};

// The converted network reproduces PyTorch's outputs: float64 to 1e-9 relative (same f32 weights,
// both computed in f64, only summation order differs), in both BN modes (eval: running
// statistics; train: batch statistics with gamma / beta). float32: 1e-4 relative in eval mode,
// 2e-3 in train mode, where BN statistics over as few as 2 values (MiDaS layer4 is 1x2 for the
// 32x64 input) amplify float32 rounding.
TEST_P(ConvertParity, MatchesPyTorchOutputs) {
  REQUIRE_FIXTURE(f, GetParam());
  OnnxConversion c = convert_onnx(f->onnx, GetParam(), f->width);
  EXPECT_EQ(c.report.by_name, c.report.layers) << "the export keeps state names";
  EXPECT_EQ(c.report.by_structure, 0u);
  EXPECT_GT(c.report.layers, 10u);
  EXPECT_TRUE(c.report.warnings.empty()) << c.report.warnings.front();
  const Tensor input = f->tensor("input");
  for (const char* mode : {"eval", "train"}) {
    const bool train = std::string(mode) == "train";
    const Tensor expected = f->tensor(std::string(mode) + "/output");
    const double scale = std::max(1.0, max_abs(expected));
    // Fresh conversions: a train-mode forward updates the running statistics.
    OnnxConversion c64 = convert_onnx(f->onnx, GetParam(), f->width);
    const Tensor out64 = raw_output(*c64.net, input, DType::f64, train);
    EXPECT_EQ(out64.shape(), expected.shape()) << mode;
    EXPECT_LE(max_abs_diff(out64, expected), 1e-9 * scale) << GetParam() << " f64 " << mode;
    OnnxConversion c32 = convert_onnx(f->onnx, GetParam(), f->width);
    const Tensor out32 = raw_output(*c32.net, input, DType::f32, train);
    EXPECT_LE(max_abs_diff(out32, expected), (train ? 2e-3 : 1e-4) * scale)
        << GetParam() << " f32 " << mode;
  }
}

// The same graph with every initializer renamed ("w<i>", shuffled in the file) converts by graph
// structure alone to exactly the same tensors.
TEST_P(ConvertParity, AnonymousInitializersMatchByStructure) {
  REQUIRE_FIXTURE(f, GetParam());
  OnnxModel model = read_onnx(f->onnx);
  test::anonymize_initializers(model, 7);

  Generator gen(3);
  auto anon = create_depth_net(GetParam(), f->width, gen);
  const OnnxConversionReport r = load_onnx_weights(model, *anon);
  EXPECT_EQ(r.by_name, 0u);
  EXPECT_EQ(r.by_structure, r.layers);
  OnnxConversion named = convert_onnx(f->onnx, GetParam(), f->width);
  const auto a = anon->state_dict(), b = named.net->state_dict();
  ASSERT_EQ(a.size(), b.size());
  size_t compared = 0;
  for (const auto& [name, t] : b) {
    if (name.ends_with("num_batches_tracked")) continue;
    ASSERT_TRUE(a.count(name)) << name;
    EXPECT_EQ(max_abs_diff(a.at(name), t), 0.0) << name;
    ++compared;
  }
  EXPECT_GT(compared, 20u);
}

// The wrong width: every shape mismatch is listed in one error naming the file.
TEST_P(ConvertParity, WrongWidthListsShapeMismatches) {
  REQUIRE_FIXTURE(f, GetParam());
  try {
    convert_onnx(f->onnx, GetParam(), f->width * 2);
    FAIL() << "converted at the wrong width";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(e.category(), ErrorCategory::format);
    EXPECT_NE(msg.find(f->onnx.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("has shape"), std::string::npos) << msg;
    EXPECT_NE(msg.find("problems"), std::string::npos) << msg;
  }
}

INSTANTIATE_TEST_SUITE_P(Archs, ConvertParity,
                         ::testing::Values("mannequin", "midas_v2", "midas_small"));

TEST(Convert, WrongArchitectureIsRefused) {
  REQUIRE_FIXTURE(f, "mannequin");
  try {
    convert_onnx(f->onnx, "midas_small", 1.0 / 32);
    FAIL() << "a Mannequin graph converted into MiDaS small";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::format);
    EXPECT_NE(std::string(e.what()).find("cannot convert to midas_small"), std::string::npos)
        << e.what();
  }
}

TEST(Convert, UnsupportedOpsAreListedWithCounts) {
  const fs::path file = onnx_dir() / "unsupported_ops.onnx";
  try {
    convert_onnx(file, "mannequin", 1.0 / 16);
    FAIL() << "a graph with unsupported ops converted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(e.category(), ErrorCategory::unsupported);
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("FancyOp (domain com.example) x2"), std::string::npos) << msg;
    EXPECT_NE(msg.find("LSTM x1"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("Reshape x"), std::string::npos) << "Reshape is supported: " << msg;
    // The same error also lists the weights that do not match (a 1-conv graph vs the hourglass).
    EXPECT_NE(msg.find("network tensors with no counterpart"), std::string::npos) << msg;
  }
}

TEST(Convert, ReaderDecodesGraphStructure) {
  const OnnxModel m = read_onnx(onnx_dir() / "unsupported_ops.onnx");
  EXPECT_EQ(m.default_opset(), 14);
  ASSERT_EQ(m.graph.nodes.size(), 5u);
  EXPECT_EQ(m.graph.nodes[1].op_type, "FancyOp");
  EXPECT_EQ(m.graph.nodes[1].domain, "com.example");
  EXPECT_EQ(m.graph.nodes[4].int_attribute("hidden_size", 0), 2);
  const OnnxTensor* w = m.graph.initializer("conv.weight");
  ASSERT_NE(w, nullptr);
  EXPECT_EQ(w->dims, (std::vector<int64_t>{2, 2, 1, 1}));
  ASSERT_TRUE(w->values.defined());
  EXPECT_EQ(w->values.data<float>()[0], 1.0f);  // written as float_data, not raw_data
  EXPECT_EQ(w->values.data<float>()[1], 0.0f);
  const OnnxTensor* shape = m.graph.initializer("shape");
  ASSERT_NE(shape, nullptr);
  EXPECT_EQ(shape->ints, (std::vector<int64_t>{1, 2, 16}));
  EXPECT_EQ(m.graph.inputs, std::vector<std::string>{"x"});
  EXPECT_EQ(m.graph.outputs, std::vector<std::string>{"y"});
}

void expect_format_error(const fs::path& file, const std::string& needle) {
  try {
    read_onnx(file);
    FAIL() << file << " was accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(e.category(), ErrorCategory::format) << msg;
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
  }
}

TEST(Convert, TruncatedAndCorruptFilesAreRejectedNamingTheFile) {
  REQUIRE_FIXTURE(f, "mannequin");
  test::TempDir dir;
  std::ifstream in(f->onnx, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto write = [&](const std::string& name, const std::string& data) {
    std::ofstream(dir / name, std::ios::binary) << data;
    return dir / name;
  };
  expect_format_error(write("half.onnx", bytes.substr(0, bytes.size() / 2)), "truncated");
  expect_format_error(write("cut.onnx", bytes.substr(0, bytes.size() - 3)),
                      "not a valid ONNX model");
  expect_format_error(write("empty.onnx", ""), "empty");
  expect_format_error(write("text.onnx", "hello, this is not a model\n"), "not a valid ONNX model");
  expect_format_error(write("model.pt", std::string("PK\x03\x04", 4) + std::string(100, 'x')),
                      "PyTorch");
  std::string flipped = bytes;
  flipped[0] = static_cast<char>(0xff);  // an invalid first key
  expect_format_error(write("flipped.onnx", flipped), "not a valid ONNX model");
  try {
    read_onnx(dir / "missing.onnx");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::io);
    EXPECT_NE(std::string(e.what()).find("missing.onnx"), std::string::npos);
  }
}

// Well-formed ModelProtos whose one tensor is impossible (tools/reference/export_onnx.py
// --bad-tensors; the fuzzer's findings rebuilt as valid protobuf, so that they reach the checks
// after decoding): each is one Error(format) naming the file, the tensor and the cause, raised
// before any allocation the shape asks for.
TEST(Convert, ImpossibleTensorsAreRefusedNamingTheCause) {
  const fs::path dir = onnx_dir() / "bad_tensors";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"impossibly_large_shape", "tensor 'w' has an impossibly large shape"},
      {"zero_dim_with_huge_strides", "tensor 'w' has an impossibly large shape"},
      {"negative_dimension", "tensor 'w' has negative dimension -1"},
      {"float_data_shorter_than_shape", "holds 1 values in float_data"},
      {"raw_data_shorter_than_shape", "holds 2 values in raw_data"},
      {"int64_raw_data_of_odd_length", "holds 1 values in raw_data"},
  };
  for (const auto& [name, needle] : cases) {
    SCOPED_TRACE(name);
    expect_format_error(dir / (name + ".onnx"), needle);
  }
}

// A model that decodes and passes cvd's own checks but breaks ONNX's rules is refused by the ONNX
// checker, naming the file: here a node reads a value nothing produces.
TEST(Convert, TheOnnxCheckerRefusesAnInvalidGraph) {
  REQUIRE_FIXTURE(f, "mannequin");
  std::ifstream in(f->onnx, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NO_THROW(parse_onnx(bytes, f->onnx)) << "the fixture itself is valid";
  onnx::ModelProto p;
  ASSERT_TRUE(p.ParseFromString(bytes));
  ASSERT_GT(p.graph().node_size(), 1);
  onnx::NodeProto* node = p.mutable_graph()->mutable_node(1);
  ASSERT_GT(node->input_size(), 0);
  node->set_input(0, "a_value_nothing_produces");
  std::string broken;
  ASSERT_TRUE(p.SerializeToString(&broken));
  test::TempDir dir;
  std::ofstream(dir / "dangling.onnx", std::ios::binary) << broken;
  expect_format_error(dir / "dangling.onnx", "the ONNX checker rejects it");
}

TEST(Convert, ExternalDataIsRefusedWithAFix) {
  const fs::path file = onnx_dir() / "external_data.onnx";
  try {
    read_onnx(file);
    FAIL() << "external data accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(e.category(), ErrorCategory::unsupported);
    EXPECT_NE(msg.find("conv.weight"), std::string::npos) << msg;
    EXPECT_NE(msg.find("weights.bin"), std::string::npos) << msg;
    EXPECT_NE(msg.find("save_as_external_data=False"), std::string::npos) << msg;
  }
}

// An eval-mode export with constant folding has no BatchNormalization: refused with the fix.
TEST(Convert, FoldedBatchNormIsRefusedWithTheExportFix) {
  REQUIRE_FIXTURE(f, "mannequin");
  OnnxModel m = read_onnx(f->onnx);
  std::erase_if(m.graph.nodes, [](const OnnxNode& n) { return n.op_type == "BatchNormalization"; });
  Generator gen(0);
  auto net = create_depth_net("mannequin", f->width, gen);
  try {
    load_onnx_weights(m, *net);
    FAIL() << "a graph without BatchNormalization converted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("no BatchNormalization"), std::string::npos) << msg;
    EXPECT_NE(msg.find("do_constant_folding=False"), std::string::npos) << msg;
  }
}

// MiDaS's published ONNX files use align_corners=False: converted, with a warning.
TEST(Convert, ResizeWithoutAlignCornersWarns) {
  REQUIRE_FIXTURE(f, "midas_small");
  OnnxModel m = read_onnx(f->onnx);
  int changed = 0;
  for (auto& n : m.graph.nodes)
    for (auto& a : n.attributes)
      if (a.name == "coordinate_transformation_mode" && a.s == "align_corners") {
        a.s = "half_pixel";
        ++changed;
      }
  ASSERT_GT(changed, 0) << "the fixture has align_corners Resize nodes";
  Generator gen(0);
  auto net = create_depth_net("midas_small", f->width, gen);
  const OnnxConversionReport r = load_onnx_weights(m, *net);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("align_corners"), std::string::npos) << r.warnings[0];
}

// ---- CLI ---------------------------------------------------------------------------------------

std::string q(const fs::path& p) { return "'" + p.string() + "'"; }

TEST(ConvertCli, ConvertWritesWeightsAndRefusesBadInput) {
  REQUIRE_FIXTURE(f, "mannequin");
  test::TempDir dir;
  const fs::path out = dir / "m.cvdw";
  auto r = test::run_cvd("convert " + q(f->onnx) + " --arch mannequin --width 0.0625 -o " + q(out));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("matched by name"), std::string::npos) << r.output;
  const CvdwContents w = read_cvdw(out);
  EXPECT_EQ(w.header.model, "mannequin");
  EXPECT_EQ(w.header.config.at("width").get<double>(), 0.0625);
  EXPECT_EQ(w.header.config.at("source").get<std::string>(), "mannequin_tiny.onnx");
  // The file loads into the network and holds the ONNX weights.
  Generator gen(9);
  auto net = create_depth_net("mannequin", 0.0625, gen);
  load_weights(*net, out);
  const OnnxModel m = read_onnx(f->onnx);
  EXPECT_EQ(
      max_abs_diff(net->find_tensor("seq.0.weight"), m.graph.initializer("seq.0.weight")->values),
      0.0);

  r = test::run_cvd("convert " + q(onnx_dir() / "unsupported_ops.onnx") + " --arch mannequin -o " +
                    q(dir / "bad.cvdw"));
  EXPECT_EQ(r.exit_code, 7) << r.output;  // kExitUnsupported
  EXPECT_NE(r.output.find("FancyOp (domain com.example) x2"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "bad.cvdw"));

  r = test::run_cvd("convert " + q(dir / "nope.onnx") + " --arch mannequin -o " +
                    q(dir / "x.cvdw"));
  EXPECT_EQ(r.exit_code, 4) << r.output;  // kExitIo
  EXPECT_NE(r.output.find("nope.onnx"), std::string::npos) << r.output;

  r = test::run_cvd("convert " + q(f->onnx) + " --arch resnet -o " + q(dir / "x.cvdw"));
  EXPECT_EQ(r.exit_code, 2) << r.output;  // kExitUsage

  r = test::run_cvd("convert " + q(f->onnx) + " --arch mannequin -o " + q(dir / "x.cvdw"));
  EXPECT_EQ(r.exit_code, 3) << r.output;  // width 1 vs a tiny file: kExitBadInput
  EXPECT_NE(r.output.find("has shape"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "x.cvdw"));
}

cv::Mat test_image(int w, int h, int seed) {
  cv::Mat img(h, w, CV_8UC3);
  cv::RNG rng(seed);
  rng.fill(img, cv::RNG::UNIFORM, 0, 255);
  return img;
}

TEST(ConvertCli, DepthOfImagesFoldersAndVideos) {
  REQUIRE_FIXTURE(f, "mannequin");
  test::TempDir dir;
  const fs::path weights = dir / "m.cvdw";
  ASSERT_EQ(
      test::run_cvd("convert " + q(f->onnx) + " --arch mannequin --width 0.0625 -o " + q(weights))
          .exit_code,
      0);
  const cv::Mat img = test_image(80, 60, 1);
  write_image(dir / "a.png", img);

  // Without --model: refused, no weights ship.
  auto r = test::run_cvd("depth " + q(dir / "a.png") + " -o " + q(dir / "out0"));
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("no pretrained weights"), std::string::npos) << r.output;

  // One image: depth equals the network's own prediction at 64x48 (long side 64, multiples of 16).
  r = test::run_cvd("depth --model " + q(weights) + " " + q(dir / "a.png") + " -o " +
                    q(dir / "out1") + " --size 64");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const cv::Mat d = read_pfm(dir / "out1" / "depth" / "a.pfm");
  ASSERT_EQ(d.cols, 64);
  ASSERT_EQ(d.rows, 48);
  EXPECT_TRUE(fs::exists(dir / "out1" / "depth_color" / "a.png"));
  {
    Generator gen(0);
    auto net = create_depth_net("mannequin", 0.0625, gen);
    load_weights(*net, weights);
    net->eval();
    NoGradGuard no_grad;
    const Tensor depth = net->depth(unsqueeze(frame_tensor(img, cv::Size(64, 48)), 0));
    const cv::Mat expect = depth_to_mat(reshape(depth, {48, 64}));
    double maxrel = 0;
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 64; ++x) {
        ASSERT_GT(d.at<float>(y, x), 0.0f);
        maxrel = std::max(maxrel, std::abs(d.at<float>(y, x) / expect.at<float>(y, x) - 1.0));
      }
    EXPECT_LE(maxrel, 1e-6);
  }
  // A single image to a .pfm path: the PNG goes beside it.
  r = test::run_cvd("depth --model " + q(weights) + " " + q(dir / "a.png") + " -o " +
                    q(dir / "single.pfm") + " --size 64");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(read_pfm(dir / "single.pfm").cols, 64);
  EXPECT_TRUE(fs::exists(dir / "single.png"));

  // A folder: one PFM and one PNG per image.
  fs::create_directories(dir / "frames");
  for (int i = 0; i < 3; ++i)
    write_image(dir / "frames" / ("f" + std::to_string(i) + ".png"), test_image(80, 60, 10 + i));
  r = test::run_cvd("depth --model " + q(weights) + " " + q(dir / "frames") + " -o " +
                    q(dir / "out2") + " --size 64");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(fs::exists(dir / "out2" / "depth" / ("f" + std::to_string(i) + ".pfm")));
    EXPECT_TRUE(fs::exists(dir / "out2" / "depth_color" / ("f" + std::to_string(i) + ".png")));
  }

  // A video (MJPG in AVI, OpenCV's FFmpeg backend), when this OpenCV can write one.
  const fs::path video = dir / "v.avi";
  {
    cv::VideoWriter w(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10,
                      cv::Size(80, 60));
    if (w.isOpened())
      for (int i = 0; i < 3; ++i) w.write(test_image(80, 60, 20 + i));
  }
  if (fs::exists(video) && fs::file_size(video) > 0) {
    r = test::run_cvd("depth --model " + q(weights) + " " + q(video) + " -o " + q(dir / "out3") +
                      " --size 64");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_TRUE(fs::exists(dir / "out3" / "depth" / "frame_000000.pfm"));
    EXPECT_TRUE(fs::exists(dir / "out3" / "depth_color" / "frame_000002.png"));
  }

  // --arch that contradicts the weights file: bad input.
  r = test::run_cvd("depth --model " + q(weights) + " --arch midas_v2 " + q(dir / "a.png") +
                    " -o " + q(dir / "out4"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("holds a 'mannequin' network"), std::string::npos) << r.output;
  // A missing input.
  r = test::run_cvd("depth --model " + q(weights) + " " + q(dir / "none.png") + " -o " +
                    q(dir / "out5"));
  EXPECT_EQ(r.exit_code, 3) << r.output;
  EXPECT_NE(r.output.find("none.png"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace cvd
