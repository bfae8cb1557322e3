// The `cvd run` flags (shared with `cvd demo`), bound to a RunOptions.
#pragma once
#include <CLI/CLI.hpp>

#include <string>

#include "pipeline/run/run_options.h"

namespace cvd::cli {

struct RunFlagStrings {
  std::string intrinsics;  // "fx,fy,cx,cy"
};

// Adds the pipeline flags (everything but input/output) to `cmd`.
void add_pipeline_flags(CLI::App* cmd, RunOptions& o, RunFlagStrings& s);
// Applies parsed string flags (e.g. --intrinsics) to `o`; throws cvd::Error on bad values.
void apply_flag_strings(const RunFlagStrings& s, RunOptions& o);
// Logging level from the global -q / -v flags.
void configure_logging();

}  // namespace cvd::cli
