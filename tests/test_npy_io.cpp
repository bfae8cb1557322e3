// NumPy depth output (pipeline/io/npy_io.h): the (N, H, W) float32 layout NumPy reads, frames
// read back one by one, bad files named with their cause, and `cvd eval`'s reader taking a run
// written with --formats npy only.
#include <gtest/gtest.h>

#include <fstream>

#include "engine/error.h"
#include "pipeline/eval/eval_readers.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/npy_io.h"
#include "test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

std::vector<cv::Mat> maps(int n, int h, int w) {
  std::vector<cv::Mat> m;
  for (int k = 0; k < n; ++k) {
    cv::Mat d(h, w, CV_32F);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) d.at<float>(y, x) = 1.0f + k + 0.01f * y + 0.001f * x;
    m.push_back(d);
  }
  return m;
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

TEST(NpyIo, WritesTheLayoutNumPyReadsAndReadsFramesBack) {
  test::TempDir dir;
  const auto m = maps(3, 5, 7);
  write_npy_stack(dir.path() / "depth.npy", m);
  const std::string bytes = slurp(dir.path() / "depth.npy");
  ASSERT_GE(bytes.size(), 10u);
  EXPECT_EQ(bytes.substr(0, 6), std::string("\x93NUMPY"));
  const size_t header = size_t(uint8_t(bytes[8])) | (size_t(uint8_t(bytes[9])) << 8);
  EXPECT_EQ((10 + header) % 64, 0u);  // data aligned as NumPy writes it
  EXPECT_NE(bytes.find("'shape': (3, 5, 7)"), std::string::npos);
  EXPECT_EQ(bytes.size(), 10 + header + 3 * 5 * 7 * sizeof(float));
  const NpyStackInfo info = read_npy_stack_info(dir.path() / "depth.npy");
  EXPECT_EQ(info.frames, 3);
  EXPECT_EQ(info.height, 5);
  EXPECT_EQ(info.width, 7);
  for (int k = 0; k < 3; ++k) {
    const cv::Mat d = read_npy_frame(dir.path() / "depth.npy", k);
    EXPECT_EQ(cv::norm(d, m[size_t(k)], cv::NORM_INF), 0.0) << k;
  }
  EXPECT_THROW(read_npy_frame(dir.path() / "depth.npy", 3), Error);
}

TEST(NpyIo, BadFilesAreNamedWithTheirCause) {
  test::TempDir dir;
  write_npy_stack(dir.path() / "ok.npy", maps(2, 4, 4));
  std::string ok = slurp(dir.path() / "ok.npy");
  auto expect_error = [&](const std::string& content, const std::string& cause) {
    const fs::path p = dir.path() / "bad.npy";
    write_text_file(p, content);
    try {
      read_npy_stack_info(p);
      FAIL() << "no error for " << cause;
    } catch (const Error& e) {
      EXPECT_EQ(e.category(), ErrorCategory::format) << e.what();
      EXPECT_NE(std::string(e.what()).find(p.string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(cause), std::string::npos) << e.what();
    }
  };
  expect_error("not numpy at all", "bad magic");
  expect_error(ok.substr(0, ok.size() - 4), "truncated .npy data");
  std::string f8 = ok;
  f8.replace(f8.find("<f4"), 3, "<f8");
  expect_error(f8, "float32");
  std::string fortran = ok;
  fortran.replace(fortran.find("False"), 5, "True ");
  expect_error(fortran, "C order");
}

TEST(NpyIo, EvalReadsARunWrittenAsNpyOnly) {
  test::TempDir dir;
  const auto m = maps(2, 6, 8);
  write_npy_stack(dir.path() / "depth.npy", m);
  write_text_file(dir.path() / "frames.txt", "frame_a\nframe_b\n");
  const EvalSequence seq = read_cvd_run(dir.path(), "depth");
  ASSERT_EQ(seq.frames.size(), 2u);
  EXPECT_EQ(seq.frames[1].name, "frame_b");
  EXPECT_EQ(cv::norm(load_eval_depth(seq.frames[1]), m[1], cv::NORM_INF), 0.0);
  // frames.txt and the array must agree.
  write_text_file(dir.path() / "frames.txt", "frame_a\n");
  EXPECT_THROW(read_cvd_run(dir.path(), "depth"), Error);
}

}  // namespace
}  // namespace cvd
