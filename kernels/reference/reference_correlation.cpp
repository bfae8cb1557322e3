// Reference kernels of FlowNet's correlation and ChannelNorm (semantics in
// engine/kernel_params.h, CorrelationParams), forward and backward, as plain float64 loops over
// the definition: every backward scatters through exactly the products of its forward.
#include <cmath>

#include "engine/kernel_params.h"
#include "kernels/reference/reference_access.h"
#include "kernels/reference/reference_kernels.h"

namespace cvd::reference {

namespace {

// Calls fn(ia, ib, io) for every product a[ia] * b[ib] that contributes to y[io] (flat offsets
// into contiguous a, b [N, C, H, W] and y [N, D*D, Ho, Wo]), skipping reads outside the image.
template <class F>
void for_each_correlation_term(const Shape& in, const Shape& out, const CorrelationParams& p,
                               F&& fn) {
  const int64_t n_img = in[0], ch = in[1], h = in[2], w = in[3];
  const int64_t oh = out[2], ow = out[3];
  const int r = p.displacement_radius(), d = p.displacement_size(), kr = p.kernel_radius();
  for (int64_t n = 0; n < n_img; ++n)
    for (int tj = -r; tj <= r; ++tj)
      for (int ti = -r; ti <= r; ++ti) {
        const int64_t oc = (tj + r) * d + (ti + r);
        for (int64_t oy = 0; oy < oh; ++oy)
          for (int64_t ox = 0; ox < ow; ++ox) {
            const int64_t io = ((n * out[1] + oc) * oh + oy) * ow + ox;
            const int64_t cy = oy * p.stride1 + p.border() - p.pad;
            const int64_t cx = ox * p.stride1 + p.border() - p.pad;
            for (int dj = -kr; dj <= kr; ++dj)
              for (int di = -kr; di <= kr; ++di) {
                const int64_t ya = cy + dj, xa = cx + di;
                const int64_t yb = ya + int64_t{tj} * p.stride2, xb = xa + int64_t{ti} * p.stride2;
                if (ya < 0 || ya >= h || xa < 0 || xa >= w) continue;
                if (yb < 0 || yb >= h || xb < 0 || xb >= w) continue;
                for (int64_t c = 0; c < ch; ++c) {
                  const int64_t plane = (n * ch + c) * h;
                  fn((plane + ya) * w + xa, (plane + yb) * w + xb, io);
                }
              }
          }
      }
}

double correlation_scale(const Shape& in, const CorrelationParams& p) {
  return 1.0 / (static_cast<double>(p.kernel_size) * p.kernel_size * static_cast<double>(in[1]));
}

void check_correlation_shapes(const Tensor& a, const Tensor& b, const Tensor& y,
                              const CorrelationParams& p) {
  CVD_ASSERT(is_f64_contiguous(a) && is_f64_contiguous(b) && is_f64_contiguous(y));
  CVD_ASSERT(a.dim() == 4 && a.shape() == b.shape() && y.dim() == 4);
  CVD_ASSERT(y.shape()[0] == a.shape()[0] &&
             y.shape()[1] == int64_t{p.displacement_size()} * p.displacement_size());
  CVD_ASSERT(y.shape()[2] == p.out_size(a.shape()[2]) && y.shape()[3] == p.out_size(a.shape()[3]));
}

}  // namespace

void correlation(const KernelArgs& args) {
  const Tensor &a = args.in[0], &b = args.in[1], &y = args.out[0];
  const auto& p = args.p<CorrelationParams>();
  check_correlation_shapes(a, b, y, p);
  const double* ap = a.data<double>();
  const double* bp = b.data<double>();
  double* yp = y.data<double>();
  for (int64_t i = 0; i < y.numel(); ++i) yp[i] = 0.0;
  for_each_correlation_term(a.shape(), y.shape(), p,
                            [&](int64_t ia, int64_t ib, int64_t io) { yp[io] += ap[ia] * bp[ib]; });
  const double s = correlation_scale(a.shape(), p);
  for (int64_t i = 0; i < y.numel(); ++i) yp[i] *= s;
}

// in: gy, a, b; out: ga, gb (either may be undefined when not needed).
void correlation_backward(const KernelArgs& args) {
  const Tensor &gy = args.in[0], &a = args.in[1], &b = args.in[2];
  const Tensor &ga = args.out[0], &gb = args.out[1];
  const auto& p = args.p<CorrelationParams>();
  check_correlation_shapes(a, b, gy, p);
  const double s = correlation_scale(a.shape(), p);
  const double* ap = a.data<double>();
  const double* bp = b.data<double>();
  const double* gp = gy.data<double>();
  double* gap = ga.defined() ? ga.data<double>() : nullptr;
  double* gbp = gb.defined() ? gb.data<double>() : nullptr;
  for (const Tensor* t : {&ga, &gb}) {
    if (!t->defined()) continue;
    CVD_ASSERT(is_f64_contiguous(*t) && t->shape() == a.shape());
    double* tp = t->data<double>();
    for (int64_t i = 0; i < t->numel(); ++i) tp[i] = 0.0;
  }
  for_each_correlation_term(a.shape(), gy.shape(), p, [&](int64_t ia, int64_t ib, int64_t io) {
    const double g = gp[io] * s;
    if (gap) gap[ia] += g * bp[ib];
    if (gbp) gbp[ib] += g * ap[ia];
  });
}

// y[n, 0, h, w] = sqrt(sum_c x[n, c, h, w]^2).
void channel_norm(const KernelArgs& args) {
  const Tensor &x = args.in[0], &y = args.out[0];
  CVD_ASSERT(is_f64_contiguous(x) && is_f64_contiguous(y) && x.dim() == 4 && y.dim() == 4);
  const int64_t n_img = x.shape()[0], ch = x.shape()[1], hw = x.shape()[2] * x.shape()[3];
  CVD_ASSERT(y.shape()[0] == n_img && y.shape()[1] == 1 && y.shape()[2] * y.shape()[3] == hw);
  const double* xp = x.data<double>();
  double* yp = y.data<double>();
  for (int64_t n = 0; n < n_img; ++n)
    for (int64_t i = 0; i < hw; ++i) {
      double s = 0.0;
      for (int64_t c = 0; c < ch; ++c) {
        const double v = xp[(n * ch + c) * hw + i];
        s += v * v;
      }
      yp[n * hw + i] = std::sqrt(s);
    }
}

// in: gy, x, y; out: gx = gy * x / y, defined as 0 where y == 0 (the minimum-norm subgradient).
void channel_norm_backward(const KernelArgs& args) {
  const Tensor &gy = args.in[0], &x = args.in[1], &y = args.in[2], &gx = args.out[0];
  CVD_ASSERT(is_f64_contiguous(gy) && is_f64_contiguous(x) && is_f64_contiguous(y));
  CVD_ASSERT(is_f64_contiguous(gx) && gx.shape() == x.shape() && gy.shape() == y.shape());
  const int64_t n_img = x.shape()[0], ch = x.shape()[1], hw = x.shape()[2] * x.shape()[3];
  const double* gyp = gy.data<double>();
  const double* xp = x.data<double>();
  const double* yp = y.data<double>();
  double* gxp = gx.data<double>();
  for (int64_t n = 0; n < n_img; ++n)
    for (int64_t i = 0; i < hw; ++i) {
      const double norm = yp[n * hw + i];
      const double f = norm > 0.0 ? gyp[n * hw + i] / norm : 0.0;
      for (int64_t c = 0; c < ch; ++c) gxp[(n * ch + c) * hw + i] = f * xp[(n * ch + c) * hw + i];
    }
}

}  // namespace cvd::reference
