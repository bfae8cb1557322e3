// Running COLMAP's subcommands for the pose stage (pipeline/poses/colmap_runner.h): without a
// shell, output appended to the stage's log, wall time recorded; and the error a failed step gives.
#pragma once
#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/elapsed_time.h"
#include "pipeline/poses/colmap_runner.h"

namespace cvd::colmap {

using Clock = std::chrono::steady_clock;

// The last `n` non-empty lines of a text file, each on a new line prefixed "  | " (for errors).
std::string tail_lines(const std::filesystem::path& file, size_t n);

struct CommandRun {
  int exit_code = -1;
  double seconds = 0;
};

// Runs `exe subcommand args...` without a shell, stdout and stderr appended to result.log_file,
// stdin from /dev/null; the wall time is logged and appended to result.step_seconds.
CommandRun run_logged(const std::filesystem::path& exe, const std::string& subcommand,
                      const std::vector<std::string>& args, ColmapResult& result);

// The arguments of `colmap bundle_adjuster` on `input` -> `output`: the focal free or fixed,
// principal point and distortion fixed, and Ceres' own stopping rule (relative cost change below
// 1e-6, at most 50 iterations). COLMAP's bundle_adjuster sets every tolerance to 0, so it always
// ran its 100 iterations: on a 600-frame clip each took 80 s while the cost had stopped moving
// after 4 (bench/keyframe_poses.sh, issue 23).
std::vector<std::string> bundle_adjuster_args(const std::filesystem::path& input,
                                              const std::filesystem::path& output,
                                              bool refine_focal);

// Error(external) naming the subcommand, its exit code and the log's last lines, unless it
// succeeded.
void require_success(const CommandRun& run, const std::string& subcommand,
                     const std::filesystem::path& log);

}  // namespace cvd::colmap
