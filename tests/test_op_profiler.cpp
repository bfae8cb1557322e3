// engine/op_profiler: per-op kernel time recorded by dispatch() only while profiling is on.
#include "engine/op_profiler.h"

#include <gtest/gtest.h>

#include <string>

#include "engine/ops.h"
#include "engine/random.h"
#include "engine/tensor.h"

namespace cvd {
namespace {

const op_profiler::OpTotal* find_total(const std::vector<op_profiler::OpTotal>& all, OpId op) {
  for (const auto& t : all) {
    if (t.op == op) return &t;
  }
  return nullptr;
}

// Restores the profiler state after each test.
struct ProfilerOn {
  ProfilerOn() {
    op_profiler::reset();
    op_profiler::set_enabled(true);
  }
  ~ProfilerOn() {
    op_profiler::set_enabled(false);
    op_profiler::reset();
  }
};

TEST(OpProfiler, CountsEveryDispatchedCallOfAnOp) {
  Generator gen(3);
  const Tensor a = Tensor::randn({64, 64}, gen), b = Tensor::randn({64, 64}, gen);
  ProfilerOn on;
  for (int i = 0; i < 3; ++i) (void)add(a, b);
  (void)relu(a);
  const auto all = op_profiler::totals();
  const op_profiler::OpTotal* bin = find_total(all, OpId::binary);
  ASSERT_NE(bin, nullptr);
  EXPECT_EQ(bin->calls, 3);
  EXPECT_GT(bin->seconds, 0.0);
  const op_profiler::OpTotal* un = find_total(all, OpId::unary);
  ASSERT_NE(un, nullptr);
  EXPECT_EQ(un->calls, 1);
  // Sorted by time, most first.
  for (size_t i = 1; i < all.size(); ++i) EXPECT_GE(all[i - 1].seconds, all[i].seconds);
  const std::string r = op_profiler::report(10.0);
  EXPECT_NE(r.find("elementwise"), std::string::npos) << r;
  EXPECT_NE(r.find("binary"), std::string::npos) << r;
  EXPECT_NE(r.find("outside kernels"), std::string::npos) << r;
}

TEST(OpProfiler, RecordsNothingWhenOffAndResetClears) {
  Generator gen(4);
  const Tensor a = Tensor::randn({16, 16}, gen);
  op_profiler::set_enabled(false);
  op_profiler::reset();
  (void)add(a, a);
  EXPECT_TRUE(op_profiler::totals().empty());
  {
    ProfilerOn on;
    (void)add(a, a);
    EXPECT_EQ(op_profiler::totals().size(), 1u);
    op_profiler::reset();
    EXPECT_TRUE(op_profiler::totals().empty());
  }
}

TEST(OpProfiler, FamiliesGroupTheOpsOfOneKind) {
  EXPECT_STREQ(op_profiler::op_family(OpId::conv2d_backward_weight), "conv");
  EXPECT_STREQ(op_profiler::op_family(OpId::conv_transpose2d), "conv");
  EXPECT_STREQ(op_profiler::op_family(OpId::batch_norm_backward), "batch_norm");
  EXPECT_STREQ(op_profiler::op_family(OpId::upsample_bilinear2d_backward), "resample");
  EXPECT_STREQ(op_profiler::op_family(OpId::adam_update), "optimizer");
  EXPECT_STREQ(op_profiler::op_family(OpId::concat), "layout");
  for (int i = 0; i < kNumOps; ++i) {
    EXPECT_STRNE(op_profiler::op_family(static_cast<OpId>(i)), "other")
        << op_name(static_cast<OpId>(i));
  }
}

}  // namespace
}  // namespace cvd
