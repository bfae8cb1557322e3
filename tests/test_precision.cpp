// `--precision bf16` (issue 9, engine/compute_precision.h) end to end: on a CPU with AMX or
// AVX512-BF16 a whole `cvd run` in bf16 gives the depth of the f32 run within bf16 rounding, and
// says so in run.json; on a CPU without native bf16 (simulated with oneDNN's ONEDNN_MAX_CPU_ISA)
// the run is refused with the `unsupported` exit code before any output is written.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <vector>

#include "engine/autograd.h"
#include "engine/compute_precision.h"
#include "engine/error.h"
#include "engine/random.h"
#include "models/depth_net.h"
#include "pipeline/io/pfm_io.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using test::CommandResult;
using test::shell_quoted;
using test::TempDir;

class PrecisionClip : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    CommandResult r = test::run_cvd("scene --out " + shell_quoted(dir_->path() / "scene") +
                                    " --frames 6 --width 128 --height 96");
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  // `cvd run` on the clip with its poses and intrinsics, 3 epochs of the default network at
  // width 0.25 (16-64 channels: its convolutions of 16+ channels a side run in bf16).
  static std::string run_args(const fs::path& out, const std::string& precision) {
    const fs::path scene = dir_->path() / "scene";
    const std::string intr = test::intrinsics_flag_value(scene / "intrinsics.json");
    return "run " + shell_quoted(scene / "rgb") + " -o " + shell_quoted(out) +
           " --epochs 3 --warmup 20 --width 0.25 --depth-size 64 --no-videos --no-ply --poses " +
           shell_quoted(scene / "poses.txt") + " --poses-format tum --intrinsics " + intr +
           " --precision " + precision + " --pair-precision f32";
  }
  static TempDir* dir_;
};
TempDir* PrecisionClip::dir_ = nullptr;

// Per-pixel |a - b| / b over the depth PFMs of two runs, all frames together.
std::vector<double> relative_depth_differences(const fs::path& a, const fs::path& b) {
  std::vector<double> d;
  for (const auto& e : fs::directory_iterator(a / "depth")) {
    if (e.path().extension() != ".pfm") continue;
    cv::Mat da = read_pfm(e.path()), db = read_pfm(b / "depth" / e.path().filename());
    EXPECT_EQ(da.size(), db.size()) << e.path();
    if (da.size() != db.size()) continue;
    for (int y = 0; y < da.rows; ++y)
      for (int x = 0; x < da.cols; ++x) {
        const double va = da.at<float>(y, x), vb = db.at<float>(y, x);
        d.push_back(std::abs(va - vb) / std::max(std::abs(vb), 1e-6));
      }
  }
  return d;
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return INFINITY;
  auto at = v.begin() + static_cast<std::ptrdiff_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), at, v.end());
  return *at;
}

// Median absolute relative depth error against the clip's ground truth (per-frame median
// scaling), from `cvd eval`.
double abs_rel_vs_gt(const fs::path& run, const fs::path& scene) {
  CommandResult r =
      test::run_cvd("-q eval --pred " + shell_quoted(run) + " --gt " + shell_quoted(scene));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  json m = json::parse(std::ifstream(run / "eval" / "metrics.json"));
  return m["depth"]["median_frame"]["depth"]["abs_rel"].get<double>();
}

// The runs hold their flow pairs in f32 (--pair-precision f32), the storage the spreads below
// were measured with: half-precision flows perturb the inputs too, which on a clip this chaotic
// is a third source of run-to-run difference (with them, CI measured bf16 0.94% from f32 and the
// seeds 0.35% apart), and this test isolates the arithmetic.
// Test-time training on this 6-frame clip is chaotic: two f32 runs that differ only in the seed
// (the order of the pairs) end 11.6% apart (median relative depth difference, measured), while
// bf16 and f32 with the same seed end 7.1% apart. What bf16 must not do is move the result
// further than the training's own run-to-run spread, or make it worse against the ground truth:
// asserted are median(bf16 vs f32) <= twice the larger of median(f32 seed 1 vs f32 seed 2) and
// median(f32 seed 1 vs f32 seed 3), and AbsRel(bf16) <= 1.2 AbsRel(f32) (measured 0.233 vs 0.298).
// Twice: the bf16 difference is one more draw of the same chaotic spread, and one draw exceeds
// the larger of two others by chance one time in three; on a fresh VM of the same kind on
// 2026-12-06 it measured 1.92% against seed spreads of at most 1.59%.
// One seed pair is too small a sample of the spread: on 2026-12-05 a change of f32 rounding alone
// (backward recomputing activations, engine/rematerialize.h) moved bf16-vs-f32 from 0.35% to
// 0.54% and the seed-2 spread from 0.97% to 0.37%. The networks' bf16 arithmetic itself is checked
// tightly by the next test and by test_onednn_kernels.
TEST_F(PrecisionClip, Bf16RunStaysWithinTheTrainingsOwnSpreadOfTheF32Run) {
  CVD_REQUIRE_NATIVE_BF16();
  const fs::path f32 = dir_->path() / "f32", bf16 = dir_->path() / "bf16",
                 f32_seed2 = dir_->path() / "f32-seed2", f32_seed3 = dir_->path() / "f32-seed3";
  for (const auto& [out, args] :
       {std::pair{f32, run_args(f32, "f32")}, std::pair{bf16, run_args(bf16, "bf16")},
        std::pair{f32_seed2, run_args(f32_seed2, "f32") + " --seed 2"},
        std::pair{f32_seed3, run_args(f32_seed3, "f32") + " --seed 3"}}) {
    CommandResult r = test::run_cvd(args);
    ASSERT_EQ(r.exit_code, 0) << out << "\n" << r.output;
  }
  json info = json::parse(std::ifstream(bf16 / "run.json"));
  EXPECT_EQ(info["training"]["precision"], "bf16");
  EXPECT_EQ(info["training"]["precision_unit"], bf16_unit());
  EXPECT_EQ(json::parse(std::ifstream(f32 / "run.json"))["training"]["precision"], "f32");
  const std::vector<double> d = relative_depth_differences(bf16, f32);
  const double spread = std::max(quantile(relative_depth_differences(f32_seed2, f32), 0.5),
                                 quantile(relative_depth_differences(f32_seed3, f32), 0.5));
  ASSERT_EQ(d.size(), 6u * 64 * 48);
  EXPECT_LE(quantile(d, 0.5), 2.0 * spread) << "seed spread " << spread;
  // The runs did differ: bf16 really ran (an identical result would mean it was ignored).
  EXPECT_GT(quantile(d, 1.0), 0.0);
  const fs::path scene = dir_->path() / "scene";
  const double e32 = abs_rel_vs_gt(f32, scene), e16 = abs_rel_vs_gt(bf16, scene);
  EXPECT_LE(e16, 1.2 * e32) << "AbsRel f32 " << e32 << ", bf16 " << e16;
}

// One forward of the Mannequin network (random weights, width 0.5, BN in eval mode) in bf16 against
// f32: largest difference <= 0.5% of the output's range (measured 0.10%). bf16 rounds each
// convolution's inputs to 2^-9 relative, and tens of layers accumulate that.
TEST(ComputePrecision, Bf16InferenceOfTheMannequinNetworkMatchesF32) {
  CVD_REQUIRE_NATIVE_BF16();
  // MiDaS with random weights outputs all zeros (its final ReLU), so only Mannequin here.
  for (const char* arch : {"mannequin"}) {
    SCOPED_TRACE(arch);
    Generator gen(5);
    std::unique_ptr<DepthNet> net = create_depth_net(arch, 0.5, gen);
    net->eval();
    Generator data(9);
    const Tensor rgb = Tensor::uniform({2, 3, 96, 128}, data, 0.0, 1.0);
    NoGradGuard no_grad;
    const std::vector<double> a = net->forward_raw(net->normalize_input(rgb)).to_vector();
    std::vector<double> b;
    {
      ScopedComputePrecision bf16(ComputePrecision::bf16);
      b = net->forward_raw(net->normalize_input(rgb)).to_vector();
    }
    ASSERT_EQ(a.size(), b.size());
    double lo = a[0], hi = a[0], worst = 0;
    for (size_t k = 0; k < a.size(); ++k) {
      lo = std::min(lo, a[k]);
      hi = std::max(hi, a[k]);
      worst = std::max(worst, std::abs(a[k] - b[k]));
    }
    ASSERT_GT(hi - lo, 0.0);
    EXPECT_LE(worst, 5e-3 * (hi - lo)) << "range " << lo << ".." << hi;
    EXPECT_GT(worst, 0.0);  // bf16 was used
    std::printf("%s: bf16 vs f32 largest difference %.2e of the output range\n", arch,
                worst / (hi - lo));
  }
}

TEST_F(PrecisionClip, Bf16IsRefusedWithoutNativeBf16AndWritesNothing) {
  // ONEDNN_MAX_CPU_ISA caps the ISA oneDNN uses (and reports) below AVX512-BF16.
  const fs::path out = dir_->path() / "refused";
  CommandResult r = test::run_command("ONEDNN_MAX_CPU_ISA=AVX512_CORE " + test::cli_path() + " " +
                                      run_args(out, "bf16"));
  EXPECT_EQ(r.exit_code, 7) << r.output;  // ErrorCategory::unsupported (README, exit codes)
  EXPECT_NE(r.output.find("--precision bf16 needs a CPU with AMX or AVX512-BF16"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(out));
}

TEST(ComputePrecision, NamesParseAndUnknownOnesAreRejected) {
  EXPECT_EQ(parse_precision("f32"), ComputePrecision::f32);
  EXPECT_EQ(parse_precision("bf16"), ComputePrecision::bf16);
  EXPECT_STREQ(precision_name(ComputePrecision::bf16), "bf16");
  try {
    parse_precision("fp8");
    FAIL() << "fp8 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("fp8"), std::string::npos);
  }
  // The scope restores the previous precision.
  std::string why;
  if (bf16_supported(&why)) {
    {
      ScopedComputePrecision s(ComputePrecision::bf16);
      EXPECT_EQ(compute_precision(), ComputePrecision::bf16);
    }
    EXPECT_EQ(compute_precision(), ComputePrecision::f32);
  }
}

}  // namespace
}  // namespace cvd
