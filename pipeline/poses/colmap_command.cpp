#include "pipeline/poses/colmap_command.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <cerrno>
#include <cstring>
#include <deque>
#include <fstream>

#include "engine/error.h"

extern char** environ;

namespace cvd::colmap {

namespace fs = std::filesystem;

namespace {

// Shell-style quoting, only for logging the command (nothing is ever run through a shell).
std::string quoted(const std::string& s) {
  if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                        "0123456789-_./=,:+") == std::string::npos)
    return s;
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

}  // namespace

std::string tail_lines(const fs::path& file, size_t n) {
  std::ifstream in(file);
  std::deque<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    lines.push_back(line);
    if (lines.size() > n) lines.pop_front();
  }
  std::string out;
  for (const auto& l : lines) out += "\n  | " + l;
  return out;
}

CommandRun run_logged(const fs::path& exe, const std::string& subcommand,
                      const std::vector<std::string>& args, ColmapResult& result) {
  const fs::path& log = result.log_file;
  std::vector<std::string> argv_s = {exe.string(), subcommand};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::string printable;
  for (const auto& a : argv_s) printable += (printable.empty() ? "" : " ") + quoted(a);
  spdlog::info("colmap: running {}", printable);
  {
    std::ofstream l(log, std::ios::app);
    l << "\n==== " << printable << "\n";
  }
  std::vector<char*> argv;
  for (auto& a : argv_s) argv.push_back(a.data());
  argv.push_back(nullptr);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  std::string log_s = log.string();
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_s.c_str(),
                                   O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  auto t0 = Clock::now();
  pid_t pid = 0;
  int rc = posix_spawn(&pid, argv_s[0].c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) fail(ErrorCategory::external, "cannot start {}: {}", argv_s[0], std::strerror(rc));
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) fail(ErrorCategory::external, "waitpid on colmap {} failed", subcommand);
  }
  CommandRun run;
  run.seconds = seconds_since(t0);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  spdlog::info("colmap {}: exit code {}, {:.1f} s", subcommand, run.exit_code, run.seconds);
  result.step_seconds.emplace_back(subcommand, run.seconds);
  return run;
}

void require_success(const CommandRun& run, const std::string& subcommand, const fs::path& log) {
  if (run.exit_code != 0)
    fail(ErrorCategory::external,
         "COLMAP {} failed with exit code {}; its log is {}; last lines:{}", subcommand,
         run.exit_code, log.string(), tail_lines(log, 8));
}

std::vector<std::string> bundle_adjuster_args(const std::filesystem::path& input,
                                              const std::filesystem::path& output,
                                              bool refine_focal) {
  return {"--input_path",
          input.string(),
          "--output_path",
          output.string(),
          "--BundleAdjustment.refine_focal_length",
          refine_focal ? "1" : "0",
          "--BundleAdjustment.refine_principal_point",
          "0",
          "--BundleAdjustment.refine_extra_params",
          "0",
          "--BundleAdjustment.function_tolerance",
          "1e-6",
          "--BundleAdjustment.max_num_iterations",
          "50"};
}

}  // namespace cvd::colmap
