#include "pipeline/io/pfm_io.h"

#include <bit>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "engine/error.h"
#include "pipeline/io/atomic_file.h"

namespace cvd {

static_assert(std::endian::native == std::endian::little, "PFM IO assumes a little-endian host");

namespace {

struct PfmHeader {
  int channels = 0;
  long width = 0, height = 0;
  bool big_endian = false;
};

[[noreturn]] void bad_header(const std::filesystem::path& path, const std::string& why) {
  fail(ErrorCategory::format, "PFM file '{}' has a bad header: {}", path.string(), why);
}

void skip_whitespace(const std::vector<char>& bytes, size_t& pos) {
  while (pos < bytes.size() && std::isspace(static_cast<unsigned char>(bytes[pos]))) ++pos;
}

std::string next_token(const std::vector<char>& bytes, size_t& pos) {
  skip_whitespace(bytes, pos);
  std::string token;
  while (pos < bytes.size() && !std::isspace(static_cast<unsigned char>(bytes[pos])) &&
         token.size() < 64)
    token.push_back(bytes[pos++]);
  return token;
}

long parse_dimension(const std::filesystem::path& path, const std::string& token,
                     const char* what) {
  if (token.empty() || token.size() > 9 ||
      token.find_first_not_of("0123456789") != std::string::npos)
    bad_header(path, fmt::format("{} '{}' is not a positive integer", what, token));
  const long v = std::stol(token);
  if (v <= 0 || v > kPfmMaxDimension)
    bad_header(path, fmt::format("{} {} is outside 1..{}", what, v, kPfmMaxDimension));
  return v;
}

// Parses the magic and the three header fields; on success `pos` points at the first data byte.
PfmHeader parse_header(const std::filesystem::path& path, const std::vector<char>& bytes,
                       size_t& pos) {
  PfmHeader h;
  if (bytes.size() < 2 || bytes[0] != 'P' || (bytes[1] != 'F' && bytes[1] != 'f'))
    bad_header(path, "it does not start with the magic 'PF' or 'Pf' (not a PFM file)");
  h.channels = bytes[1] == 'F' ? 3 : 1;
  pos = 2;
  if (pos >= bytes.size() || !std::isspace(static_cast<unsigned char>(bytes[pos])))
    bad_header(path, "no whitespace after the magic");
  h.width = parse_dimension(path, next_token(bytes, pos), "width");
  h.height = parse_dimension(path, next_token(bytes, pos), "height");
  const std::string scale_token = next_token(bytes, pos);
  double scale = 0;
  try {
    size_t used = 0;
    scale = std::stod(scale_token, &used);
    if (used != scale_token.size()) throw std::invalid_argument("trailing characters");
  } catch (const std::exception&) {
    bad_header(path, fmt::format("scale '{}' is not a number", scale_token));
  }
  if (!std::isfinite(scale) || scale == 0)
    bad_header(path, fmt::format("scale '{}' must be finite and non-zero", scale_token));
  h.big_endian = scale > 0;
  // Exactly one whitespace byte separates the scale from the data.
  if (pos >= bytes.size() || !std::isspace(static_cast<unsigned char>(bytes[pos])))
    bad_header(path, "the header does not end with a newline after the scale");
  ++pos;
  return h;
}

}  // namespace

cv::Mat read_pfm(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(ErrorCategory::io, "cannot open PFM file '{}' for reading", path.string());
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) fail(ErrorCategory::io, "cannot read PFM file '{}'", path.string());

  size_t pos = 0;
  const PfmHeader h = parse_header(path, bytes, pos);
  const size_t row_floats = size_t(h.width) * size_t(h.channels);
  const size_t expected = size_t(h.height) * row_floats * sizeof(float);
  const size_t available = bytes.size() - pos;
  if (available < expected)
    fail(ErrorCategory::format,
         "PFM file '{}' is truncated: {} data bytes for {}x{}x{} float32, expected {}",
         path.string(), available, h.width, h.height, h.channels, expected);
  if (available > expected)
    fail(ErrorCategory::format,
         "PFM file '{}' has a size mismatch: {} data bytes for {}x{}x{} float32, expected {}",
         path.string(), available, h.width, h.height, h.channels, expected);

  cv::Mat image(int(h.height), int(h.width), h.channels == 3 ? CV_32FC3 : CV_32FC1);
  for (int y = 0; y < image.rows; ++y) {
    // The file stores the bottom row first.
    const char* src = bytes.data() + pos + size_t(image.rows - 1 - y) * row_floats * sizeof(float);
    auto* dst = image.ptr<float>(y);
    std::memcpy(dst, src, row_floats * sizeof(float));
    if (h.big_endian) {
      for (size_t i = 0; i < row_floats; ++i) {
        std::uint32_t u;
        std::memcpy(&u, dst + i, 4);
        u = __builtin_bswap32(u);
        std::memcpy(dst + i, &u, 4);
      }
    }
    if (h.channels == 3)
      for (size_t x = 0; x < size_t(h.width); ++x) std::swap(dst[3 * x], dst[3 * x + 2]);
  }
  return image;
}

void write_pfm(const std::filesystem::path& path, const cv::Mat& image) {
  CVD_CHECK(image.type() == CV_32FC1 || image.type() == CV_32FC3,
            "write_pfm('{}'): image must be CV_32FC1 or CV_32FC3, got type {}", path.string(),
            image.type());
  CVD_CHECK(!image.empty(), "write_pfm('{}'): image is empty", path.string());
  const int channels = image.channels();
  write_atomically(path, [&](const std::filesystem::path& tmp) {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out)
      fail(ErrorCategory::io, "cannot open '{}' for writing PFM file '{}'", tmp.string(),
           path.string());
    const std::string header =
        fmt::format("{}\n{} {}\n-1\n", channels == 3 ? "PF" : "Pf", image.cols, image.rows);
    out.write(header.data(), std::streamsize(header.size()));
    std::vector<float> row(size_t(image.cols) * channels);
    for (int y = image.rows - 1; y >= 0; --y) {
      std::memcpy(row.data(), image.ptr<float>(y), row.size() * sizeof(float));
      if (channels == 3)
        for (size_t x = 0; x < size_t(image.cols); ++x) std::swap(row[3 * x], row[3 * x + 2]);
      out.write(reinterpret_cast<const char*>(row.data()),
                std::streamsize(row.size() * sizeof(float)));
    }
    out.close();
    if (!out)
      fail(ErrorCategory::io, "writing PFM file '{}' failed (disk full or no permission?)",
           path.string());
  });
}

}  // namespace cvd
