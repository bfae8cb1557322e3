// The `cvd` command line: every subcommand lives in tools/cli/cmd_<name>.cpp.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "engine/backend_info.h"
#include "engine/error.h"
#include "kernels/builtin_backends.h"
#include "pipeline/run/dependency_versions.h"
#include "tools/cli/command.h"

namespace cvd::cli {

GlobalOptions& global_options() {
  static GlobalOptions o;
  return o;
}

std::vector<RegisteredCommand>& registered_commands() {
  static std::vector<RegisteredCommand> v;
  return v;
}

CommandRegistration::CommandRegistration(int order, std::function<void(CLI::App&)> setup) {
  registered_commands().push_back({order, std::move(setup)});
}

static int exit_code_for(ErrorCategory c) {
  switch (c) {
    case ErrorCategory::invalid_argument:
    case ErrorCategory::format:
      return kExitBadInput;
    case ErrorCategory::io:
      return kExitIo;
    case ErrorCategory::external:
      return kExitExternal;
    case ErrorCategory::numerical:
      return kExitNumerical;
    case ErrorCategory::unsupported:
    case ErrorCategory::device:
      return kExitUnsupported;
    case ErrorCategory::cancelled:
      return kExitCancelled;
    case ErrorCategory::internal:
      return kExitFailure;
  }
  return kExitFailure;
}

}  // namespace cvd::cli

int main(int argc, char** argv) {
  using namespace cvd::cli;
  cvd::register_builtin_backends();
  CLI::App app{"cvd: consistent video depth (Luo et al. 2020) in native C++"};
  app.require_subcommand(1);
  // --version: the build's backends and the devices usable now (a missing GPU is not an error).
  app.set_version_flag("--version", [] {
    std::string v = std::string("cvd ") + CVD_VERSION + "\ncompiled backends:";
    for (const std::string& b : cvd::compiled_backends()) v += "\n  " + b;
    v += "\nCUDA at run time: " + cvd::cuda_runtime_status();
    v += "\ndependencies:";
    for (const std::string& d : cvd::dependency_versions()) v += "\n  " + d;
    return v;
  });
  auto& g = global_options();
  g.argv.assign(argv, argv + argc);
  app.add_flag("-q,--quiet", g.quiet, "Only print errors and the final summary");
  app.add_flag("-v,--verbose", g.verbose, "Print debug detail");
  // Every --help shows each flag's default (subcommands inherit this when they are created).
  app.option_defaults()->always_capture_default(true);
  auto cmds = registered_commands();
  std::sort(cmds.begin(), cmds.end(), [](auto& a, auto& b) { return a.order < b.order; });
  for (auto& c : cmds) c.setup(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int rc = app.exit(e);
    return rc == 0 ? 0 : kExitUsage;
  } catch (const cvd::Error& e) {
    std::fprintf(stderr, "cvd: error: %s\n", e.what());
    return exit_code_for(e.category());
  } catch (const std::filesystem::filesystem_error& e) {
    // A file system call without its own error handling: still an I/O error naming the path.
    std::fprintf(stderr, "cvd: error: %s: %s\n", e.path1().string().c_str(),
                 e.code().message().c_str());
    return kExitIo;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cvd: internal error: %s\n", e.what());
    return kExitFailure;
  }
  return 0;
}
