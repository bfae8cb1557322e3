// The `cvd` command line: every subcommand lives in tools/cli/cmd_<name>.cpp.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "engine/backend_info.h"
#include "engine/error.h"
#include "engine/process_group.h"
#include "kernels/builtin_backends.h"
#include "pipeline/run/dependency_versions.h"
#include "tools/cli/command.h"
#include "tools/distributed/mpi_process_group.h"

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

int run_cli(int argc, char** argv);

namespace {

// Under mpirun: one rank's failure ends the whole job (the others would wait forever in a
// collective); its message names the rank.
int failed(int rc, const std::string& message) {
  cvd::ProcessGroup& pg = cvd::process_group();
  if (pg.size() == 1) {
    std::fprintf(stderr, "cvd: %s\n", message.c_str());
    return rc;
  }
  std::fprintf(stderr, "cvd: rank %d of %d: %s; ending every rank\n", pg.rank(), pg.size(),
               message.c_str());
  std::fflush(stderr);
  pg.abort(rc);
  return rc;  // not reached
}

}  // namespace

int main(int argc, char** argv) {
  using namespace cvd::cli;
  cvd::register_builtin_backends();
  if (cvd::launched_by_mpi()) {
    if (!cvd::mpi_compiled()) {
      std::fprintf(stderr,
                   "cvd: error: started by an MPI launcher, but this cvd was built without MPI; "
                   "each rank would run alone on the same output (rebuild with libopenmpi-dev "
                   "installed, or run without mpirun)\n");
      return kExitUnsupported;
    }
    try {
      cvd::set_process_group(cvd::start_mpi_process_group());
    } catch (const cvd::Error& e) {
      std::fprintf(stderr, "cvd: error: %s\n", e.what());
      return kExitUnsupported;
    }
  }
  const int rc = run_cli(argc, argv);  // a failure on one of several ranks does not return
  // Ranks that finished wait (without spinning) for rank 0's outputs before MPI_Finalize.
  if (cvd::process_group().size() > 1) cvd::process_group().barrier();
  cvd::finish_mpi();
  return rc;
}

int run_cli(int argc, char** argv) {
  using namespace cvd::cli;
  CLI::App app{"cvd: consistent video depth (Luo et al. 2020) in native C++"};
  app.require_subcommand(1);
  // --version: the build's backends and the devices usable now (a missing GPU is not an error).
  app.set_version_flag("--version", [] {
    std::string v = std::string("cvd ") + CVD_VERSION + "\ncompiled backends:";
    for (const std::string& b : cvd::compiled_backends()) v += "\n  " + b;
    v += "\nCUDA at run time: " + cvd::cuda_runtime_status();
    v += "\ndependencies:";
    for (const std::string& d : cvd::dependency_versions()) v += "\n  " + d;
    v += "\nMPI: " + (cvd::mpi_compiled()
                          ? cvd::mpi_library_version() + " (mpirun -np R cvd run ...)"
                          : std::string("not compiled (-DCVD_MPI=ON)"));
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
    // --help and --version print and succeed; a bad command line reads like every other error.
    if (e.get_exit_code() == 0) return app.exit(e);
    std::fprintf(stderr, "cvd: error: %s\nRun with --help for more information.\n", e.what());
    return kExitUsage;
  } catch (const cvd::Error& e) {
    return failed(exit_code_for(e.category()), std::string("error: ") + e.what());
  } catch (const std::filesystem::filesystem_error& e) {
    // A file system call without its own error handling: still an I/O error naming the path.
    return failed(kExitIo, "error: " + e.path1().string() + ": " + e.code().message());
  } catch (const std::exception& e) {
    return failed(kExitFailure, std::string("internal error: ") + e.what());
  }
  return 0;
}
