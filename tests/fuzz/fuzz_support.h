// Shared by the libFuzzer targets in tests/fuzz/: the readers take file paths, so each input is
// written to a per-process scratch file first. A reader may reject an input only with cvd::Error;
// any other exception escaping it is a bug (it would surface as "internal error" in the CLI), so
// it aborts like a crash.
#pragma once
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "engine/error.h"

namespace cvd::fuzz {

inline std::filesystem::path scratch_path(const std::string& name) {
  return std::filesystem::temp_directory_path() /
         ("cvd-fuzz-" + std::to_string(getpid()) + "-" + name);
}

inline void write_bytes(const std::filesystem::path& p, std::string_view bytes) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

inline std::filesystem::path input_file(const uint8_t* data, size_t size, const std::string& name) {
  std::filesystem::path p = scratch_path(name);
  write_bytes(p, std::string_view(reinterpret_cast<const char*>(data), size));
  return p;
}

template <class F>
void expect_only_cvd_errors(F&& read) {
  try {
    read();
  } catch (const cvd::Error&) {
    // a clean rejection
  } catch (const std::exception& e) {
    std::fprintf(stderr, "reader threw a non-cvd exception: %s\n", e.what());
    std::abort();
  }
}

}  // namespace cvd::fuzz
