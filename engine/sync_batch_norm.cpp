#include "engine/sync_batch_norm.h"

#include "engine/autograd.h"
#include "engine/error.h"
#include "engine/ops.h"
#include "engine/process_group.h"

namespace cvd {

Tensor sync_batch_norm(const Tensor& x, const Tensor& running_mean, const Tensor& running_var,
                       const Tensor& gamma, const Tensor& beta, const BatchNormParams& p) {
  CVD_CHECK(x.dim() == 4, "sync_batch_norm: x {} must be 4-d NCHW", x.str());
  const int64_t c = x.size(1);
  double count = static_cast<double>(x.numel() / c);
  process_group().all_reduce_sum(&count, 1);
  CVD_CHECK(count > 1,
            "sync_batch_norm: training needs more than one value per channel, got {} "
            "over all processes",
            count);
  const Shape bc{1, c, 1, 1};
  Tensor mean = mul_scalar(all_reduce_sum(sum(x, {0, 2, 3})), 1.0 / count);
  Tensor centred = sub(x, mean.reshape(bc));
  Tensor var = mul_scalar(all_reduce_sum(sum(square(centred), {0, 2, 3})), 1.0 / count);
  Tensor y = mul(centred, pow(add_scalar(var, p.eps), -0.5).reshape(bc));
  if (gamma.defined()) y = mul(y, gamma.reshape(bc));
  if (beta.defined()) y = add(y, beta.reshape(bc));
  if (p.momentum > 0 && running_mean.defined() && running_var.defined()) {
    NoGradGuard ng;
    const double m = p.momentum;
    running_mean.copy_(add(mul_scalar(running_mean, 1.0 - m), mul_scalar(mean.detach(), m)));
    running_var.copy_(
        add(mul_scalar(running_var, 1.0 - m), mul_scalar(var.detach(), m * count / (count - 1.0))));
    running_mean.bump_version();
    running_var.bump_version();
  }
  return y;
}

}  // namespace cvd
