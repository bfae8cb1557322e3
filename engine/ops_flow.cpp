// Optical-flow ops of FlowNet2: correlation (FlowNetC) and ChannelNorm, each a forward kernel
// and a backward kernel of the dispatch table.
#include "engine/op_support.h"

namespace cvd {

using detail::check_same_kind;
using detail::empty_like_kind;

Tensor correlation(const Tensor& a_in, const Tensor& b_in, const CorrelationParams& p) {
  check_same_kind("correlation", a_in, b_in);
  CVD_CHECK(a_in.dim() == 4 && a_in.shape() == b_in.shape(),
            "correlation: a {} and b {} must be [N,C,H,W] of the same shape", a_in.str(),
            b_in.str());
  CVD_CHECK(p.kernel_size >= 1 && p.kernel_size % 2 == 1,
            "correlation: kernel_size {} must be odd and >= 1", p.kernel_size);
  CVD_CHECK(p.pad >= 0 && p.max_displacement >= 0 && p.stride1 >= 1 && p.stride2 >= 1,
            "correlation: pad {} and max_displacement {} must be >= 0, strides {} {} >= 1", p.pad,
            p.max_displacement, p.stride1, p.stride2);
  const int64_t oh = p.out_size(a_in.size(2)), ow = p.out_size(a_in.size(3));
  CVD_CHECK(oh > 0 && ow > 0,
            "correlation: input {} too small for pad {}, kernel {}, max displacement {}",
            a_in.str(), p.pad, p.kernel_size, p.max_displacement);
  Tensor a = a_in.contiguous(), b = b_in.contiguous();
  const int64_t d = p.displacement_size();
  Tensor y = empty_like_kind({a.size(0), d * d, oh, ow}, a);
  dispatch(OpId::correlation, a, KernelArgs{{a, b}, {y}, &p});
  if (!any_requires_grad({a, b})) return y;
  return record(
      "correlation", y, {a, b},
      [as = a.detach(), bs = b.detach(), p](const Tensor& g_in, const std::vector<bool>& need) {
        Tensor g = g_in.contiguous();
        Tensor ga = need[0] ? empty_like_kind(as.shape(), as) : Tensor();
        Tensor gb = need[1] ? empty_like_kind(bs.shape(), bs) : Tensor();
        dispatch(OpId::correlation_backward, g, KernelArgs{{g, as, bs}, {ga, gb}, &p});
        return std::vector<Tensor>{ga, gb};
      });
}

Tensor channel_norm(const Tensor& x_in) {
  CVD_CHECK(x_in.dim() == 4, "channel_norm: x {} must be [N,C,H,W]", x_in.str());
  Tensor x = x_in.contiguous();
  Tensor y = empty_like_kind({x.size(0), 1, x.size(2), x.size(3)}, x);
  dispatch(OpId::channel_norm, x, KernelArgs{{x}, {y}, nullptr});
  if (!any_requires_grad({x})) return y;
  return record("channel_norm", y, {x},
                [xs = x.detach(), ys = y.detach()](const Tensor& g_in, const std::vector<bool>&) {
                  Tensor g = g_in.contiguous();
                  Tensor gx = empty_like_kind(xs.shape(), xs);
                  dispatch(OpId::channel_norm_backward, g, KernelArgs{{g, xs, ys}, {gx}, nullptr});
                  return std::vector<Tensor>{gx};
                });
}

}  // namespace cvd
