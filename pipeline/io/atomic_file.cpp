#include "pipeline/io/atomic_file.h"

#include <unistd.h>

#include <atomic>
#include <fstream>
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

namespace {

// The process id in a name temporary_path_for() made ("." stem ".tmp-" pid "-" n [extension]),
// or an empty string for any other name.
std::string temporary_owner(const std::string& file) {
  if (file.empty() || file[0] != '.') return {};
  const size_t tag = file.rfind(".tmp-");
  if (tag == std::string::npos || tag == 0) return {};
  auto digits = [&](size_t from) {
    size_t to = from;
    while (to < file.size() && file[to] >= '0' && file[to] <= '9') ++to;
    return to;
  };
  const size_t pid_begin = tag + 5, pid_end = digits(pid_begin);
  if (pid_end == pid_begin || pid_end >= file.size() || file[pid_end] != '-') return {};
  const size_t n_end = digits(pid_end + 1);
  if (n_end == pid_end + 1) return {};
  // What follows the counter is nothing or one extension ("." and no further dot).
  if (n_end < file.size() && (file[n_end] != '.' || file.find('.', n_end + 1) != std::string::npos))
    return {};
  return file.substr(pid_begin, pid_end - pid_begin);
}

}  // namespace

size_t remove_stale_temporaries(const std::filesystem::path& root) {
  namespace fs = std::filesystem;
  const std::string own = std::to_string(static_cast<long>(::getpid()));
  std::error_code ec;
  std::vector<fs::path> stale;
  for (auto it = fs::recursive_directory_iterator(root, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    const std::string owner = temporary_owner(it->path().filename().string());
    if (!owner.empty() && owner != own) stale.push_back(it->path());
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
