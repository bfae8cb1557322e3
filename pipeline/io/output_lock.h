// One run per output folder: an exclusive flock on OUT/.lock held for the whole run. A second run
// on the same folder fails at once, naming the process that holds it; the lock dies with its
// process, so a run that was killed leaves nothing that blocks the next one.
#pragma once
#include <filesystem>

namespace cvd {

class OutputFolderLock {
 public:
  // Creates `dir`/.lock if needed and locks it. Throws Error(io) naming the file and the holding
  // process (its PID and command, as recorded in the file) when another process holds it.
  explicit OutputFolderLock(const std::filesystem::path& dir);
  ~OutputFolderLock();
  OutputFolderLock(const OutputFolderLock&) = delete;
  OutputFolderLock& operator=(const OutputFolderLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace cvd
