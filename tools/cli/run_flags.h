// The `cvd run` flags (shared with `cvd demo`), bound to a RunOptions.
#pragma once
#include <CLI/CLI.hpp>

#include <string>

#include "pipeline/run/run_options.h"

namespace cvd::cli {

struct RunFlagStrings {
  std::string intrinsics;           // "fx,fy,cx,cy"
  std::string quality = "default";  // --quality preset
  // The knobs a preset sets; a flag given on the command line keeps its value.
  CLI::Option *depth_size = nullptr, *width = nullptr, *epochs = nullptr, *warmup = nullptr,
              *quality_flag = nullptr;
};

// Adds the pipeline flags (everything but input/output) to `cmd`. ground_truth_poses: the command
// has ground-truth poses (`cvd demo`), so --poses-source also takes "gt".
void add_pipeline_flags(CLI::App* cmd, RunOptions& o, RunFlagStrings& s,
                        bool ground_truth_poses = false);
// Applies parsed string flags (--intrinsics, the --quality preset to the knobs not given) to `o`;
// throws cvd::Error on bad values.
void apply_flag_strings(const RunFlagStrings& s, RunOptions& o);
// Logging level from the global -q / -v flags.
void configure_logging();

}  // namespace cvd::cli
