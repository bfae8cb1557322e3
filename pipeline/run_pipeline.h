// The whole CVD pipeline (DESIGN.md section 6): frames -> poses -> initial depth -> scale
// calibration -> pair sampling -> flow -> test-time training -> outputs -> evaluation.
// Every stage caches its result under <out>/cache, so rerunning the same command resumes.
#pragma once
#include "pipeline/run_options.h"

namespace cvd {

RunResult run_pipeline(const RunOptions& options);

// Default (lr, lambda) of the paper per architecture (DESIGN.md 6.6).
double default_learning_rate(const std::string& arch);
double default_lambda(const std::string& arch);

}  // namespace cvd
