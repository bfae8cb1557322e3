// The OpenMP f32 CPU resampling kernels (kernels/cpu, impl "openmp": bilinear and nearest resize,
// grid_sample, forward and backward) against the float64 reference kernels (kernels/reference),
// both called through the dispatch registry on the same inputs (tests/cpu_kernel_comparison.h),
// plus PyTorch facts the reference comparison cannot show.
//
// Tolerances (max |fast - ref| <= tol * max |ref| over each output):
//   exact (0): nearest forward;  1e-6: nearest backward;
//   1e-5: bilinear forward / backward, grid_sample forward / backward (x and grid gradients).
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "engine/kernel_params.h"
#include "tests/cpu_kernel_comparison.h"

namespace cvd {
namespace {

using namespace cvd::test;  // NOLINT: the comparison helpers

// ---- resize ------------------------------------------------------------------------------------

struct ResizeCase {
  Shape in;  // N, C, H, W
  int64_t oh, ow;
};

const std::vector<ResizeCase> kResizeCases = {
    {{2, 3, 1, 1}, 1, 1},       {{2, 3, 1, 1}, 5, 4},      {{2, 3, 5, 4}, 1, 1},
    {{2, 3, 4, 6}, 8, 12},      {{2, 3, 8, 12}, 4, 6},     {{1, 2, 7, 9}, 13, 23},
    {{1, 2, 13, 23}, 7, 9},     {{2, 1, 3, 5}, 10, 6},     {{1, 1, 6, 10}, 10, 6},
    {{2, 8, 48, 64}, 96, 128},  {{2, 8, 96, 128}, 37, 51}, {{1, 1, 64, 80}, 150, 170},
    {{1, 3, 150, 170}, 64, 80},
};

TEST(CpuResampleKernels, UpsampleBilinearBothAlignModes) {
  Generator gen(8);
  for (const ResizeCase& c : kResizeCases) {
    const Shape out = {c.in[0], c.in[1], c.oh, c.ow};
    for (bool ac : {false, true}) {
      const std::string what =
          shape_text(c.in) + " -> " + shape_text(out) + (ac ? " align_corners" : " half-pixel");
      const UpsampleParams p{ac};
      expect_close(run_both(OpId::upsample_bilinear2d, {normal(c.in, gen)}, {out}, &p), 1e-5,
                   "bilinear " + what);
      expect_close(run_both(OpId::upsample_bilinear2d_backward, {normal(out, gen)}, {c.in}, &p),
                   1e-5, "bilinear backward " + what);
    }
  }
}

TEST(CpuResampleKernels, UpsampleBicubic) {
  Generator gen(18);
  for (const ResizeCase& c : kResizeCases) {
    const Shape out = {c.in[0], c.in[1], c.oh, c.ow};
    for (bool ac : {false, true}) {
      const std::string what =
          shape_text(c.in) + " -> " + shape_text(out) + (ac ? " align_corners" : " half-pixel");
      const UpsampleParams p{ac};
      expect_close(run_both(OpId::upsample_bicubic2d, {normal(c.in, gen)}, {out}, &p), 1e-5,
                   "bicubic " + what);
      expect_close(run_both(OpId::upsample_bicubic2d_backward, {normal(out, gen)}, {c.in}, &p),
                   1e-5, "bicubic backward " + what);
    }
  }
  // DINOv2 / Depth Anything: a 37 x 37 position-embedding grid to 28 x 37 patches with the scale
  // factors (n + 0.1) / 37 given.
  const UpsampleParams p{false, 28.1 / 37, 37.1 / 37};
  const Shape in{1, 16, 37, 37}, out{1, 16, 28, 37};
  expect_close(run_both(OpId::upsample_bicubic2d, {normal(in, gen)}, {out}, &p), 1e-5,
               "bicubic with scale factors");
  expect_close(run_both(OpId::upsample_bicubic2d_backward, {normal(out, gen)}, {in}, &p), 1e-5,
               "bicubic backward with scale factors");
}

TEST(CpuResampleKernels, UpsampleNearest) {
  Generator gen(9);
  for (const ResizeCase& c : kResizeCases) {
    const Shape out = {c.in[0], c.in[1], c.oh, c.ow};
    const std::string what = shape_text(c.in) + " -> " + shape_text(out);
    expect_close(run_both(OpId::upsample_nearest2d, {normal(c.in, gen)}, {out}, nullptr), 0.0,
                 "nearest " + what);
    expect_close(run_both(OpId::upsample_nearest2d_backward, {normal(out, gen)}, {c.in}, nullptr),
                 1e-6, "nearest backward " + what);
  }
}

// PyTorch computes the nearest source index as floor(o * float(in / out)): for in 2, out 82 the
// output column 41 reads column 0 (exact arithmetic would give 1). Verified against PyTorch 1.13
// F.interpolate(mode="nearest").
TEST(CpuResampleKernels, NearestMatchesPyTorchFloatScale) {
  const KernelInfo* k =
      kernel_registry().find(OpId::upsample_nearest2d, DeviceType::cpu, DType::f32);
  ASSERT_NE(k, nullptr);
  Tensor x = Tensor::from_vector(std::vector<double>{10.0, 20.0}, {1, 1, 1, 2}, DType::f32);
  Tensor y = Tensor::empty({1, 1, 1, 82}, DType::f32);
  k->fn(KernelArgs{{x}, {y}, nullptr});
  const float* yp = y.data<float>();
  EXPECT_EQ(yp[40], 10.0f);
  EXPECT_EQ(yp[41], 10.0f);
  EXPECT_EQ(yp[42], 20.0f);
  EXPECT_EQ(yp[81], 20.0f);
}

// ---- grid_sample -------------------------------------------------------------------------------

// Grid values whose pixel coordinates stay >= 0.02 px away from integers (so f32 and f64 pick the
// same bilinear cell) and extend `margin` pixels beyond the image on each side.
Pair sample_grid(int64_t n, int64_t oh, int64_t ow, int64_t h, int64_t w, bool align_corners,
                 double margin, Generator& gen) {
  std::vector<double> v(static_cast<size_t>(n * oh * ow * 2));
  for (size_t i = 0; i < v.size(); ++i) {
    const int64_t size = i % 2 == 0 ? w : h;
    if (align_corners && size == 1) {  // every coordinate maps to pixel 0
      v[i] = 2.0 * gen.uniform() - 1.0;
      continue;
    }
    const double lo = -0.5 - margin, hi = static_cast<double>(size) - 0.5 + margin;
    const double cell = std::floor(lo + (hi - lo) * gen.uniform());
    const double px = cell + 0.02 + 0.96 * gen.uniform();
    v[i] = align_corners ? px / static_cast<double>(size - 1) * 2.0 - 1.0
                         : (2.0 * px + 1.0) / static_cast<double>(size) - 1.0;
  }
  return pair_of(v, {n, oh, ow, 2});
}

TEST(CpuResampleKernels, GridSampleForwardBackward) {
  Generator gen(10);
  struct Case {
    Shape x;  // N, C, H, W
    int64_t oh, ow;
  };
  const std::vector<Case> cases = {
      {{2, 3, 7, 9}, 5, 6},     {{1, 2, 1, 1}, 4, 3},      {{2, 1, 1, 5}, 3, 3},
      {{1, 4, 6, 1}, 2, 7},     {{2, 16, 48, 64}, 40, 56}, {{1, 1, 30, 40}, 50, 60},
      {{8, 2, 20, 24}, 20, 24},
  };
  for (const Case& c : cases) {
    for (GridPadding pad : {GridPadding::zeros, GridPadding::border}) {
      for (bool ac : {false, true}) {
        const std::string what =
            shape_text(c.x) + " grid " + std::to_string(c.oh) + "x" + std::to_string(c.ow) +
            (pad == GridPadding::zeros ? " zeros" : " border") + (ac ? " align_corners" : "");
        const GridSampleParams p{pad, ac};
        const Pair x = normal(c.x, gen);
        const Pair grid = sample_grid(c.x[0], c.oh, c.ow, c.x[2], c.x[3], ac, 2.0, gen);
        const Shape out = {c.x[0], c.x[1], c.oh, c.ow};
        expect_close(run_both(OpId::grid_sample, {x, grid}, {out}, &p), 1e-5,
                     "grid_sample " + what);
        const Pair gy = normal(out, gen);
        expect_close(
            run_both(OpId::grid_sample_backward, {gy, x, grid}, {c.x, grid.t64.shape()}, &p), 1e-5,
            "grid_sample backward " + what);
      }
    }
  }
}

// PyTorch's border padding (clip_coordinates_set_grad) has zero gradient AT the clip limits too:
// with align_corners, grid (-1, -1) is pixel (0, 0) exactly and grid y = 1 is row H - 1; both are
// clipped, so those gradient components are 0. Verified against PyTorch 1.13 grid_sample.
TEST(CpuResampleKernels, GridSampleBorderGradientZeroAtClipLimits) {
  const KernelInfo* fwd = kernel_registry().find(OpId::grid_sample, DeviceType::cpu, DType::f32);
  const KernelInfo* bwd =
      kernel_registry().find(OpId::grid_sample_backward, DeviceType::cpu, DType::f32);
  ASSERT_TRUE(fwd && bwd);
  std::vector<double> xv(20);
  for (size_t i = 0; i < xv.size(); ++i) xv[i] = static_cast<double>(i * i % 7) - 2.0;
  Tensor x = Tensor::from_vector(xv, {1, 1, 4, 5}, DType::f32);
  Tensor grid =
      Tensor::from_vector(std::vector<double>{-1.0, -1.0, 0.5, 1.0}, {1, 1, 2, 2}, DType::f32);
  const GridSampleParams p{GridPadding::border, true};
  Tensor y = Tensor::empty({1, 1, 1, 2}, DType::f32);
  fwd->fn(KernelArgs{{x, grid}, {y}, &p});
  // (0.5, 1.0) -> pixel (x 3, y 3).
  EXPECT_FLOAT_EQ(y.data<float>()[0], static_cast<float>(xv[0]));
  EXPECT_FLOAT_EQ(y.data<float>()[1], static_cast<float>(xv[3 * 5 + 3]));
  Tensor gy = Tensor::from_vector(std::vector<double>{1.0, 1.0}, {1, 1, 1, 2}, DType::f32);
  Tensor gx = Tensor::empty({1, 1, 4, 5}, DType::f32);
  Tensor ggrid = Tensor::empty({1, 1, 2, 2}, DType::f32);
  bwd->fn(KernelArgs{{gy, x, grid}, {gx, ggrid}, &p});
  const float* gg = ggrid.data<float>();
  EXPECT_EQ(gg[0], 0.0f);
  EXPECT_EQ(gg[1], 0.0f);
  EXPECT_EQ(gg[3], 0.0f);
  // d/dx at (3, 3) on the bottom row: (x[3][4] - x[3][3]) * (W - 1) / 2.
  EXPECT_FLOAT_EQ(gg[2], static_cast<float>((xv[3 * 5 + 4] - xv[3 * 5 + 3]) * 2.0));
}

}  // namespace
}  // namespace cvd
