// The main of the Google Benchmark programs: registers the compiled-in backends with the engine
// (kernels/builtin_backends.h), then runs the benchmarks.
#pragma once
#include <benchmark/benchmark.h>

#include "kernels/builtin_backends.h"

#define CVD_BENCHMARK_MAIN()                                          \
  int main(int argc, char** argv) {                                   \
    cvd::register_builtin_backends();                                 \
    benchmark::Initialize(&argc, argv);                               \
    if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1; \
    benchmark::RunSpecifiedBenchmarks();                              \
    benchmark::Shutdown();                                            \
    return 0;                                                         \
  }
