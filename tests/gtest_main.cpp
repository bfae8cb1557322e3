// The main of every test executable: registers the compiled-in backends with the engine
// (kernels/builtin_backends.h), then runs GoogleTest.
#include <gtest/gtest.h>

#include "kernels/builtin_backends.h"

int main(int argc, char** argv) {
  cvd::register_builtin_backends();
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
