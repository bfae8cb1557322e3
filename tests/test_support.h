// Helpers shared by the test files: locating the shared data, temporary directories, running
// the cvd binary.
#pragma once
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "engine/compute_precision.h"

namespace cvd::test {

// ../shared/data/<name>, or empty when absent (then the test must GTEST_SKIP with a reason).
inline std::filesystem::path shared_data(const std::string& name) {
  std::filesystem::path p = std::filesystem::path(CVD_SHARED_DIR) / "data" / name;
  return std::filesystem::exists(p) ? p : std::filesystem::path();
}

#define CVD_REQUIRE_SHARED_DATA(var, name)                                            \
  const std::filesystem::path var = ::cvd::test::shared_data(name);                   \
  if (var.empty()) {                                                                  \
    GTEST_SKIP() << "shared data '" << name << "' not found under " << CVD_SHARED_DIR \
                 << "/data (it exists in CI and on developer machines)";              \
  }

// Skips the test on a CPU whose oneDNN ISA has neither AMX nor AVX512-BF16
// (engine/compute_precision.h), saying what it offers.
#define CVD_REQUIRE_NATIVE_BF16()                                      \
  if (std::string why_no_bf16; !::cvd::bf16_supported(&why_no_bf16)) { \
    GTEST_SKIP() << "no native bf16 on this CPU: " << why_no_bf16;     \
  }

// A fresh empty directory under the system temp dir, removed when the object dies.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "cvd-test-XXXXXX").string();
    char* d = mkdtemp(tmpl.data());
    if (!d) throw std::runtime_error("mkdtemp failed");
    path_ = d;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& s) const { return path_ / s; }

 private:
  std::filesystem::path path_;
};

inline std::filesystem::path source_dir() { return CVD_SOURCE_DIR; }
inline std::string cli_path() { return CVD_CLI_PATH; }

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// Runs a shell command, capturing stdout+stderr.
inline CommandResult run_command(const std::string& cmd) {
  CommandResult r;
  FILE* f = popen((cmd + " 2>&1").c_str(), "r");
  if (!f) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, f)) > 0) r.output.append(buf, n);
  int status = pclose(f);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

// `p` in single quotes, for a shell command line.
inline std::string shell_quoted(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

// Runs the cvd CLI with the given argument string.
inline CommandResult run_cvd(const std::string& args) {
  return run_command(cli_path() + " " + args);
}

// The value of `cvd run --intrinsics` ("fx,fy,cx,cy", full precision) for an intrinsics.json
// (a generated scene's, or a run's output).
inline std::string intrinsics_flag_value(const std::filesystem::path& intrinsics_json) {
  std::ifstream in(intrinsics_json);
  const nlohmann::json k = nlohmann::json::parse(in);
  char v[256];
  std::snprintf(v, sizeof v, "%.17g,%.17g,%.17g,%.17g", k.at("fx").get<double>(),
                k.at("fy").get<double>(), k.at("cx").get<double>(), k.at("cy").get<double>());
  return v;
}

}  // namespace cvd::test
