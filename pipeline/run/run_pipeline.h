// The whole CVD pipeline (docs/design.md section 5): frames -> poses -> initial depth -> scale
// calibration -> pair sampling -> flow -> test-time training -> outputs -> evaluation.
// Every stage caches its result under <out>/cache, so rerunning the same command resumes.
#pragma once
#include "pipeline/run/run_options.h"

namespace cvd {

RunResult run_pipeline(const RunOptions& options);

}  // namespace cvd
