// Subcommands of the `cvd` CLI register themselves here: each tools/cli/cmd_<name>.cpp defines a
// static CommandRegistration whose setup function adds a CLI11 subcommand and its callback.
#pragma once
#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

namespace cvd::cli {

// Global flags shared by every subcommand.
struct GlobalOptions {
  bool quiet = false;
  bool verbose = false;
  std::vector<std::string> argv;  // the command line as given (for "rerun ..." hints)
};
GlobalOptions& global_options();

struct CommandRegistration {
  // `order` sorts the subcommands in --help.
  CommandRegistration(int order, std::function<void(CLI::App&)> setup);
};

struct RegisteredCommand {
  int order;
  std::function<void(CLI::App&)> setup;
};
std::vector<RegisteredCommand>& registered_commands();

// Exit codes of the cvd CLI (documented in the README).
enum ExitCode : int {
  kExitOk = 0,
  kExitFailure = 1,      // internal error
  kExitUsage = 2,        // bad command line
  kExitBadInput = 3,     // invalid or corrupt input file / argument
  kExitIo = 4,           // cannot read or write (permissions, disk full)
  kExitExternal = 5,     // an external tool (COLMAP, ffmpeg) failed
  kExitNumerical = 6,    // training diverged (non-finite values everywhere)
  kExitUnsupported = 7,  // the build or input asks for something unsupported
  kExitCancelled = 130,
};

}  // namespace cvd::cli
