#include "pipeline/poses/exif_focal.h"

#include <cmath>
#include <fstream>
#include <vector>

namespace cvd {
namespace {

// A bounds-checked view of the TIFF structure inside the APP1 segment.
class TiffView {
 public:
  TiffView(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  bool init() {
    if (size_ < 8) return false;
    if (data_[0] == 'I' && data_[1] == 'I')
      little_ = true;
    else if (data_[0] == 'M' && data_[1] == 'M')
      little_ = false;
    else
      return false;
    uint16_t magic = 0;
    return u16(2, magic) && magic == 42;
  }
  bool u16(size_t at, uint16_t& v) const {
    if (at > size_ || size_ - at < 2) return false;
    v = little_ ? uint16_t(data_[at] | data_[at + 1] << 8)
                : uint16_t(data_[at] << 8 | data_[at + 1]);
    return true;
  }
  bool u32(size_t at, uint32_t& v) const {
    if (at > size_ || size_ - at < 4) return false;
    const uint8_t* p = data_ + at;
    v = little_
            ? uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24
            : uint32_t(p[3]) | uint32_t(p[2]) << 8 | uint32_t(p[1]) << 16 | uint32_t(p[0]) << 24;
    return true;
  }
  // The entry of `tag` in the IFD at `ifd`: its type, count and the offset of its 4-byte value
  // field. False when absent or out of bounds.
  bool find(uint32_t ifd, uint16_t tag, uint16_t& type, uint32_t& count, size_t& value_at) const {
    uint16_t n = 0;
    if (!u16(ifd, n)) return false;
    for (uint32_t i = 0; i < n; ++i) {
      size_t e = size_t(ifd) + 2 + 12 * size_t(i);
      uint16_t t = 0;
      if (!u16(e, t) || !u16(e + 2, type) || !u32(e + 4, count)) return false;
      if (t == tag) {
        value_at = e + 8;
        return value_at + 4 <= size_;
      }
    }
    return false;
  }

 private:
  const uint8_t* data_;
  size_t size_;
  bool little_ = true;
};

std::optional<double> focal_from_tiff(const uint8_t* data, size_t size) {
  TiffView tiff(data, size);
  if (!tiff.init()) return std::nullopt;
  uint32_t ifd0 = 0;
  if (!tiff.u32(4, ifd0)) return std::nullopt;
  uint16_t type = 0;
  uint32_t count = 0;
  size_t at = 0;
  if (!tiff.find(ifd0, 0x8769, type, count, at)) return std::nullopt;  // Exif sub-IFD pointer
  uint32_t exif_ifd = 0;
  if (!tiff.u32(at, exif_ifd) || exif_ifd == ifd0) return std::nullopt;
  if (!tiff.find(exif_ifd, 0xA405, type, count, at) || count < 1) return std::nullopt;
  double value = 0;
  if (type == 3) {  // SHORT, as the standard says
    uint16_t v = 0;
    if (!tiff.u16(at, v)) return std::nullopt;
    value = v;
  } else if (type == 4) {  // LONG, written by some tools
    uint32_t v = 0;
    if (!tiff.u32(at, v)) return std::nullopt;
    value = v;
  } else {
    return std::nullopt;
  }
  if (!(value > 0) || value > 10000) return std::nullopt;  // 0 = unknown
  return value;
}

}  // namespace

std::optional<double> parse_exif_focal_35mm(const uint8_t* data, size_t size) {
  if (!data || size < 4 || data[0] != 0xFF || data[1] != 0xD8) return std::nullopt;
  size_t pos = 2;
  while (pos + 4 <= size) {
    if (data[pos] != 0xFF) return std::nullopt;
    uint8_t marker = data[pos + 1];
    if (marker == 0xFF) {  // fill byte
      ++pos;
      continue;
    }
    if (marker == 0xD9 || marker == 0xDA) return std::nullopt;   // end of image / start of scan
    size_t length = size_t(data[pos + 2]) << 8 | data[pos + 3];  // includes the 2 length bytes
    if (length < 2 || length > size - pos - 2) return std::nullopt;
    const uint8_t* seg = data + pos + 4;
    size_t seg_size = length - 2;
    static const uint8_t kExif[6] = {'E', 'x', 'i', 'f', 0, 0};
    if (marker == 0xE1 && seg_size > 6 && std::equal(kExif, kExif + 6, seg)) {
      if (auto f = focal_from_tiff(seg + 6, seg_size - 6)) return f;
    }
    pos += 2 + length;
  }
  return std::nullopt;
}

std::optional<double> read_exif_focal_35mm(const std::filesystem::path& jpeg) {
  std::ifstream in(jpeg, std::ios::binary);
  if (!in) return std::nullopt;
  std::vector<uint8_t> bytes(256 * 1024);
  in.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size()));
  bytes.resize(size_t(in.gcount()));
  return parse_exif_focal_35mm(bytes.data(), bytes.size());
}

double focal_px_from_35mm(double focal_35mm, int width, int height) {
  return focal_35mm * std::hypot(double(width), double(height)) / std::hypot(36.0, 24.0);
}

}  // namespace cvd
