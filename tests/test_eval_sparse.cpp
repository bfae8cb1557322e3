// sparse_depth.csv (a run's sparse SfM / triangulated points) and its metrics against GT depth,
// on hand-made inputs with known answers.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>

#include "engine/error.h"
#include "pipeline/eval/eval_sparse.h"
#include "test_support.h"

namespace cvd {
namespace {

namespace fs = std::filesystem;

std::string first_bytes(const fs::path& p, size_t n) {
  std::ifstream in(p, std::ios::binary);
  std::string s(n, '\0');
  in.read(s.data(), static_cast<std::streamsize>(n));
  s.resize(static_cast<size_t>(in.gcount()));
  return s;
}

// Written compressed (".gz", what a run writes) and plain (older runs' sparse_depth.csv); both read
// back the same, and no temporary is left beside them.
TEST(SparseDepthCsv, RoundTripsByFrameNameCompressedAndPlain) {
  for (const char* file : {"s.csv.gz", "s.csv"}) {
    SCOPED_TRACE(file);
    test::TempDir dir;
    std::map<std::string, SparseDepthFrame> in;
    in["frame-a"] = {4, 3, {{0.0, 0.0, 1.5}, {3.0, 2.0, 2.25}}};
    in["frame-b"] = {4, 3, {{1.25, 1.5, 0.125}}};
    in["frame-c"] = {4, 3, {}};  // no points: no lines
    write_sparse_depth_csv(dir / file, in);
    const std::string head = first_bytes(dir / file, 2);
    if (fs::path(file).extension() == ".gz") {
      EXPECT_EQ(head, "\x1f\x8b") << "not gzip";
    } else {
      EXPECT_EQ(head, "fr") << "not the plain header";
    }
    auto out = read_sparse_depth_csv(dir / file);
    ASSERT_EQ(out.size(), 2u);
    ASSERT_EQ(out["frame-a"].points.size(), 2u);
    EXPECT_EQ(out["frame-a"].width, 4);
    EXPECT_EQ(out["frame-a"].height, 3);
    EXPECT_DOUBLE_EQ(out["frame-a"].points[1].z, 2.25);
    EXPECT_DOUBLE_EQ(out["frame-b"].points[0].u, 1.25);
    EXPECT_DOUBLE_EQ(out["frame-b"].points[0].v, 1.5);
    EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1);
  }
}

// Frames streamed one at a time: many lines (past the writer's 1 MiB chunk) come back in order.
TEST(SparseDepthCsv, StreamsFramesLargerThanOneChunk) {
  test::TempDir dir;
  const size_t n = 40000;  // ~1.4 MB of lines
  std::vector<double> u(n), v(n), z(n);
  for (size_t i = 0; i < n; ++i) u[i] = double(i % 640), v[i] = double(i / 640), z[i] = 1.0 + i;
  write_sparse_depth_csv(dir / "big.csv.gz", [&](SparseDepthCsvWriter& w) {
    w.add_frame("f0", 640, 480, u.data(), v.data(), z.data(), n);
    w.add_frame("f1", 320, 240, u.data(), v.data(), z.data(), 3);
  });
  EXPECT_LT(fs::file_size(dir / "big.csv.gz"), 700000u) << "hardly compressed";
  auto out = read_sparse_depth_csv(dir / "big.csv.gz");
  ASSERT_EQ(out["f0"].points.size(), n);
  ASSERT_EQ(out["f1"].points.size(), 3u);
  EXPECT_EQ(out["f1"].width, 320);
  EXPECT_DOUBLE_EQ(out["f0"].points[n - 1].z, double(n));
  EXPECT_DOUBLE_EQ(out["f0"].points[12345].u, double(12345 % 640));
}

// A writer that throws part-way leaves neither the file nor a temporary.
TEST(SparseDepthCsv, FailedWriteLeavesNothing) {
  test::TempDir dir;
  const double x[] = {1.0};
  EXPECT_THROW(write_sparse_depth_csv(dir / "s.csv.gz",
                                      [&](SparseDepthCsvWriter& w) {
                                        w.add_frame("ok", 4, 3, x, x, x, 1);
                                        w.add_frame("a,b", 4, 3, x, x, x, 1);  // comma: rejected
                                      }),
               Error);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 0);
}

TEST(SparseDepthCsv, TruncatedCompressedFileIsAFormatError) {
  test::TempDir dir;
  std::map<std::string, SparseDepthFrame> in;
  for (int i = 0; i < 2000; ++i) in["f"].points.push_back({double(i % 4), 1.0, 1.0 + i});
  in["f"].width = 4, in["f"].height = 3;
  write_sparse_depth_csv(dir / "s.csv.gz", in);
  const auto size = fs::file_size(dir / "s.csv.gz");
  fs::resize_file(dir / "s.csv.gz", size / 2);
  try {
    read_sparse_depth_csv(dir / "s.csv.gz");
    ADD_FAILURE() << "a truncated file was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("s.csv.gz"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
}

void expect_rejected(const std::string& content, const std::string& fragment) {
  test::TempDir dir;
  std::ofstream(dir / "bad.csv") << content;
  try {
    read_sparse_depth_csv(dir / "bad.csv");
    ADD_FAILURE() << "accepted: " << content;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.csv"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(SparseDepthCsv, RejectsMalformedFilesNamingTheLine) {
  expect_rejected("", "empty file");
  expect_rejected("frame,u,v\n", "header");
  expect_rejected("frame,width,height,u,v,z\na,4,3,1,1\n", ":2:");
  expect_rejected("frame,width,height,u,v,z\na,4,3,1,1,-2\n", "z > 0");
  expect_rejected("frame,width,height,u,v,z\na,4,3,1,1,nan\n", ":2:");
  expect_rejected("frame,width,height,u,v,z\na,4,3,1,1,2\na,8,6,1,1,2\n", "changes size");
  expect_rejected("frame,width,height,u,v,z\na,4,3,1,1,2,7\n", ":2:");
}

TEST(SparseDepthEval, KnownAnswersPerFrameAndPerVideoScale) {
  // GT 8x6, 2 m everywhere except one invalid pixel; points given at 4x3, so (u, v) maps to
  // GT pixel (2u + 0.5, 2v + 0.5) rounded.
  cv::Mat gt(6, 8, CV_32FC1, cv::Scalar(2.0f));
  gt.at<float>(5, 7) = 0.0f;  // invalid: the point at (3, 2) lands here and is ignored
  std::map<std::string, SparseDepthFrame> s;
  // Frame a: ratios 2, 2, 2/1.1 -> per-frame scale 2 -> errors 0, 0, 0.1.
  s["a"] = {4, 3, {{0, 0, 1.0}, {1, 1, 1.0}, {2, 1, 1.1}, {3, 2, 9.0}}};
  // Frame b: ratios 4, 4 -> per-frame scale 4 -> errors 0.
  s["b"] = {4, 3, {{0, 2, 0.5}, {3, 0, 0.5}}};
  // Frame c has points but is not in the evaluated list.
  s["c"] = {4, 3, {{0, 0, 100.0}}};
  SparseDepthEval r = evaluate_sparse_depth(s, {"a", "b", "missing"}, {gt, gt, gt}, 1e-3, 0);
  EXPECT_EQ(r.frames, 2);
  EXPECT_EQ(r.points, 5);
  EXPECT_NEAR(r.abs_rel, (0.1 / 3 + 0.0) / 2, 1e-12);
  EXPECT_NEAR(r.density, (3.0 / 12 + 2.0 / 12) / 2, 1e-12);
  EXPECT_DOUBLE_EQ(r.delta1, 1.0);
  // One video scale: median of {2, 2, 1.818, 4, 4} = 2; frame b is then 50% off.
  EXPECT_NEAR(r.abs_rel_video, (0.1 / 3 + 0.5) / 2, 1e-12);
}

TEST(SparseDepthEval, DepthCapAndNoPointsGiveEmptyResult) {
  cv::Mat gt(3, 4, CV_32FC1, cv::Scalar(20.0f));
  std::map<std::string, SparseDepthFrame> s;
  s["a"] = {4, 3, {{1, 1, 1.0}}};
  SparseDepthEval capped = evaluate_sparse_depth(s, {"a"}, {gt}, 1e-3, 10.0);
  EXPECT_EQ(capped.frames, 0);
  EXPECT_EQ(capped.points, 0);
  SparseDepthEval none = evaluate_sparse_depth({}, {"a"}, {gt}, 1e-3, 0);
  EXPECT_EQ(none.frames, 0);
}

}  // namespace
}  // namespace cvd
