#include "pipeline/io/npy_io.h"

#include <fmt/format.h>

#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"

namespace cvd {

namespace fs = std::filesystem;

namespace {
constexpr char kMagic[] = "\x93NUMPY";
}  // namespace

void write_npy_stack(const fs::path& file, const std::vector<cv::Mat>& maps) {
  CVD_CHECK(!maps.empty(), "{}: no depth maps to write", file.string());
  const int h = maps[0].rows, w = maps[0].cols;
  for (const cv::Mat& m : maps)
    CVD_CHECK(m.type() == CV_32F && m.rows == h && m.cols == w,
              "{}: every map must be CV_32F of {}x{}", file.string(), w, h);
  std::string header = fmt::format(
      "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}", maps.size(), h, w);
  // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of 64
  // and ended by a newline.
  const size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  write_atomically(file, [&](const fs::path& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    out.write(kMagic, 6);
    const char version[2] = {1, 0};
    out.write(version, 2);
    const uint16_t len = static_cast<uint16_t>(header.size());
    const char len_le[2] = {static_cast<char>(len & 0xff), static_cast<char>(len >> 8)};
    out.write(len_le, 2);
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    for (const cv::Mat& m : maps) {
      const cv::Mat c = m.isContinuous() ? m : m.clone();
      out.write(reinterpret_cast<const char*>(c.ptr<float>()),
                static_cast<std::streamsize>(sizeof(float) * size_t(h) * size_t(w)));
    }
    out.flush();
    if (!out)
      fail(ErrorCategory::io, "writing {} failed (disk full or no permission?)", file.string());
  });
}

NpyStackInfo read_npy_stack_info(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) fail(ErrorCategory::io, "{}: cannot open", file.string());
  char pre[10];
  if (!in.read(pre, 10) || std::memcmp(pre, kMagic, 6) != 0)
    fail(ErrorCategory::format, "{}: not a NumPy .npy file (bad magic)", file.string());
  if (pre[6] != 1)
    fail(ErrorCategory::format, "{}: .npy format version {}.{} (only 1.0 is read)", file.string(),
         int(pre[6]), int(pre[7]));
  const size_t len = size_t(uint8_t(pre[8])) | (size_t(uint8_t(pre[9])) << 8);
  std::string header(len, '\0');
  if (!in.read(header.data(), static_cast<std::streamsize>(len)))
    fail(ErrorCategory::format, "{}: truncated .npy header", file.string());
  if (header.find("'descr': '<f4'") == std::string::npos)
    fail(ErrorCategory::format, "{}: .npy dtype must be little-endian float32 ('<f4')",
         file.string());
  if (header.find("'fortran_order': False") == std::string::npos)
    fail(ErrorCategory::format, "{}: .npy array must be in C order", file.string());
  // 'shape': (N, H, W) — parsed by hand (three non-negative integers).
  NpyStackInfo info;
  {
    const size_t key = header.find("'shape':");
    const size_t open = key == std::string::npos ? key : header.find('(', key);
    const size_t close = open == std::string::npos ? open : header.find(')', open);
    std::vector<int64_t> dims;
    if (close != std::string::npos) {
      int64_t v = -1;
      for (size_t k = open + 1; k <= close; ++k) {
        const char c = header[k];
        if (c >= '0' && c <= '9') {
          if (v > (int64_t(1) << 40)) v = int64_t(1) << 41;  // out of range either way
          v = (v < 0 ? 0 : v * 10) + (c - '0');
        } else if (c == ',' || c == ')') {
          if (v >= 0) dims.push_back(v);
          v = -1;
        } else if (c != ' ') {
          dims.clear();
          break;
        }
      }
    }
    if (dims.size() != 3)
      fail(ErrorCategory::format, "{}: .npy array must have shape (frames, height, width)",
           file.string());
    info.frames = dims[0];
    info.height = dims[1];
    info.width = dims[2];
  }
  if (info.frames > (int64_t(1) << 31))
    fail(ErrorCategory::format, "{}: .npy frame count {} out of range", file.string(), info.frames);
  if (info.height <= 0 || info.width <= 0 || info.height > 65536 || info.width > 65536)
    fail(ErrorCategory::format, "{}: .npy frame size {}x{} out of range", file.string(), info.width,
         info.height);
  info.data_offset = 10 + len;
  std::error_code ec;
  const uintmax_t size = fs::file_size(file, ec);
  const uintmax_t need = info.data_offset + uintmax_t(info.frames) * uintmax_t(info.height) *
                                                uintmax_t(info.width) * sizeof(float);
  if (ec || size < need)
    fail(ErrorCategory::format, "{}: truncated .npy data ({} bytes, the shape needs {})",
         file.string(), size, need);
  return info;
}

cv::Mat read_npy_frame(const fs::path& file, int64_t index) {
  const NpyStackInfo info = read_npy_stack_info(file);
  if (index < 0 || index >= info.frames)
    fail(ErrorCategory::format, "{}: frame {} requested, the array holds {}", file.string(), index,
         info.frames);
  cv::Mat d(static_cast<int>(info.height), static_cast<int>(info.width), CV_32F);
  std::ifstream in(file, std::ios::binary);
  const size_t bytes = sizeof(float) * size_t(info.height) * size_t(info.width);
  in.seekg(static_cast<std::streamoff>(info.data_offset + bytes * size_t(index)));
  if (!in.read(reinterpret_cast<char*>(d.ptr<float>()), static_cast<std::streamsize>(bytes)))
    fail(ErrorCategory::io, "{}: cannot read frame {}", file.string(), index);
  return d;
}

}  // namespace cvd
