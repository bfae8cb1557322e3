// Row normalisations over the last dimension: layer norm and softmax (the transformer's ops).
// Each forward runs its kernel on x viewed as [rows, C] and records a backward that runs the
// matching backward kernel.
#include "engine/op_support.h"

namespace cvd {

using detail::check_same_kind;
using detail::contiguous_or_undefined;
using detail::empty_like_kind;

Tensor layer_norm(const Tensor& x_in, const Tensor& gamma_in, const Tensor& beta_in, double eps) {
  CVD_CHECK(x_in.dim() >= 1 && x_in.size(-1) > 0, "layer_norm: x {} needs a non-empty last dim",
            x_in.str());
  CVD_CHECK(eps >= 0, "layer_norm: eps must be >= 0, got {}", eps);
  const int64_t c = x_in.size(-1);
  for (const Tensor* t : {&gamma_in, &beta_in}) {
    if (!t->defined()) continue;
    check_same_kind("layer_norm", x_in, *t);
    CVD_CHECK(t->dim() == 1 && t->size(0) == c, "layer_norm: {} does not match the last dim {}",
              t->str(), c);
  }
  Tensor x = x_in.contiguous(), gamma = contiguous_or_undefined(gamma_in),
         beta = contiguous_or_undefined(beta_in);
  const int64_t rows = x.numel() / c;
  Tensor y = empty_like_kind(x.shape(), x);
  Tensor mean = empty_like_kind({rows}, x), invstd = empty_like_kind({rows}, x);
  LayerNormParams p{eps};
  dispatch(OpId::layer_norm, x, KernelArgs{{x, gamma, beta}, {y, mean, invstd}, &p});
  if (!any_requires_grad({x, gamma, beta})) return y;
  return record(
      "layer_norm", y, {x, gamma, beta},
      [xs = x.detach(), gs = gamma.defined() ? gamma.detach() : Tensor(), has_beta = beta.defined(),
       mean, invstd, p](const Tensor& g_in, const std::vector<bool>& need) {
        Tensor g = g_in.contiguous();
        const int64_t c = xs.size(-1);
        Tensor gx = need[0] ? empty_like_kind(xs.shape(), xs) : Tensor();
        Tensor gg = gs.defined() && need[1] ? empty_like_kind({c}, xs) : Tensor();
        Tensor gb = has_beta && need[2] ? empty_like_kind({c}, xs) : Tensor();
        dispatch(OpId::layer_norm_backward, g,
                 KernelArgs{{g, xs, gs, mean, invstd}, {gx, gg, gb}, &p});
        return std::vector<Tensor>{gx, gg, gb};
      });
}

Tensor softmax(const Tensor& x_in) {
  CVD_CHECK(x_in.dim() >= 1 && x_in.size(-1) > 0, "softmax: x {} needs a non-empty last dim",
            x_in.str());
  Tensor x = x_in.contiguous();
  Tensor y = empty_like_kind(x.shape(), x);
  dispatch(OpId::softmax, x, KernelArgs{{x}, {y}, nullptr});
  if (!any_requires_grad({x})) return y;
  return record("softmax", y, {x}, [ys = y.detach()](const Tensor& g_in, const std::vector<bool>&) {
    Tensor g = g_in.contiguous();
    Tensor gx = empty_like_kind(ys.shape(), ys);
    dispatch(OpId::softmax_backward, g, KernelArgs{{g, ys}, {gx}, nullptr});
    return std::vector<Tensor>{gx};
  });
}

}  // namespace cvd
