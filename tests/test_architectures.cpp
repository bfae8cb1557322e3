// The architecture table (models/depth_net_architectures.h) agrees with the networks it creates,
// (the pipeline's per-architecture lr and lambda are its default_lr / default_lambda).
#include <gtest/gtest.h>

#include "engine/error.h"
#include "models/depth_net_architectures.h"

namespace cvd {

TEST(Architectures, TableMatchesTheNetworksItCreates) {
  ASSERT_GE(depth_net_architectures().size(), 3u);
  for (const DepthNetArchitecture& a : depth_net_architectures()) {
    Generator gen(0);
    // The narrowest width every architecture accepts keeps this quick.
    std::unique_ptr<DepthNet> net = a.create(1.0 / 16, gen);
    EXPECT_EQ(net->arch(), a.name);
    EXPECT_EQ(net->output_kind(), a.output_kind) << a.name;
    EXPECT_EQ(net->alignment(), a.alignment) << a.name;
    EXPECT_GT(a.default_lr, 0) << a.name;
    EXPECT_GE(a.default_lambda, 0) << a.name;
    EXPECT_EQ(&depth_net_architecture(a.name), &a);
  }
}

TEST(Architectures, UnknownNameListsTheAvailableOnes) {
  try {
    depth_net_architecture("midas_v3");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::unsupported);
    for (const DepthNetArchitecture& a : depth_net_architectures())
      EXPECT_NE(std::string(e.what()).find(a.name), std::string::npos) << e.what();
  }
}

}  // namespace cvd
