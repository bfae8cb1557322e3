// One run per output folder (pipeline/io/output_lock.h): a second lock on the folder fails at
// once naming the holder, and a lock whose process died does not block.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include "engine/error.h"
#include "pipeline/io/output_lock.h"
#include "test_support.h"

namespace cvd {
namespace {

TEST(OutputLock, SecondLockFailsNamingTheHolderAndADeadHolderDoesNotBlock) {
  test::TempDir dir;
  int ready[2];
  ASSERT_EQ(pipe(ready), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    // The holder: takes the lock, says so, and waits to be killed.
    OutputFolderLock lock(dir.path());
    const char c = 'x';
    if (write(ready[1], &c, 1) != 1) _exit(1);
    for (;;) pause();
  }
  char c = 0;
  ASSERT_EQ(read(ready[0], &c, 1), 1);
  try {
    OutputFolderLock second(dir.path());
    FAIL() << "a second lock on a folder in use succeeded";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::io);
    EXPECT_NE(std::string(e.what()).find("in use by process " + std::to_string(child)),
              std::string::npos)
        << e.what();
  }
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  close(ready[0]);
  close(ready[1]);
  // The killed holder's lock is gone with it; its file stays and does not block.
  EXPECT_NO_THROW(OutputFolderLock again(dir.path()));
  // Released on destruction: locking twice in a row works.
  { OutputFolderLock a(dir.path()); }
  EXPECT_NO_THROW(OutputFolderLock b(dir.path()));
}

}  // namespace
}  // namespace cvd
