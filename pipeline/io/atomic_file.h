// Atomic file writes: content goes to a temporary name next to the target and is renamed onto it
// only when complete, so a reader never sees a half-written file (rename is atomic on POSIX).
#pragma once
#include <filesystem>
#include <functional>
#include <string_view>

namespace cvd {

// A temporary path next to `target` (same directory, so rename cannot cross file systems) that
// keeps the target's extension, as encoders such as cv::imwrite pick the format from it:
// "dir/frame.png" -> "dir/.frame.tmp-<pid>-<n>.png".
std::filesystem::path temporary_path_for(const std::filesystem::path& target);

// Calls write(tmp) with a fresh temporary path, then renames tmp onto `target`. If write throws,
// or the rename fails, the temporary file is removed; a rename failure throws Error(io).
void write_atomically(const std::filesystem::path& target,
                      const std::function<void(const std::filesystem::path& tmp)>& write);

// Removes the temporaries a killed process left under `root` (recursively): files named like
// temporary_path_for() names them whose process id is not this process's. Call it only while
// holding the folder's OutputFolderLock, so no other live writer owns them. Returns the count.
size_t remove_stale_temporaries(const std::filesystem::path& root);

// Writes `content` to `target` atomically. Throws Error(io) naming the file on failure.
void write_text_file(const std::filesystem::path& target, std::string_view content);

}  // namespace cvd
