#include "pipeline/io/output_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "engine/error.h"

namespace cvd {

namespace {

// The command line of a process, from /proc (empty when it cannot be read).
std::string command_of(const std::string& pid) {
  std::ifstream in("/proc/" + pid + "/cmdline", std::ios::binary);
  std::string cmd((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (char& c : cmd)
    if (c == '\0') c = ' ';
  while (!cmd.empty() && cmd.back() == ' ') cmd.pop_back();
  return cmd;
}

}  // namespace

OutputFolderLock::OutputFolderLock(const std::filesystem::path& dir) {
  const std::filesystem::path file = dir / ".lock";
  fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0)
    fail(ErrorCategory::io, "{}: cannot open the output folder's lock: {}", file.string(),
         std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    std::string holder;
    {
      std::ifstream in(file);
      std::getline(in, holder);
    }
    ::close(fd_);
    fd_ = -1;
    if (err != EWOULDBLOCK)
      fail(ErrorCategory::io, "{}: cannot lock the output folder: {}", file.string(),
           std::strerror(err));
    std::string who = holder.empty() ? "another process" : "process " + holder;
    if (!holder.empty()) {
      const std::string cmd = command_of(holder);
      if (!cmd.empty()) who += " (" + cmd + ")";
    }
    fail(ErrorCategory::io,
         "{}: the output folder is in use by {}; wait for it to finish or choose another -o",
         dir.string(), who);
  }
  // Record who holds it, for the message a second run prints.
  const std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, pid.data(), pid.size(), 0) < 0) {
    // The lock holds without the record; the message then says "another process".
  }
}

OutputFolderLock::~OutputFolderLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the flock
}

}  // namespace cvd
