// `cvd view`: the page's data read back from a run folder (points in the world, cameras, the
// slider's frames, warnings), the HTML's escaping, the errors on a folder that is not a run, and
// the written page. The page in a real browser: tests/viewer/viewer_browser_test.sh (ctest
// viewer_browser).
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <opencv2/imgproc.hpp>

#include "engine/error.h"
#include "pipeline/eval/eval_report.h"
#include "pipeline/io/image_io.h"
#include "pipeline/run/run_outputs.h"
#include "test_support.h"
#include "tools/viewer/viewer_page.h"

namespace cvd {
namespace {
namespace fs = std::filesystem;

std::vector<unsigned char> base64_decode(const std::string& s) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    return c == '+' ? 62 : c == '/' ? 63 : -1;
  };
  std::vector<unsigned char> out;
  int bits = 0, acc = 0;
  for (char c : s) {
    int v = value(c);
    if (v < 0) continue;  // '=' padding
    acc = (acc << 6) | v;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(static_cast<unsigned char>((acc >> bits) & 0xff));
    }
  }
  return out;
}

// A finished-run folder as `cvd run` leaves it: `n` frames 32x24 looking down +z from x = k,
// depth 2 + 0.1 k everywhere, input frames in cache/frames/ (coloured by frame) unless told not.
void write_run(const fs::path& out, int n, bool with_frames = true) {
  RunOutputs r;
  for (int k = 0; k < n; ++k) {
    std::string name = fmt::format("frame_{:03d}", k);
    r.names.push_back(name);
    r.depths.push_back(cv::Mat(24, 32, CV_32F, cv::Scalar(2.0f + 0.1f * k)));
    r.frames_bgr.push_back(cv::Mat(24, 32, CV_8UC3, cv::Scalar(10, 20, 30 + k)));
    NamedCamera c;
    c.name = name;
    c.pose.t = Eigen::Vector3d(k, 0, 0);
    c.intrinsics = {30, 30, 16, 12, 32, 24};
    r.cameras.push_back(c);
  }
  write_depth_maps(out, r, {"pfm"});
  write_cameras(out, r);
  if (with_frames) {
    fs::create_directories(out / "cache" / "frames");
    for (int k = 0; k < n; ++k) {
      cv::Mat big;  // the cache holds frames above the depth resolution
      cv::resize(r.frames_bgr[k], big, cv::Size(64, 48), 0, 0, cv::INTER_NEAREST);
      write_image(out / "cache" / "frames" / (r.names[k] + ".png"), big);
    }
  }
}

TEST(ViewerData, PointsAreTheDepthMapsInTheWorld) {
  test::TempDir dir;
  write_run(dir.path(), 3);
  ViewerSummary s;
  nlohmann::json d = viewer_data(dir.path(), {}, s);
  // Every 2nd pixel of every frame: 16 x 12 x 3.
  ASSERT_EQ(s.points, 576u);
  EXPECT_EQ(d["points"]["count"].get<size_t>(), 576u);
  std::vector<unsigned char> pos = base64_decode(d["points"]["positions"].get<std::string>());
  std::vector<unsigned char> col = base64_decode(d["points"]["colors"].get<std::string>());
  ASSERT_EQ(pos.size(), 576u * 3 * sizeof(float));
  ASSERT_EQ(col.size(), 576u * 3);
  std::vector<float> xyz(576 * 3);
  std::memcpy(xyz.data(), pos.data(), pos.size());
  for (size_t i = 0; i < 576; ++i) {
    size_t k = i / 192;  // the frame of this point
    float z = xyz[3 * i + 2];
    EXPECT_NEAR(z, 2.0f + 0.1f * k, 1e-5) << "point " << i;
    // Inside frame k's view: |x - k| <= z * (16 / 30).
    EXPECT_LE(std::abs(xyz[3 * i] - float(k)), z * 16.0f / 30.0f + 1e-5f);
    EXPECT_EQ(col[3 * i], 30 + k) << "red of point " << i << " (frame colour, RGB order)";
    EXPECT_EQ(col[3 * i + 2], 10);
  }
  ASSERT_EQ(d["cameras"].size(), 3u);
  EXPECT_EQ(s.cameras, 3u);
  EXPECT_DOUBLE_EQ(d["cameras"][2]["c2w"][3].get<double>(), 2.0);  // t.x of frame 2
  EXPECT_DOUBLE_EQ(d["cameras"][0]["fx"].get<double>(), 30.0);
  ASSERT_EQ(d["frames"].size(), 3u);
  EXPECT_EQ(d["frames"][1]["name"], "frame_001");
  EXPECT_EQ(d["frames"][1]["image"].get<std::string>().rfind("data:image/jpeg;base64,", 0), 0u);
  // No run.json: a warning, no error.
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("run.json"), std::string::npos) << s.warnings[0];
}

TEST(ViewerData, CloudAndSliderAreCappedEvenly) {
  test::TempDir dir;
  write_run(dir.path(), 10);
  ViewerOptions o;
  o.max_points = 100;
  o.max_frames = 4;
  ViewerSummary s;
  nlohmann::json d = viewer_data(dir.path(), o, s);
  EXPECT_EQ(s.points, 100u);
  EXPECT_EQ(base64_decode(d["points"]["positions"].get<std::string>()).size(), 1200u);
  ASSERT_EQ(d["frames"].size(), 4u);
  std::vector<int> shown;
  for (auto& f : d["frames"]) shown.push_back(f["index"].get<int>());
  EXPECT_EQ(shown, (std::vector<int>{0, 3, 6, 9}));
  EXPECT_EQ(d["cameras"].size(), 10u) << "every camera is drawn, whatever the slider shows";
  bool said = false;
  for (auto& w : s.warnings) said |= w.find("4 of the 10 frames") != std::string::npos;
  EXPECT_TRUE(said);
}

TEST(ViewerData, MissingInputFramesAreAWarningNotAnError) {
  test::TempDir dir;
  write_run(dir.path(), 2, /*with_frames=*/false);
  ViewerSummary s;
  nlohmann::json d = viewer_data(dir.path(), {}, s);
  EXPECT_GT(s.points, 0u);
  std::vector<unsigned char> col = base64_decode(d["points"]["colors"].get<std::string>());
  EXPECT_EQ(col[0], 200) << "grey points without input frames";
  bool said = false;
  for (auto& w : s.warnings) said |= w.find("cache/frames") != std::string::npos;
  EXPECT_TRUE(said);
}

TEST(ViewerData, NotARunFolderIsOneErrorNamingTheFile) {
  test::TempDir dir;
  ViewerSummary s;
  try {
    viewer_data(dir.path(), {}, s);
    FAIL() << "an empty folder is not a run";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::format);
    EXPECT_NE(std::string(e.what()).find(dir.path().string()), std::string::npos) << e.what();
  }
  write_run(dir.path(), 2);
  fs::remove(dir / "intrinsics.json");
  try {
    viewer_data(dir.path(), {}, s);
    FAIL() << "a run without intrinsics.json";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("intrinsics.json"), std::string::npos) << e.what();
  }
  EXPECT_THROW(viewer_data(fs::path(dir.path()) / "absent", {}, s), Error);
}

TEST(ViewerHtml, DataCannotEndItsScriptElement) {
  nlohmann::json data = {{"title", "a </script><b>x</b> name"}};
  std::string html = viewer_html(data, "console.log(1)");
  EXPECT_EQ(html.find("</script><b>"), std::string::npos);
  EXPECT_NE(html.find("<\\/script><b>x<\\/b>"), std::string::npos);
  // Exactly the two script elements the page has.
  size_t n = 0;
  for (size_t p = html.find("</script>"); p != std::string::npos; p = html.find("</script>", p + 1))
    ++n;
  EXPECT_EQ(n, 2u);
}

TEST(WriteViewer, OnePageWithTheBundledScript) {
  EXPECT_EQ(viewer_available(), CVD_VIEWER_BUNDLED != 0)
      << "the build's CMake said the viewer script was " << (CVD_VIEWER_BUNDLED ? "" : "not ")
      << "bundled";
  test::TempDir dir;
  write_run(dir.path(), 3);
  if (!viewer_available()) {
    try {
      write_viewer(dir.path());
      FAIL() << "no script, no page";
    } catch (const Error& e) {
      EXPECT_EQ(e.category(), ErrorCategory::unsupported);
    }
    EXPECT_FALSE(fs::exists(dir / "viewer.html"));
    GTEST_SKIP() << "this build has no viewer script (node / npm packages absent at configure)";
  }
  ViewerSummary s = write_viewer(dir.path());
  EXPECT_EQ(s.file, dir / "viewer.html");
  ASSERT_TRUE(fs::exists(s.file));
  EXPECT_EQ(fs::file_size(s.file), s.bytes);
  std::ifstream in(s.file);
  std::string html((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(html.find("id=\"cvd-data\""), std::string::npos);
  EXPECT_NE(html.find("Three.js Authors"), std::string::npos) << "three.js and its licence inlined";
  EXPECT_EQ(html.find("src=\"http"), std::string::npos) << "nothing loaded from the network";
  for (auto& e : fs::directory_iterator(dir.path()))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos)
        << "temporary file left: " << e.path();
}

}  // namespace
}  // namespace cvd
