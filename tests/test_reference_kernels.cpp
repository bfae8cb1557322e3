// Validates the float64 reference kernels (kernels/reference), the oracle of every fast kernel,
// against PyTorch: tests/data/op_fixtures.json (written by tools/reference/gen_op_fixtures.py with
// torch 1.13 in float64) holds, per case, one kernel's exact arguments and PyTorch's results. Each
// case runs the kernel registered for (op, cpu, f64) straight from the registry, without the op
// layer, and compares every output (and every tensor updated in place) with
//   max |ours - torch| <= 1e-9 * max(1, max |torch|).
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "engine/dispatch.h"
#include "engine/kernel_params.h"
#include "engine/tensor.h"

namespace cvd {
namespace {

using nlohmann::json;

constexpr double kRelativeTolerance = 1e-9;

const json& fixtures() {
  static const json doc = [] {
    const std::string path = std::string(CVD_SOURCE_DIR) + "/tests/data/op_fixtures.json";
    std::ifstream f(path);
    if (!f) throw std::runtime_error("cannot open " + path);
    return json::parse(f);
  }();
  return doc;
}

OpId op_from_name(const std::string& name) {
  for (int i = 0; i < kNumOps; ++i) {
    if (name == op_name(static_cast<OpId>(i))) return static_cast<OpId>(i);
  }
  throw std::runtime_error("fixture names unknown kernel '" + name + "'");
}

// A JSON tensor: contiguous {"shape", "data"}, or a strided view {"shape", "strides", "offset"}
// of the flat storage "data"; "dtype" "f32" or f64 by default; null is an undefined tensor.
Tensor tensor_from_json(const json& j) {
  if (j.is_null()) return Tensor();
  const DType dtype = j.value("dtype", std::string("f64")) == "f32" ? DType::f32 : DType::f64;
  const std::vector<double> data = j.at("data").get<std::vector<double>>();
  const Shape shape = j.at("shape").get<Shape>();
  if (!j.contains("strides")) return Tensor::from_vector(data, shape, dtype);
  const Tensor storage = Tensor::from_vector(data, {static_cast<int64_t>(data.size())}, dtype);
  auto impl = std::make_shared<TensorImpl>();
  impl->storage = storage.storage();
  impl->shape = shape;
  impl->strides = j.at("strides").get<Shape>();
  impl->offset = storage.offset() + j.at("offset").get<int64_t>();
  impl->dtype = dtype;
  return Tensor(impl);
}

// An output of the expected's shape and dtype, filled with NaN so unwritten elements fail.
Tensor output_like(const json& expected) {
  if (expected.is_null()) return Tensor();
  const DType dtype =
      expected.value("dtype", std::string("f64")) == "f32" ? DType::f32 : DType::f64;
  return Tensor::full(expected.at("shape").get<Shape>(), std::nan(""), dtype);
}

// Empty when `actual` matches `expected` within the tolerance, else a description.
std::string compare(const Tensor& actual, const json& expected) {
  const Shape shape = expected.at("shape").get<Shape>();
  if (actual.shape() != shape) {
    return "shape " + shape_str(actual.shape()) + " != expected " + shape_str(shape);
  }
  const std::vector<double> want = expected.at("data").get<std::vector<double>>();
  const std::vector<double> got = actual.to_vector();
  double scale = 1.0;
  for (double v : want) scale = std::max(scale, std::abs(v));
  double worst = 0.0;
  size_t worst_at = 0;
  for (size_t i = 0; i < want.size(); ++i) {
    const double err =
        std::isnan(got[i]) ? std::numeric_limits<double>::infinity() : std::abs(got[i] - want[i]);
    if (err > worst) worst = err, worst_at = i;
  }
  if (worst <= kRelativeTolerance * scale) return "";
  return fmt::format(
      "max abs error {:.3e} at flat index {} (got {:.17g}, expected {:.17g}), "
      "tolerance {:.3e}",
      worst, worst_at, got[worst_at], want[worst_at], kRelativeTolerance * scale);
}

// The params struct of a kernel, filled from the fixture's "params" (field names as in C++).
struct ParsedParams {
  FillParams fill;
  UnaryParams unary;
  BinaryParams binary;
  ReduceParams reduce;
  ConcatParams concat;
  PadParams pad;
  Conv2dParams conv;
  ConvTranspose2dParams conv_t;
  BatchNormParams bn;
  Pool2dParams pool;
  UpsampleParams upsample;
  LayerNormParams layer_norm;
  MatmulParams matmul;
  GridSampleParams grid;
  AdamParams adam;
  SgdParams sgd;
  const void* ptr = nullptr;
};

UnaryOp unary_op(const std::string& s) {
  static const std::map<std::string, UnaryOp> m = {{"relu", UnaryOp::relu},
                                                   {"clip", UnaryOp::clip},
                                                   {"leaky_relu", UnaryOp::leaky_relu},
                                                   {"sigmoid", UnaryOp::sigmoid},
                                                   {"tanh", UnaryOp::tanh},
                                                   {"exp", UnaryOp::exp},
                                                   {"log", UnaryOp::log},
                                                   {"abs", UnaryOp::abs},
                                                   {"sqrt", UnaryOp::sqrt},
                                                   {"neg", UnaryOp::neg},
                                                   {"reciprocal", UnaryOp::reciprocal},
                                                   {"pow_scalar", UnaryOp::pow_scalar},
                                                   {"mul_scalar", UnaryOp::mul_scalar},
                                                   {"add_scalar", UnaryOp::add_scalar}};
  return m.at(s);
}

BinaryOp binary_op(const std::string& s) {
  static const std::map<std::string, BinaryOp> m = {{"add", BinaryOp::add},
                                                    {"sub", BinaryOp::sub},
                                                    {"mul", BinaryOp::mul},
                                                    {"div", BinaryOp::div},
                                                    {"minimum", BinaryOp::minimum},
                                                    {"maximum", BinaryOp::maximum},
                                                    {"gt", BinaryOp::gt},
                                                    {"ge", BinaryOp::ge},
                                                    {"lt", BinaryOp::lt},
                                                    {"le", BinaryOp::le},
                                                    {"eq", BinaryOp::eq}};
  return m.at(s);
}

template <class P>
void read_conv_common(const json& j, P& p) {
  p.stride_h = j.at("stride_h"), p.stride_w = j.at("stride_w");
  p.pad_top = j.at("pad_top"), p.pad_bottom = j.at("pad_bottom");
  p.pad_left = j.at("pad_left"), p.pad_right = j.at("pad_right");
  p.dilation_h = j.at("dilation_h"), p.dilation_w = j.at("dilation_w");
  p.groups = j.at("groups");
}

void parse_params(const std::string& kernel, const json& j, ParsedParams& p) {
  if (kernel == "fill") {
    p.fill.value = j.at("value");
    p.ptr = &p.fill;
  } else if (kernel == "unary" || kernel == "unary_backward") {
    p.unary = {unary_op(j.at("op")), j.at("a"), j.at("b")};
    p.ptr = &p.unary;
  } else if (kernel == "binary") {
    p.binary.op = binary_op(j.at("op"));
    p.ptr = &p.binary;
  } else if (kernel == "reduce_sum") {
    p.reduce.dims = j.at("dims").get<std::vector<int>>();
    p.ptr = &p.reduce;
  } else if (kernel == "concat") {
    p.concat.dim = j.at("dim");
    p.ptr = &p.concat;
  } else if (kernel == "pad") {
    p.pad = {j.at("before").get<std::vector<int64_t>>(), j.at("after").get<std::vector<int64_t>>(),
             j.at("value")};
    p.ptr = &p.pad;
  } else if (kernel.rfind("conv2d", 0) == 0) {
    read_conv_common(j, p.conv);
    p.ptr = &p.conv;
  } else if (kernel.rfind("conv_transpose2d", 0) == 0) {
    read_conv_common(j, p.conv_t);
    p.conv_t.output_padding_h = j.at("output_padding_h");
    p.conv_t.output_padding_w = j.at("output_padding_w");
    p.ptr = &p.conv_t;
  } else if (kernel.rfind("batch_norm", 0) == 0) {
    p.bn = BatchNormParams{};
    p.bn.training = j.at("training");
    p.bn.momentum = j.at("momentum");
    p.bn.eps = j.at("eps");
    p.ptr = &p.bn;
  } else if (kernel.rfind("max_pool2d", 0) == 0 || kernel.rfind("avg_pool2d", 0) == 0) {
    p.pool.kernel_h = j.at("kernel_h"), p.pool.kernel_w = j.at("kernel_w");
    p.pool.stride_h = j.at("stride_h"), p.pool.stride_w = j.at("stride_w");
    p.pool.pad_top = j.at("pad_top"), p.pool.pad_bottom = j.at("pad_bottom");
    p.pool.pad_left = j.at("pad_left"), p.pool.pad_right = j.at("pad_right");
    p.pool.ceil_mode = j.at("ceil_mode"), p.pool.count_include_pad = j.at("count_include_pad");
    p.ptr = &p.pool;
  } else if (kernel.rfind("upsample_", 0) == 0) {
    p.upsample.align_corners = j.value("align_corners", false);
    p.upsample.scale_h = j.value("scale_h", 0.0);
    p.upsample.scale_w = j.value("scale_w", 0.0);
    p.ptr = &p.upsample;
  } else if (kernel.rfind("layer_norm", 0) == 0) {
    p.layer_norm.eps = j.at("eps");
    p.ptr = &p.layer_norm;
  } else if (kernel == "matmul") {
    p.matmul = {j.at("trans_a"), j.at("trans_b")};
    p.ptr = &p.matmul;
  } else if (kernel.rfind("grid_sample", 0) == 0) {
    p.grid.padding = j.at("padding") == "border" ? GridPadding::border : GridPadding::zeros;
    p.grid.align_corners = j.at("align_corners");
    p.ptr = &p.grid;
  } else if (kernel == "adam_update") {
    p.adam = {j.at("lr"),  j.at("beta1"),        j.at("beta2"),
              j.at("eps"), j.at("weight_decay"), j.at("step")};
    p.ptr = &p.adam;
  } else if (kernel == "sgd_update") {
    p.sgd = {j.at("lr"),           j.at("momentum"), j.at("dampening"),
             j.at("weight_decay"), j.at("nesterov"), j.at("first_step")};
    p.ptr = &p.sgd;
  }
  // copy and where take no params
}

// Indices of all fixture cases; none when the file is unreadable (then the coverage test below
// fails with the reason).
std::vector<size_t> all_case_indices() {
  size_t n = 0;
  try {
    n = fixtures().at("cases").size();
  } catch (const std::exception&) {
  }
  std::vector<size_t> idx(n);
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  return idx;
}

class ReferenceKernelVsTorch : public ::testing::TestWithParam<size_t> {};

TEST_P(ReferenceKernelVsTorch, MatchesPyTorchFloat64) {
  const json& c = fixtures().at("cases").at(GetParam());
  const std::string kernel = c.at("kernel");
  SCOPED_TRACE("case " + c.at("name").get<std::string>() + " (kernel " + kernel + ")");

  const KernelInfo* info =
      kernel_registry().find(op_from_name(kernel), DeviceType::cpu, DType::f64);
  ASSERT_NE(info, nullptr) << "no (cpu, f64) kernel registered";
  ASSERT_STREQ(info->impl, "reference");

  ParsedParams params;
  parse_params(kernel, c.at("params"), params);
  KernelArgs args;
  args.params = params.ptr;
  for (const json& t : c.at("in")) args.in.push_back(tensor_from_json(t));
  for (const json& t : c.at("out")) args.out.push_back(output_like(t));
  info->fn(args);

  for (size_t i = 0; i < args.out.size(); ++i) {
    if (c["out"][i].is_null()) continue;
    EXPECT_EQ(compare(args.out[i], c["out"][i]), "") << "output " << i;
  }
  if (c.contains("inplace")) {
    for (size_t i = 0; i < c["inplace"].size(); ++i) {
      if (c["inplace"][i].is_null()) continue;
      EXPECT_EQ(compare(args.in[i], c["inplace"][i]), "") << "input " << i << " after the update";
    }
  }
}

std::string case_name(const ::testing::TestParamInfo<size_t>& info) {
  std::string s = fixtures().at("cases").at(info.param).at("name");
  for (char& ch : s) {
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  }
  return s + "_" + std::to_string(info.param);
}

INSTANTIATE_TEST_SUITE_P(Fixtures, ReferenceKernelVsTorch, ::testing::ValuesIn(all_case_indices()),
                         case_name);

// Every op of the dispatch table has a reference kernel, and PyTorch fixtures exercise it.
TEST(ReferenceKernels, EveryOpIsRegisteredAndCoveredByFixtures) {
  std::set<std::string> covered;
  for (const json& c : fixtures().at("cases")) covered.insert(c.at("kernel").get<std::string>());
  for (int i = 0; i < kNumOps; ++i) {
    const OpId op = static_cast<OpId>(i);
    const KernelInfo* info = kernel_registry().find(op, DeviceType::cpu, DType::f64);
    ASSERT_NE(info, nullptr) << op_name(op);
    EXPECT_STREQ(info->impl, "reference") << op_name(op);
    // FlowNet2's ops have no torch.nn counterpart: their PyTorch check is the FlowNet2 parity
    // test (tests/test_flownet2.cpp, pure-torch correlation), plus the op table's gradient checks.
    static const std::set<std::string> checked_elsewhere = {
        "correlation", "correlation_backward", "channel_norm", "channel_norm_backward"};
    if (checked_elsewhere.count(op_name(op))) continue;
    EXPECT_TRUE(covered.count(op_name(op))) << "no fixture for " << op_name(op);
  }
}

// Kernels check their preconditions: an output of the wrong size is an internal error, not a
// silent out-of-bounds write.
TEST(ReferenceKernels, RejectsArgumentsThatBreakTheContract) {
  const KernelInfo* conv = kernel_registry().find(OpId::conv2d, DeviceType::cpu, DType::f64);
  ASSERT_NE(conv, nullptr);
  Conv2dParams p;  // stride 1, no padding: 5x5 input, 3x3 kernel -> 3x3 output
  KernelArgs args;
  args.params = &p;
  args.in = {Tensor::zeros({1, 2, 5, 5}, DType::f64), Tensor::zeros({4, 2, 3, 3}, DType::f64),
             Tensor()};
  args.out = {Tensor::zeros({1, 4, 4, 4}, DType::f64)};
  try {
    conv->fn(args);
    FAIL() << "conv2d accepted a 4x4 output for a 3x3 result";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::internal);
  }
  args.out = {Tensor::zeros({1, 4, 3, 3}, DType::f32)};  // wrong dtype
  EXPECT_THROW(conv->fn(args), Error);
  args.out = {Tensor::zeros({1, 4, 3, 3}, DType::f64)};
  EXPECT_NO_THROW(conv->fn(args));
}

}  // namespace
}  // namespace cvd
