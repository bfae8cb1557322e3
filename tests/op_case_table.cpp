// Part of the cvd_test_support library linked into every test executable.
#include "tests/op_case_table.h"

namespace cvd::test {

namespace {

Conv2dParams conv(int s, int pt, int pb, int pl, int pr, int d = 1, int g = 1) {
  Conv2dParams p;
  p.stride_h = p.stride_w = s;
  p.pad_top = pt;
  p.pad_bottom = pb;
  p.pad_left = pl;
  p.pad_right = pr;
  p.dilation_h = p.dilation_w = d;
  p.groups = g;
  return p;
}

ConvTranspose2dParams deconv(int s, int pad, int out_pad, int d = 1, int g = 1) {
  ConvTranspose2dParams p;
  p.stride_h = p.stride_w = s;
  p.pad_top = p.pad_bottom = p.pad_left = p.pad_right = pad;
  p.output_padding_h = p.output_padding_w = out_pad;
  p.dilation_h = p.dilation_w = d;
  p.groups = g;
  return p;
}

Pool2dParams pool(int k, int s, int pad, bool ceil_mode, bool include_pad = true) {
  Pool2dParams p;
  p.kernel_h = p.kernel_w = k;
  p.stride_h = p.stride_w = s;
  p.pad_top = p.pad_bottom = p.pad_left = p.pad_right = pad;
  p.ceil_mode = ceil_mode;
  p.count_include_pad = include_pad;
  return p;
}

using In = std::vector<Tensor>;

OpCase unary_case(const std::string& name, Init init, std::function<Tensor(const Tensor&)> f) {
  return {name, {{{2, 3, 5, 7}, init}}, [f](const In& x) { return f(x[0]); }};
}

OpCase conv_case(const std::string& name, Shape x, Shape w, bool bias, Conv2dParams p) {
  std::vector<InputSpec> in{{x}, {w}};
  if (bias) in.push_back({{w[0]}});
  return {name, in,
          [p, bias](const In& t) { return conv2d(t[0], t[1], bias ? t[2] : Tensor(), p); }, 5e-5};
}

OpCase deconv_case(const std::string& name, Shape x, Shape w, bool bias, ConvTranspose2dParams p) {
  std::vector<InputSpec> in{{x}, {w}};
  if (bias) in.push_back({{w[1] * p.groups}});
  return {
      name, in,
      [p, bias](const In& t) { return conv_transpose2d(t[0], t[1], bias ? t[2] : Tensor(), p); },
      5e-5};
}

OpCase bn_case(const std::string& name, bool training, bool affine) {
  std::vector<InputSpec> in{{{3, 4, 5, 3}}};
  if (affine) {
    in.push_back({{4}, Init::positive});
    in.push_back({{4}});
  }
  return {name, in, [training, affine](const In& t) {
            // Fresh running statistics per call, so finite differences see the same state.
            Tensor rm = Tensor::full({4}, 0.1, t[0].dtype(), t[0].device());
            Tensor rv = Tensor::full({4}, 1.5, t[0].dtype(), t[0].device());
            BatchNormParams p;
            p.training = training;
            return batch_norm(t[0], rm, rv, affine ? t[1] : Tensor(), affine ? t[2] : Tensor(), p);
          }};
}

// act(batch_norm(x)), optionally read by a convolution, whose backward then regenerates the
// activation from the batch norm's input (engine/rematerialize.h).
OpCase bn_act_case(const std::string& name, bool training, UnaryParams act, bool then_conv) {
  std::vector<InputSpec> in{{{3, 4, 5, 3}}, {{4}, Init::positive}, {{4}}};
  if (then_conv) in.push_back({{2, 4, 3, 3}});
  return {name, in,
          [training, act, then_conv](const In& t) {
            Tensor rm = Tensor::full({4}, 0.1, t[0].dtype(), t[0].device());
            Tensor rv = Tensor::full({4}, 1.5, t[0].dtype(), t[0].device());
            BatchNormParams p;
            p.training = training;
            // x * 3: BN output spread over (-6, 6) and beyond, so relu6 clips on both sides.
            Tensor z = batch_norm_act(t[0], rm, rv, t[1] * 3.0, t[2], p, act);
            return then_conv ? conv2d(z, t[3], Tensor(), conv(1, 1, 1, 1, 1)) : z;
          },
          5e-5};
}

}  // namespace

std::vector<OpCase> all_op_cases() {
  std::vector<OpCase> c;
  // ---- unary ----
  c.push_back(unary_case("relu", Init::away_from_zero, [](auto& x) { return relu(x); }));
  c.push_back(unary_case("relu6", Init::away_from_zero, [](auto& x) { return relu6(x * 4.0); }));
  c.push_back(
      unary_case("clamp", Init::away_from_zero, [](auto& x) { return clamp(x, -0.7, 0.5); }));
  c.push_back(
      unary_case("leaky_relu", Init::away_from_zero, [](auto& x) { return leaky_relu(x, 0.1); }));
  c.push_back(unary_case("sigmoid", Init::normal, [](auto& x) { return sigmoid(x); }));
  c.push_back(unary_case("tanh", Init::normal, [](auto& x) { return tanh(x); }));
  c.push_back(unary_case("exp", Init::normal, [](auto& x) { return exp(x); }));
  c.push_back(unary_case("log", Init::positive, [](auto& x) { return log(x); }));
  c.push_back(unary_case("abs", Init::away_from_zero, [](auto& x) { return abs(x); }));
  c.push_back(unary_case("sqrt", Init::positive, [](auto& x) { return sqrt(x); }));
  c.push_back(unary_case("neg", Init::normal, [](auto& x) { return neg(x); }));
  c.push_back(unary_case("reciprocal", Init::positive, [](auto& x) { return reciprocal(x); }));
  c.push_back(unary_case("pow", Init::positive, [](auto& x) { return pow(x, 1.7); }));
  c.push_back(unary_case("mul_add_scalar", Init::normal, [](auto& x) { return x * 2.5 + 1.0; }));
  c.push_back(unary_case("gelu", Init::normal, [](auto& x) { return gelu(x * 2.0); }));
  c.push_back(unary_case("softplus", Init::normal, [](auto& x) { return softplus(x * 3.0); }));
  // ---- binary, with broadcasting ----
  auto bin = [&](const std::string& n, Shape a, Shape b, Init ib,
                 std::function<Tensor(const Tensor&, const Tensor&)> f) {
    c.push_back({n, {{a}, {b, ib}}, [f](const In& t) { return f(t[0], t[1]); }});
  };
  bin("add_same", {3, 4, 5}, {3, 4, 5}, Init::normal, [](auto& a, auto& b) { return add(a, b); });
  bin("add_bcast_row", {3, 4, 5}, {5}, Init::normal, [](auto& a, auto& b) { return add(a, b); });
  bin("sub_bcast_mid", {2, 3, 4, 5}, {3, 1, 1}, Init::normal,
      [](auto& a, auto& b) { return sub(a, b); });
  bin("mul_bcast_both", {3, 1, 5}, {1, 4, 1}, Init::normal,
      [](auto& a, auto& b) { return mul(a, b); });
  bin("mul_scalar_tensor", {2, 3, 4}, {}, Init::normal, [](auto& a, auto& b) { return mul(a, b); });
  bin("div_bcast", {2, 3, 4}, {3, 1}, Init::positive, [](auto& a, auto& b) { return div(a, b); });
  bin("minimum", {3, 4, 5}, {4, 5}, Init::normal, [](auto& a, auto& b) { return minimum(a, b); });
  bin("maximum", {3, 4, 5}, {3, 4, 5}, Init::normal,
      [](auto& a, auto& b) { return maximum(a, b); });
  c.push_back({"where", {{{3, 4, 5}, Init::mask, false}, {{3, 4, 5}}, {{4, 1}}}, [](const In& t) {
                 return where(t[0], t[1], t[2]);
               }});
  // ---- reductions ----
  c.push_back({"sum_all", {{{3, 4, 5}}}, [](const In& t) { return sum(t[0]); }});
  c.push_back({"sum_dims_keep", {{{2, 3, 4, 5}}}, [](const In& t) {
                 return sum(t[0], {0, 2, 3}, true);
               }});
  c.push_back({"sum_last", {{{3, 4, 7}}}, [](const In& t) { return sum(t[0], {-1}); }});
  c.push_back({"mean_hw", {{{2, 3, 4, 5}}}, [](const In& t) { return mean(t[0], {2, 3}); }});
  // ---- shape and layout ----
  c.push_back({"reshape", {{{3, 4, 5}}}, [](const In& t) { return reshape(t[0], {5, -1}) * 1.5; }});
  c.push_back({"permute", {{{2, 3, 4, 5}}}, [](const In& t) {
                 return permute(t[0], {0, 2, 3, 1}).contiguous();
               }});
  c.push_back({"transpose_matmul", {{{3, 4}}, {{5, 4}}}, [](const In& t) {
                 return matmul(t[0], transpose(t[1], 0, 1));
               }});
  c.push_back({"squeeze_unsqueeze", {{{3, 1, 5}}}, [](const In& t) {
                 return unsqueeze(squeeze(t[0], 1), 0) * 2.0;
               }});
  c.push_back({"narrow", {{{3, 7, 5}}}, [](const In& t) { return narrow(t[0], 1, 2, 4) * 3.0; }});
  c.push_back({"expand", {{{3, 1, 5}}}, [](const In& t) {
                 return expand(t[0], {2, 3, 4, 5}) * 1.0;
               }});
  c.push_back({"concat_dim1", {{{2, 3, 4, 5}}, {{2, 1, 4, 5}}, {{2, 2, 4, 5}}}, [](const In& t) {
                 return concat({t[0], t[1], t[2]}, 1);
               }});
  c.push_back({"concat_last", {{{2, 3, 4}}, {{2, 3, 1}}}, [](const In& t) {
                 return concat({t[0], t[1]}, -1);
               }});
  c.push_back({"pad_asym", {{{2, 3, 4, 5}}}, [](const In& t) {
                 return pad(t[0], {0, 1, 1, 2}, 0.5);
               }});
  c.push_back({"pad_crop", {{{2, 3, 6, 5}}}, [](const In& t) {
                 return pad(t[0], {-1, 2, 1, -2});
               }});
  // ---- convolution ----
  c.push_back(conv_case("conv3x3_p1_bias", {2, 3, 7, 6}, {4, 3, 3, 3}, true, conv(1, 1, 1, 1, 1)));
  c.push_back(
      conv_case("conv3x3_s2_nobias", {2, 3, 9, 8}, {4, 3, 3, 3}, false, conv(2, 1, 1, 1, 1)));
  c.push_back(
      conv_case("conv_tf_same_k3s2", {1, 2, 8, 7}, {3, 2, 3, 3}, false, conv(2, 0, 1, 0, 1)));
  c.push_back(
      conv_case("conv_tf_same_k5s2", {1, 2, 9, 8}, {3, 2, 5, 5}, false, conv(2, 1, 2, 1, 2)));
  c.push_back(conv_case("conv_dilated", {1, 2, 9, 9}, {3, 2, 3, 3}, true, conv(1, 2, 2, 2, 2, 2)));
  c.push_back(
      conv_case("conv_groups2", {2, 4, 6, 5}, {6, 2, 3, 3}, true, conv(1, 1, 1, 1, 1, 1, 2)));
  c.push_back(
      conv_case("conv_depthwise5x5", {2, 4, 7, 7}, {4, 1, 5, 5}, false, conv(1, 2, 2, 2, 2, 1, 4)));
  c.push_back(
      conv_case("conv_depthwise_s2", {1, 3, 8, 8}, {3, 1, 3, 3}, false, conv(2, 0, 1, 0, 1, 1, 3)));
  c.push_back(conv_case("conv1x1", {2, 5, 4, 3}, {7, 5, 1, 1}, true, conv(1, 0, 0, 0, 0)));
  c.push_back(conv_case("conv7x7_s2_p3", {1, 3, 11, 10}, {2, 3, 7, 7}, false, conv(2, 3, 3, 3, 3)));
  c.push_back(conv_case("conv_1px_image", {2, 3, 1, 1}, {4, 3, 3, 3}, true, conv(1, 1, 1, 1, 1)));
  c.push_back(
      conv_case("conv_stride3_odd", {1, 2, 10, 7}, {2, 2, 2, 3}, true, conv(3, 0, 0, 1, 1)));
  c.push_back(deconv_case("deconv_k4s2p1", {2, 3, 4, 5}, {3, 2, 4, 4}, true, deconv(2, 1, 0)));
  c.push_back(deconv_case("deconv_outpad", {1, 2, 3, 4}, {2, 3, 3, 3}, false, deconv(2, 1, 1)));
  c.push_back(
      deconv_case("deconv_groups_dil", {1, 4, 3, 3}, {4, 1, 3, 3}, true, deconv(1, 1, 0, 2, 2)));
  c.push_back(deconv_case("deconv_1px", {2, 2, 1, 1}, {2, 3, 4, 4}, true, deconv(2, 1, 0)));
  // 16 channels per group in and out: sized for the CPU's bf16 path (kernels/cpu/
  // onednn_conv_choice.cpp), which the smaller cases above do not take.
  c.push_back(conv_case("conv3x3_c16", {1, 16, 5, 6}, {16, 16, 3, 3}, true, conv(1, 1, 1, 1, 1)));
  c.push_back(
      deconv_case("deconv_k4s2p1_c16", {1, 16, 3, 3}, {16, 16, 4, 4}, true, deconv(2, 1, 0)));
  // ---- batch norm ----
  c.push_back(bn_case("batch_norm_train_affine", true, true));
  c.push_back(bn_case("batch_norm_train_plain", true, false));
  c.push_back(bn_case("batch_norm_eval_affine", false, true));
  c.push_back(bn_case("batch_norm_eval_plain", false, false));
  c.push_back(bn_act_case("batch_norm_relu_train", true, {UnaryOp::relu}, false));
  c.push_back(bn_act_case("batch_norm_relu6_eval", false, {UnaryOp::clip, 0.0, 6.0}, false));
  c.push_back(bn_act_case("batch_norm_relu_conv_train", true, {UnaryOp::relu}, true));
  c.push_back(bn_act_case("batch_norm_relu6_conv_train", true, {UnaryOp::clip, 0.0, 6.0}, true));
  // ---- pooling ----
  c.push_back({"max_pool3x3_s2_p1", {{{2, 3, 7, 6}}}, [](const In& t) {
                 return max_pool2d(t[0], pool(3, 2, 1, false));
               }});
  c.push_back({"max_pool2_ceil", {{{1, 2, 5, 7}}}, [](const In& t) {
                 return max_pool2d(t[0], pool(2, 2, 0, true));
               }});
  c.push_back({"avg_pool2", {{{2, 3, 6, 8}}}, [](const In& t) {
                 return avg_pool2d(t[0], pool(2, 2, 0, false));
               }});
  c.push_back({"avg_pool3_p1_ceil", {{{1, 2, 7, 6}}}, [](const In& t) {
                 return avg_pool2d(t[0], pool(3, 2, 1, true));
               }});
  c.push_back({"avg_pool3_p1_nopad", {{{1, 2, 7, 6}}}, [](const In& t) {
                 return avg_pool2d(t[0], pool(3, 2, 1, true, false));
               }});
  // ---- resizing ----
  c.push_back({"bilinear_up2_ac", {{{2, 3, 4, 5}}}, [](const In& t) {
                 return upsample_bilinear2d(t[0], 8, 10, true);
               }});
  c.push_back({"bilinear_up2_noac", {{{2, 3, 4, 5}}}, [](const In& t) {
                 return upsample_bilinear2d(t[0], 8, 10, false);
               }});
  c.push_back({"bilinear_odd_ac", {{{1, 2, 5, 3}}}, [](const In& t) {
                 return upsample_bilinear2d(t[0], 7, 11, true);
               }});
  c.push_back({"bilinear_down_noac", {{{1, 2, 9, 7}}}, [](const In& t) {
                 return upsample_bilinear2d(t[0], 4, 3, false);
               }});
  c.push_back({"bilinear_from_1px", {{{1, 2, 1, 1}}}, [](const In& t) {
                 return upsample_bilinear2d(t[0], 3, 2, true);
               }});
  c.push_back({"bilinear_to_1px", {{{1, 2, 4, 3}}}, [](const In& t) {
                 return upsample_bilinear2d(t[0], 1, 1, false);
               }});
  c.push_back({"nearest_up", {{{2, 3, 4, 5}}}, [](const In& t) {
                 return upsample_nearest2d(t[0], 8, 10);
               }});
  c.push_back({"nearest_odd", {{{1, 2, 5, 3}}}, [](const In& t) {
                 return upsample_nearest2d(t[0], 7, 4);
               }});
  c.push_back({"bicubic_up_noac", {{{2, 3, 4, 5}}}, [](const In& t) {
                 return upsample_bicubic2d(t[0], 9, 7, false);
               }});
  c.push_back({"bicubic_up_ac", {{{1, 2, 5, 3}}}, [](const In& t) {
                 return upsample_bicubic2d(t[0], 7, 8, true);
               }});
  c.push_back({"bicubic_down", {{{1, 2, 9, 8}}}, [](const In& t) {
                 return upsample_bicubic2d(t[0], 4, 3, false);
               }});
  // DINOv2's position-embedding resize: scale factors (n + 0.1) / M given, not the sizes.
  c.push_back({"bicubic_scale_factor", {{{1, 3, 5, 5}}}, [](const In& t) {
                 return upsample_bicubic2d(t[0], 7, 4, false, 7.1 / 5, 4.1 / 5);
               }});
  c.push_back({"bicubic_same_size_scaled", {{{1, 2, 4, 4}}}, [](const In& t) {
                 return upsample_bicubic2d(t[0], 4, 4, false, 4.1 / 4, 4.1 / 4);
               }});
  c.push_back({"bicubic_from_1px", {{{1, 2, 1, 1}}}, [](const In& t) {
                 return upsample_bicubic2d(t[0], 3, 2, false);
               }});
  // ---- row normalisations (the transformer's) ----
  c.push_back({"layer_norm_affine", {{{2, 5, 7}}, {{7}, Init::positive}, {{7}}}, [](const In& t) {
                 return layer_norm(t[0], t[1], t[2], 1e-6);
               }});
  c.push_back({"layer_norm_plain", {{{6, 4}}}, [](const In& t) {
                 return layer_norm(t[0], Tensor(), Tensor());
               }});
  c.push_back({"layer_norm_one_column", {{{3, 1}}, {{1}}, {{1}}}, [](const In& t) {
                 return layer_norm(t[0], t[1], t[2]);
               }});
  c.push_back({"softmax_rows", {{{2, 3, 6}}}, [](const In& t) { return softmax(t[0] * 3.0); }});
  c.push_back({"softmax_one_column", {{{4, 1}}}, [](const In& t) { return softmax(t[0]); }});
  // Rows far from 0: the maximum must be subtracted (exp(90) overflows f32).
  c.push_back(
      {"softmax_large_logits", {{{3, 5}}}, [](const In& t) { return softmax(t[0] + 90.0); }});
  // ---- matmul / linear ----
  c.push_back({"matmul_2d", {{{3, 4}}, {{4, 5}}}, [](const In& t) { return matmul(t[0], t[1]); }});
  c.push_back({"matmul_batched", {{{2, 3, 4}}, {{2, 4, 5}}}, [](const In& t) {
                 return matmul(t[0], t[1]);
               }});
  c.push_back(
      {"matmul_shared_b", {{{2, 3, 4}}, {{4, 2}}}, [](const In& t) { return matmul(t[0], t[1]); }});
  c.push_back({"linear", {{{3, 6}}, {{4, 6}}, {{4}}}, [](const In& t) {
                 return linear(t[0], t[1], t[2]);
               }});
  c.push_back({"linear_tokens", {{{2, 5, 6}}, {{4, 6}}, {{4}}}, [](const In& t) {
                 return linear(t[0], t[1], t[2]);
               }});
  // Attention-shaped products: [B, H, N, d] x [B, H, d, N], and broadcast batch dims.
  c.push_back({"matmul_4d", {{{2, 3, 4, 5}}, {{2, 3, 5, 4}}}, [](const In& t) {
                 return matmul(t[0], t[1]);
               }});
  c.push_back({"matmul_4d_transposed_b", {{{2, 2, 4, 3}}, {{2, 2, 4, 3}}}, [](const In& t) {
                 return matmul(t[0], transpose(t[1], -2, -1));
               }});
  c.push_back({"matmul_broadcast_batch", {{{2, 1, 3, 4}}, {{3, 4, 5}}}, [](const In& t) {
                 return matmul(t[0], t[1]);
               }});
  c.push_back(
      {"matmul_2d_by_3d", {{{3, 4}}, {{2, 4, 5}}}, [](const In& t) { return matmul(t[0], t[1]); }});
  // A whole attention head, as the ViT composes it.
  c.push_back({"attention", {{{2, 2, 5, 4}}, {{2, 2, 5, 4}}, {{2, 2, 5, 4}}}, [](const In& t) {
                 Tensor a = softmax(matmul(t[0], transpose(t[1], -2, -1)) * 0.5);
                 return matmul(a, t[2]);
               }});
  // ---- grid_sample ----
  for (bool ac : {false, true}) {
    for (GridPadding pad : {GridPadding::zeros, GridPadding::border}) {
      std::string n = std::string("grid_sample_") +
                      (pad == GridPadding::zeros ? "zeros" : "border") + (ac ? "_ac" : "_noac");
      GridSampleParams p{pad, ac};
      c.push_back({n, {{{2, 3, 5, 6}}, {{2, 4, 3, 2}, Init::grid}}, [p](const In& t) {
                     return grid_sample(t[0], t[1], p);
                   }});
    }
  }
  // ---- correlation (FlowNetC) and channel_norm ----
  // {pad, kernel_size, max_displacement, stride1, stride2}
  struct CorrCase {
    const char* name;
    CorrelationParams p;
    Shape x;
  };
  for (const CorrCase& cc : {
           // FlowNetC's (pad 20, k 1, d 20, s1 1, s2 2) scaled down by 5: 9 displacements.
           CorrCase{"correlation_flownetc_small", {4, 1, 4, 1, 2}, {2, 3, 5, 6}},
           CorrCase{"correlation_k3_s1_2", {2, 3, 1, 2, 1}, {1, 2, 6, 7}},
           CorrCase{"correlation_unpadded", {0, 1, 1, 1, 1}, {1, 3, 4, 5}},
           CorrCase{"correlation_pad_gt_border", {3, 1, 2, 2, 2}, {1, 2, 5, 4}},
       }) {
    c.push_back({cc.name, {{cc.x}, {cc.x}}, [p = cc.p](const In& t) {
                   return correlation(t[0], t[1], p);
                 }});
  }
  c.push_back({"correlation_same_input", {{{1, 4, 5, 5}}}, [](const In& t) {
                 return correlation(t[0], t[0], CorrelationParams{2, 1, 2, 1, 1});
               }});
  c.push_back({"channel_norm", {{{2, 3, 4, 5}, Init::away_from_zero}}, [](const In& t) {
                 return channel_norm(t[0]);
               }});
  return c;
}

}  // namespace cvd::test
