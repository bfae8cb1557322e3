#include "pipeline/io/atomic_file.h"

#include <unistd.h>

#include <atomic>
#include <fstream>
#include <regex>
#include <string>
#include <vector>

#include "engine/error.h"

namespace cvd {

std::filesystem::path temporary_path_for(const std::filesystem::path& target) {
  static std::atomic<unsigned long> counter{0};
  const std::string name = "." + target.stem().string() + ".tmp-" +
                           std::to_string(static_cast<long>(::getpid())) + "-" +
                           std::to_string(counter.fetch_add(1)) + target.extension().string();
  return target.parent_path() / name;
}

size_t remove_stale_temporaries(const std::filesystem::path& root) {
  namespace fs = std::filesystem;
  static const std::regex name(R"(^\..*\.tmp-([0-9]+)-[0-9]+(\.[^.]*)?$)");
  const std::string own = std::to_string(static_cast<long>(::getpid()));
  std::error_code ec;
  std::vector<fs::path> stale;
  for (auto it = fs::recursive_directory_iterator(root, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    std::smatch m;
    const std::string file = it->path().filename().string();
    if (std::regex_match(file, m, name) && m[1].str() != own) stale.push_back(it->path());
  }
  size_t removed = 0;
  for (const fs::path& p : stale) removed += fs::remove(p, ec) ? 1 : 0;
  return removed;
}

void write_atomically(const std::filesystem::path& target,
                      const std::function<void(const std::filesystem::path& tmp)>& write) {
  const std::filesystem::path tmp = temporary_path_for(target);
  try {
    write(tmp);
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw;
  }
  std::error_code ec;
  std::filesystem::rename(tmp, target, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    fail(ErrorCategory::io, "cannot rename '{}' to '{}': {}", tmp.string(), target.string(),
         ec.message());
  }
}

void write_text_file(const std::filesystem::path& target, std::string_view content) {
  write_atomically(target, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out)
      fail(ErrorCategory::io, "cannot open '{}' for writing '{}'", tmp.string(), target.string());
    out.write(content.data(), std::streamsize(content.size()));
    out.close();
    if (!out)
      fail(ErrorCategory::io, "writing '{}' failed (disk full or no permission?)", target.string());
  });
}

}  // namespace cvd
