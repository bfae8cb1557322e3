#include "pipeline/io/flow_io.h"

#include <bit>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <vector>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"

namespace cvd {

static_assert(std::endian::native == std::endian::little, ".flo IO assumes a little-endian host");

namespace {

constexpr std::uintmax_t kFloHeaderBytes = 12;

}  // namespace

cv::Mat read_flo(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(ErrorCategory::io, "cannot open flow file '{}' for reading", path.string());
  std::error_code ec;
  const std::uintmax_t file_bytes = std::filesystem::file_size(path, ec);
  if (ec)
    fail(ErrorCategory::io, "cannot get the size of flow file '{}': {}", path.string(),
         ec.message());
  if (file_bytes < kFloHeaderBytes)
    fail(ErrorCategory::format,
         "flow file '{}' is truncated: {} bytes, shorter than the 12-byte header", path.string(),
         file_bytes);

  char header[kFloHeaderBytes];
  if (!in.read(header, sizeof header))
    fail(ErrorCategory::io, "cannot read the header of flow file '{}'", path.string());
  float magic;
  std::int32_t width, height;
  std::memcpy(&magic, header, 4);
  std::memcpy(&width, header + 4, 4);
  std::memcpy(&height, header + 8, 4);
  if (magic != kFloMagic)
    fail(ErrorCategory::format, "'{}' is not a .flo file: magic {} instead of {}", path.string(),
         magic, kFloMagic);
  if (width <= 0 || height <= 0 || width > kFloMaxDimension || height > kFloMaxDimension)
    fail(ErrorCategory::format, "flow file '{}' has an implausible size {}x{} (allowed 1..{})",
         path.string(), width, height, kFloMaxDimension);

  const std::uintmax_t payload = std::uintmax_t(width) * std::uintmax_t(height) * 8;
  if (file_bytes != kFloHeaderBytes + payload)
    fail(ErrorCategory::format, "flow file '{}' is {}: {} bytes for {}x{}, expected {}",
         path.string(),
         file_bytes < kFloHeaderBytes + payload ? "truncated" : "longer than its header says",
         file_bytes, width, height, kFloHeaderBytes + payload);

  cv::Mat flow(height, width, CV_32FC2);
  for (int y = 0; y < height; ++y) {
    if (!in.read(reinterpret_cast<char*>(flow.ptr<cv::Vec2f>(y)), std::streamsize(width) * 8))
      fail(ErrorCategory::format, "flow file '{}' is truncated at row {} of {}", path.string(), y,
           height);
  }
  return flow;
}

void write_flo(const std::filesystem::path& path, const cv::Mat& flow) {
  CVD_CHECK(flow.type() == CV_32FC2, "write_flo('{}'): flow must be CV_32FC2, got type {}",
            path.string(), flow.type());
  CVD_CHECK(!flow.empty(), "write_flo('{}'): flow is empty", path.string());
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out)
      fail(ErrorCategory::io, "cannot open '{}' for writing flow '{}'", tmp.string(),
           path.string());
    const float magic = kFloMagic;
    const std::int32_t width = flow.cols, height = flow.rows;
    out.write(reinterpret_cast<const char*>(&magic), 4);
    out.write(reinterpret_cast<const char*>(&width), 4);
    out.write(reinterpret_cast<const char*>(&height), 4);
    for (int y = 0; y < flow.rows; ++y)
      out.write(reinterpret_cast<const char*>(flow.ptr<cv::Vec2f>(y)), std::streamsize(width) * 8);
    out.close();
    if (!out)
      fail(ErrorCategory::io, "writing flow file '{}' failed (disk full or no permission?)",
           path.string());
  });
}

}  // namespace cvd
