#include "engine/sync_batch_norm.h"

#include "engine/autograd.h"
#include "engine/error.h"
#include "engine/ops.h"
#include "engine/process_group.h"

namespace cvd {

// Forward: the statistics over all processes (one all-reduce for the sums, one for the centred
// squares), then the fused batch-norm kernel in inference form with those statistics. Backward
// (recorded as one node): with x̂ = (x - mean) * invstd,
//   dgamma = Σ gy x̂, dbeta = Σ gy             (this process's share; training sums them)
//   dx = gamma * invstd * (gy - mean_all(gy) - x̂ * mean_all(gy x̂))
// where mean_all is over every process's values (one all-reduce of both sums).
Tensor sync_batch_norm(const Tensor& x, const Tensor& running_mean, const Tensor& running_var,
                       const Tensor& gamma, const Tensor& beta, const BatchNormParams& p) {
  CVD_CHECK(x.dim() == 4, "sync_batch_norm: x {} must be 4-d NCHW", x.str());
  CVD_CHECK(!p.fused_act, "sync_batch_norm: no fused activation (apply it to the output)");
  const int64_t c = x.size(1);
  double count = static_cast<double>(x.numel() / c);
  process_group().all_reduce_sum(&count, 1);
  CVD_CHECK(count > 1,
            "sync_batch_norm: training needs more than one value per channel, got {} over all "
            "processes",
            count);
  const Shape bc{1, c, 1, 1};
  Tensor mean, var, y;
  {
    NoGradGuard ng;
    const Tensor xd = x.detach();
    mean = mul_scalar(all_reduce_sum(sum(xd, {0, 2, 3})), 1.0 / count).contiguous();
    var = mul_scalar(all_reduce_sum(sum(square(sub(xd, mean.reshape(bc))), {0, 2, 3})), 1.0 / count)
              .contiguous();
    BatchNormParams normalise = p;
    normalise.training = false;
    normalise.momentum = 0.0;
    y = batch_norm(xd, mean, var, gamma.defined() ? gamma.detach() : Tensor(),
                   beta.defined() ? beta.detach() : Tensor(), normalise);
    if (p.momentum > 0 && running_mean.defined() && running_var.defined()) {
      const double m = p.momentum;
      running_mean.copy_(add(mul_scalar(running_mean, 1.0 - m), mul_scalar(mean, m)));
      running_var.copy_(
          add(mul_scalar(running_var, 1.0 - m), mul_scalar(var, m * count / (count - 1.0))));
      running_mean.bump_version();
      running_var.bump_version();
    }
  }
  if (!any_requires_grad({x, gamma, beta})) return y;
  return record("sync_batch_norm", y, {x, gamma, beta},
                [xs = x.detach(), mean, var, g = gamma.defined() ? gamma.detach() : Tensor(),
                 eps = p.eps, count, c, bc](const Tensor& gy_in, const std::vector<bool>& needs) {
                  const Tensor gy = gy_in.contiguous();
                  const Tensor invstd = pow(add_scalar(var, eps), -0.5);
                  const Tensor xhat = mul(sub(xs, mean.reshape(bc)), invstd.reshape(bc));
                  const Tensor sum_gy = sum(gy, {0, 2, 3});
                  const Tensor sum_gy_xhat = sum(mul(gy, xhat), {0, 2, 3});
                  std::vector<Tensor> grads(3);
                  if (needs[0]) {
                    const Tensor all = all_reduce_sum(concat({sum_gy, sum_gy_xhat}, 0));
                    const Tensor mean_gy = mul_scalar(all.narrow(0, 0, c), 1.0 / count);
                    const Tensor mean_gy_xhat = mul_scalar(all.narrow(0, c, c), 1.0 / count);
                    const Tensor scale = g.defined() ? mul(g, invstd) : invstd;
                    grads[0] =
                        mul(sub(sub(gy, mean_gy.reshape(bc)), mul(xhat, mean_gy_xhat.reshape(bc))),
                            scale.reshape(bc));
                  }
                  if (needs.size() > 1 && needs[1]) grads[1] = sum_gy_xhat;
                  if (needs.size() > 2 && needs[2]) grads[2] = sum_gy;
                  return grads;
                });
}

}  // namespace cvd
