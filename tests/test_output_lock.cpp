// One run per output folder (pipeline/io/output_lock.h): a second lock on the folder fails at
// once naming the holder, and a lock whose process died does not block; what a killed writer
// left behind is swept (pipeline/io/atomic_file.h).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"
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

TEST(AtomicFile, TemporariesOfOtherProcessesAreSweptAndNothingElse) {
  namespace fs = std::filesystem;
  test::TempDir dir;
  fs::create_directories(dir.path() / "cache" / "flow");
  auto touch = [](const fs::path& p) { write_text_file(p, "x"); };
  // Left by a killed process (pid 1 is never this test): a json, a png, one without extension.
  touch(dir.path() / "cache" / "flow" / ".000000_000001.tmp-1-7.json");
  touch(dir.path() / ".frame.tmp-1-0.png");
  touch(dir.path() / ".run.tmp-1-3");
  // Not temporaries, or this process's own: kept.
  const fs::path own = temporary_path_for(dir.path() / "mine.json");
  touch(own);
  touch(dir.path() / "cache" / "flow" / "000000_000001.json");
  touch(dir.path() / ".hidden");
  touch(dir.path() / ".notes.tmp-abc-1.txt");
  touch(dir.path() / ".notes.tmp-1-.txt");
  touch(dir.path() / ".notes.tmp-1-2.tar.gz");
  touch(dir.path() / "notes.tmp-1-2.txt");
  EXPECT_EQ(remove_stale_temporaries(dir.path()), 3u);
  EXPECT_FALSE(fs::exists(dir.path() / "cache" / "flow" / ".000000_000001.tmp-1-7.json"));
  EXPECT_FALSE(fs::exists(dir.path() / ".frame.tmp-1-0.png"));
  EXPECT_FALSE(fs::exists(dir.path() / ".run.tmp-1-3"));
  EXPECT_TRUE(fs::exists(own));
  EXPECT_TRUE(fs::exists(dir.path() / "cache" / "flow" / "000000_000001.json"));
  EXPECT_TRUE(fs::exists(dir.path() / ".hidden"));
  for (const char* kept :
       {".notes.tmp-abc-1.txt", ".notes.tmp-1-.txt", ".notes.tmp-1-2.tar.gz", "notes.tmp-1-2.txt"})
    EXPECT_TRUE(fs::exists(dir.path() / kept)) << kept;
  EXPECT_EQ(remove_stale_temporaries(dir.path() / "missing"), 0u);
}

}  // namespace
}  // namespace cvd
