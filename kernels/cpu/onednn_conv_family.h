// The three passes (forward, backward data, backward weights) of a oneDNN convolution or
// deconvolution on NCHW caller tensors, built once per shape and cached. Convolution
// (onednn_conv.cpp) and transposed convolution (onednn_deconv.cpp) share this code: oneDNN gives
// both families the same descriptor signatures.
#pragma once
#include <oneapi/dnnl/dnnl.hpp>

#include <memory>
#include <vector>

#include "engine/tensor.h"
#include "kernels/cpu/onednn_chunked_primitive.h"
#include "kernels/cpu/onednn_context.h"

namespace cvd::onednn {

// One convolution-like problem in oneDNN terms. "src" is the input side of the forward pass and
// "dst" its output side; weights are in oneDNN's logical order ({O, I, KH, KW}, or
// {G, O/G, I/G, KH, KW} with groups) and stored in the caller's layout `weights_tag`.
struct ConvProblem {
  dnnl::memory::dims src, dst, weights;
  dnnl::memory::format_tag weights_tag = dnnl::memory::format_tag::oihw;
  dnnl::memory::dims strides, dilates, pad_l, pad_r;  // dilates in oneDNN's convention (d - 1)
  bool bias = false;
  int64_t groups = 1;
  // Inputs of each pass rounded to bf16 (engine/compute_precision.h); results stay f32.
  bool bf16 = false;
};

enum class ConvPass : int { forward, backward_data, backward_weights };

// How the primitive sees activations: oneDNN's preferred layout (format_tag::any, usually blocked
// nChw16c, reordered to and from NCHW) or the caller's NCHW as is (no reorders; oneDNN then
// usually runs an im2col + GEMM implementation).
enum class ActivationLayout : int { preferred, nchw };

struct ConvPlanChoice {
  ActivationLayout layout = ActivationLayout::preferred;
  int64_t chunks = 1;  // the batch is run in this many equal chunks
};

// Per-pass choice of layout and batch chunking (onednn_conv_choice.cpp).
ConvPlanChoice choose_conv_plan(const ConvProblem& p, ConvPass pass);

// Sets p.bf16 from the compute precision (engine/compute_precision.h): bf16 when asked for and
// both sides have at least 16 channels per group. Narrower convolutions stay f32: they cost
// little, and oneDNN 2.6's AMX backward kernels corrupt memory on them (seen with 64 -> 1).
void choose_conv_precision(ConvProblem& p);

// Whether a depthwise convolution (groups == in == out channels) runs the hand-written NCHW
// kernel of cpu/depthwise_conv2d.h instead of a oneDNN primitive.
bool use_depthwise_kernel(const ConvProblem& p, ConvPass pass);

// Whether a pointwise convolution (1x1 kernel, stride 1, no padding, one group) runs as oneDNN
// matmul primitives straight on the NCHW tensors (onednn_pointwise_conv.cpp): per image it is
// the matrix product W [O, C] x X [C, H*W], no reorders needed.
bool use_pointwise_matmul(const ConvProblem& p);

// The pointwise passes; shapes as the conv2d kernels' (x [N, C, H, W], w [O, C, 1, 1]).
void pointwise_conv_forward(const Tensor& x, const Tensor& w, const Tensor& b, const Tensor& y);
void pointwise_conv_backward_data(const Tensor& gy, const Tensor& w, const Tensor& gx);
void pointwise_conv_backward_weight(const Tensor& gy, const Tensor& x, const Tensor& gw,
                                    const Tensor& gb);

// Whether a pointwise forward or backward-data pass on images of `pixels` pixels, summing over
// `inner` channels (the input's for forward, the output's for backward data), runs as oneDNN's
// sgemm (one call per image) instead of the matmul primitive. On large images sgemm was faster
// for both passes: 1.1-2.1x on warm buffers in a standalone check, 4-8% in bench_conv's
// 1x1_128-64_224x384 (Intel Xeon, 2 threads); slower only for a sum over one channel (0.8x). The
// matmul primitive is faster for backward weights, which keeps it, and on small images (MiDaS
// small's 16x20) neither wins steadily. CVD_POINTWISE_GEMM=0 / 1 turns it off / on everywhere.
bool use_pointwise_gemm(int64_t pixels, int64_t inner);

// Whether such a pass runs on our AVX-512 kernel (cpu/pointwise_gemm.h) instead: where the CPU
// has AVX-512F, on images of at least 128x128 pixels, summing over 64 to 128 channels, or over
// 16 to 63 into at least 64 output `rows` (channels of the result: the output's for forward, the
// input's for backward data). Outside that range sgemm was as fast or faster, or the gain was not
// resolvable (figures in the README's conv table). CVD_POINTWISE_KERNEL=0 / 1 turns it off / on
// everywhere (on only where the CPU has AVX-512F).
bool use_pointwise_kernel(int64_t pixels, int64_t inner, int64_t rows);

// Backward data of a unit-stride, undilated, ungrouped convolution whose output has fewer than 16
// channels, computed as the forward convolution of the output gradient with the weights flipped
// and transposed ([C, O, KH, KW], pads KH-1-pad per side). oneDNN 2.6 runs such narrow backward
// data passes far below its forward speed (8 -> 2 channels, 11x11, 192x256, Intel Xeon: 11.6
// GFLOP/s against 118 for the equivalent forward 2 -> 8; bench/bench_conv.cpp); the default
// network's full-resolution layers are this narrow.
bool use_backward_data_as_forward(const ConvProblem& p);

// Whether a forward or backward-weights pass (for backward data: the forward problem it is
// computed as) runs on the hand-written kernel for few output channels (cpu/narrow_conv2d.h):
// where the CPU has AVX-512F, f32, one group, unit stride, no dilation, at most 8 output and 16
// input channels, a filter larger than 1x1 and no negative padding. oneDNN 2.6 vectorises over output
// channels and ran the default network's 8 -> 2 11x11 layer at 27-31 GFLOP/s (figures in the
// README's conv table). CVD_NARROW_CONV_KERNEL=0 / 1 turns it off / on (1: on every such problem,
// which is also the default).
bool use_narrow_conv_kernel(const ConvProblem& p);

// Tuning overrides for tests and benchmarks: a forced layout (-1: automatic), the byte budget of
// the reordered activations of one chunk (0: automatic), and the depthwise kernel choice
// (-1: automatic, 0: never, 1: always), the pointwise matmul choice and the backward-data-as-
// forward choice (same values; 1 applies it to every eligible problem, narrow or not).
void set_conv_layout_override(int layout);
void set_conv_chunk_budget_override(size_t bytes);
void set_depthwise_kernel_override(int mode);
void set_pointwise_matmul_override(int mode);
void set_backward_data_as_forward_override(int mode);
void set_pointwise_gemm_override(int mode);
void set_pointwise_kernel_override(int mode);
void set_narrow_conv_kernel_override(int mode);

// Sets every byte of t to zero (nothing when t is undefined or empty): the gradients of an empty
// batch.
void zero_fill(const Tensor& t);

// Sum of gy [N, C, H, W] over N, H and W into gb [C] (f64 accumulation). bf16 backward-weights
// passes compute the bias gradient with this instead of the primitive: oneDNN 2.6's AMX kernel
// writes the bias gradient padded to 16 channels, past the end of a smaller tensor.
void bias_gradient_nchw(const Tensor& gy, const Tensor& gb);

// Widest image (input or output, pixels) on which the backward-weights pass runs in bf16. oneDNN
// 2.6's AMX backward-weights kernel corrupts the heap on wide rows: Mannequin's full-resolution
// layers crashed at widths 336 to 384 and ran clean at 320 and below (bench_models --precision
// bf16, 2026-12-01); its AVX512-BF16 fallback is slower than f32 there. Wider problems run that
// pass in f32 (forward and backward data stay bf16).
constexpr int64_t kBf16BackwardWeightsMaxWidth = 256;

// Whether the backward-weights pass of `p` may run in bf16 (p.bf16 and no row wider than the
// limit above).
bool bf16_backward_weights(const ConvProblem& p);

// The backward-weights pass of `pr` on {x, gy} into gw and, when defined, gb.
template <class Family>
void run_conv_backward_weights(ConvProblem pr, const Tensor& x, const Tensor& gy, const Tensor& gw,
                               const Tensor& gb);

struct ConvolutionFamily {
  using forward = dnnl::convolution_forward;
  using backward_data = dnnl::convolution_backward_data;
  using backward_weights = dnnl::convolution_backward_weights;
  static constexpr dnnl::algorithm algorithm = dnnl::algorithm::convolution_direct;
  static constexpr int64_t id = 1;
};

struct DeconvolutionFamily {
  using forward = dnnl::deconvolution_forward;
  using backward_data = dnnl::deconvolution_backward_data;
  using backward_weights = dnnl::deconvolution_backward_weights;
  static constexpr dnnl::algorithm algorithm = dnnl::algorithm::deconvolution_direct;
  static constexpr int64_t id = 2;
};

namespace detail {

inline dnnl::memory::dims with_batch(dnnl::memory::dims d, int64_t n) {
  d[0] = n;
  return d;
}

inline dnnl::memory::desc f32_desc(const dnnl::memory::dims& d, dnnl::memory::format_tag t) {
  return dnnl::memory::desc(d, dnnl::memory::data_type::f32, t);
}

// The type a pass reads its inputs in: bf16 in bf16 mode, else f32.
inline dnnl::memory::desc input_desc(const ConvProblem& p, const dnnl::memory::dims& d,
                                     dnnl::memory::format_tag t) {
  return dnnl::memory::desc(
      d, p.bf16 ? dnnl::memory::data_type::bf16 : dnnl::memory::data_type::f32, t);
}

// The forward primitive descriptor (also the hint of the backward passes).
template <class Family>
typename Family::forward::primitive_desc forward_pd(const ConvProblem& p,
                                                    const dnnl::memory::desc& src,
                                                    const dnnl::memory::desc& weights,
                                                    const dnnl::memory::desc& dst) {
  using tag = dnnl::memory::format_tag;
  const dnnl::memory::desc bias = p.bias ? f32_desc({p.dst[1]}, tag::x) : dnnl::memory::desc();
  typename Family::forward::desc d(dnnl::prop_kind::forward_training, Family::algorithm, src,
                                   weights, bias, dst, p.strides, p.dilates, p.pad_l, p.pad_r);
  return typename Family::forward::primitive_desc(d, cpu_engine());
}

template <class Family>
std::unique_ptr<ChunkedPrimitive> build_pass(const ConvProblem& p, ConvPass pass,
                                             const ConvPlanChoice& choice) {
  using tag = dnnl::memory::format_tag;
  const int64_t nb = p.src[0] / choice.chunks;
  const dnnl::memory::dims src_dims = with_batch(p.src, nb), dst_dims = with_batch(p.dst, nb);
  // bf16 kernels (AMX / AVX512-BF16) need oneDNN's blocked layouts.
  const tag act = choice.layout == ActivationLayout::nchw && !p.bf16 ? tag::nchw : tag::any;
  // What each pass reads (bf16 in bf16 mode) and writes (always f32).
  const dnnl::memory::desc src_in = input_desc(p, src_dims, act), src_out = f32_desc(src_dims, act);
  const dnnl::memory::desc dst_in = input_desc(p, dst_dims, act), dst_out = f32_desc(dst_dims, act);
  const dnnl::memory::desc weights_in = input_desc(p, p.weights, tag::any);
  const dnnl::memory::desc weights_out = f32_desc(p.weights, tag::any);
  const dnnl::memory::desc src_user = f32_desc(src_dims, tag::nchw);
  const dnnl::memory::desc dst_user = f32_desc(dst_dims, tag::nchw);
  const dnnl::memory::desc weights_user = f32_desc(p.weights, p.weights_tag);
  const dnnl::memory::desc bias_user = f32_desc({p.dst[1]}, tag::x);

  auto fwd = forward_pd<Family>(p, src_in, weights_in, dst_out);
  std::vector<ArgSpec> args;
  switch (pass) {
    case ConvPass::forward: {
      args.push_back({DNNL_ARG_SRC, ArgKind::batch_input, src_user, fwd.src_desc()});
      args.push_back({DNNL_ARG_WEIGHTS, ArgKind::weight_input, weights_user, fwd.weights_desc()});
      if (p.bias) args.push_back({DNNL_ARG_BIAS, ArgKind::plain_input, bias_user, bias_user});
      args.push_back({DNNL_ARG_DST, ArgKind::batch_output, dst_user, fwd.dst_desc()});
      return std::make_unique<ChunkedPrimitive>(typename Family::forward(fwd), std::move(args),
                                                choice.chunks);
    }
    case ConvPass::backward_data: {
      typename Family::backward_data::desc d(Family::algorithm, src_out, weights_in, dst_in,
                                             p.strides, p.dilates, p.pad_l, p.pad_r);
      typename Family::backward_data::primitive_desc pd(d, cpu_engine(), fwd);
      args.push_back({DNNL_ARG_DIFF_DST, ArgKind::batch_input, dst_user, pd.diff_dst_desc()});
      args.push_back({DNNL_ARG_WEIGHTS, ArgKind::weight_input, weights_user, pd.weights_desc()});
      args.push_back({DNNL_ARG_DIFF_SRC, ArgKind::batch_output, src_user, pd.diff_src_desc()});
      return std::make_unique<ChunkedPrimitive>(typename Family::backward_data(pd), std::move(args),
                                                choice.chunks);
    }
    case ConvPass::backward_weights: {
      const dnnl::memory::desc bias_req =
          p.bias ? f32_desc({p.dst[1]}, tag::x) : dnnl::memory::desc();
      typename Family::backward_weights::desc d(Family::algorithm, src_in, weights_out, bias_req,
                                                dst_in, p.strides, p.dilates, p.pad_l, p.pad_r);
      typename Family::backward_weights::primitive_desc pd(d, cpu_engine(), fwd);
      args.push_back({DNNL_ARG_SRC, ArgKind::batch_input, src_user, pd.src_desc()});
      args.push_back({DNNL_ARG_DIFF_DST, ArgKind::batch_input, dst_user, pd.diff_dst_desc()});
      args.push_back(
          {DNNL_ARG_DIFF_WEIGHTS, ArgKind::sum_output, weights_user, pd.diff_weights_desc()});
      if (p.bias) {
        args.push_back({DNNL_ARG_DIFF_BIAS, ArgKind::sum_output, bias_user, pd.diff_bias_desc()});
      }
      return std::make_unique<ChunkedPrimitive>(typename Family::backward_weights(pd),
                                                std::move(args), choice.chunks);
    }
  }
  return nullptr;
}

}  // namespace detail

// The cached plan of one pass of `p`.
template <class Family>
ChunkedPrimitive& conv_pass_plan(const ConvProblem& p, ConvPass pass) {
  static PrimitiveCache<ChunkedPrimitive> cache;
  const ConvPlanChoice choice = choose_conv_plan(p, pass);
  CacheKey key;
  key.add(Family::id).add(static_cast<int64_t>(pass)).add(onednn_threads());
  key.add(p.src).add(p.dst).add(p.weights).add(static_cast<int64_t>(p.weights_tag));
  key.add(p.strides).add(p.dilates).add(p.pad_l).add(p.pad_r).add(p.bias ? 1 : 0);
  key.add(static_cast<int64_t>(choice.layout)).add(choice.chunks).add(p.bf16 ? 1 : 0);
  return cache.get(key, [&] { return detail::build_pass<Family>(p, pass, choice); });
}

template <class Family>
void run_conv_backward_weights(ConvProblem pr, const Tensor& x, const Tensor& gy, const Tensor& gw,
                               const Tensor& gb) {
  pr.bf16 = bf16_backward_weights(pr);
  const bool own_bias = pr.bf16 && gb.defined();
  if (own_bias) pr.bias = false;
  ChunkedPrimitive& plan = conv_pass_plan<Family>(pr, ConvPass::backward_weights);
  if (pr.bias) {
    plan.execute({x, gy, gw, gb});
  } else {
    plan.execute({x, gy, gw});
  }
  if (own_bias) bias_gradient_nchw(gy, gb);
}

}  // namespace cvd::onednn
