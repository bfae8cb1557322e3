// libFuzzer target: the COLMAP text model reader (pipeline/io/trajectory_io.cpp). One input holds
// the three files, separated by lines "@@images" and "@@points": cameras.txt first, then
// images.txt, then points3D.txt (absent when there is no "@@points" line).
#include <string>

#include "pipeline/io/trajectory_io.h"
#include "tests/fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string s(reinterpret_cast<const char*>(data), size);
  auto dir = cvd::fuzz::scratch_path("colmap");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  size_t im = s.find("@@images\n");
  size_t pt = s.find("@@points\n");
  std::string cameras = s.substr(0, std::min(im, pt));
  std::string images =
      im == std::string::npos ? "" : s.substr(im + 9, pt > im ? pt - im - 9 : std::string::npos);
  cvd::fuzz::write_bytes(dir / "cameras.txt", cameras);
  cvd::fuzz::write_bytes(dir / "images.txt", images);
  if (pt != std::string::npos) cvd::fuzz::write_bytes(dir / "points3D.txt", s.substr(pt + 9));
  cvd::fuzz::expect_only_cvd_errors([&] { cvd::read_colmap_text_model(dir); });
  return 0;
}
