// The `.cvdw` weights file: named tensors with a JSON header, loadable by mmap.
//
// Layout (all integers little-endian):
//   bytes 0..3    magic "CVDW"
//   bytes 4..7    u32 format version (kCvdwVersion)
//   bytes 8..15   u64 header length H
//   bytes 16..    H bytes of UTF-8 JSON (padded with spaces so that the data starts 64-aligned):
//     {"format": "cvdw", "model": "...", "config": {...},
//      "tensors": [{"name", "dtype": "f32"|"f64", "shape": [...], "offset", "nbytes",
//                   "crc32", "kind"?}, ...]}
//   then the tensor blobs: each contiguous, row-major, little-endian, starting at `offset`
//   (absolute, from the start of the file, a multiple of 64). `crc32` is zlib's CRC-32 of the
//   blob's bytes. `kind` is optional ("parameter", "buffer", "optimizer_state", ...).
//
// Every malformed file is an Error(format) that names the file and, where one is at fault, the
// tensor; an unreadable or unwritable file is an Error(io).
#pragma once
#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

inline constexpr uint32_t kCvdwVersion = 1;
inline constexpr uint64_t kCvdwAlignment = 64;

// One tensor to write.
struct CvdwTensor {
  std::string name;
  Tensor tensor;     // any device, dtype f32 / f64, any strides
  std::string kind;  // optional; empty = not recorded
};

// Writes `tensors` (names unique, non-empty) with the model name and config to `path`, through a
// temporary file in the same directory that is renamed over `path` once complete.
void write_cvdw(const std::filesystem::path& path, const std::string& model,
                const nlohmann::json& config, const std::vector<CvdwTensor>& tensors);

// One row of the tensor table.
struct CvdwEntry {
  std::string name;
  DType dtype = DType::f32;
  Shape shape;
  uint64_t offset = 0;
  uint64_t nbytes = 0;
  uint32_t crc32 = 0;
  std::string kind;
};

struct CvdwHeader {
  uint32_t version = kCvdwVersion;
  std::string model;
  nlohmann::json config = nlohmann::json::object();
  std::vector<CvdwEntry> tensors;  // in file order
  uint64_t data_start = 0;         // first byte after the header
  uint64_t file_size = 0;
};

struct CvdwReadOptions {
  bool use_mmap = true;    // tensors alias a private (copy-on-write) mapping of the file
  bool verify_crc = true;  // check each tensor's CRC when it is loaded
};

// An open .cvdw file. The constructor reads and validates the whole header (magic, version,
// header length, JSON, every entry's dtype / shape / size / alignment / range inside the file,
// unique names); tensors are read on demand. Tensors returned from an mmap'd reader keep the
// mapping alive after the reader is gone.
class CvdwReader {
 public:
  explicit CvdwReader(const std::filesystem::path& path, CvdwReadOptions options = {});
  ~CvdwReader();
  CvdwReader(const CvdwReader&) = delete;
  CvdwReader& operator=(const CvdwReader&) = delete;

  const std::filesystem::path& path() const { return path_; }
  const CvdwHeader& header() const { return header_; }
  bool contains(const std::string& name) const;
  const CvdwEntry& entry(const std::string& name) const;  // Error(invalid_argument) if absent

  // The tensor `name` on the CPU (CRC verified when options.verify_crc).
  Tensor tensor(const std::string& name) const;
  // All tensors in file order.
  std::vector<std::pair<std::string, Tensor>> tensors() const;
  // The CRC-32 of entry `i`'s bytes as stored now (for `cvd inspect`, which reports instead of
  // throwing).
  uint32_t computed_crc32(size_t i) const;

 private:
  struct Mapping;
  Tensor load(const CvdwEntry& e) const;
  const uint8_t* blob(const CvdwEntry& e) const;  // mmap only

  std::filesystem::path path_;
  CvdwReadOptions options_;
  CvdwHeader header_;
  std::shared_ptr<Mapping> mapping_;  // null when reading without mmap
  int fd_ = -1;                       // open while reading without mmap
};

// Convenience: the whole file, tensors in file order.
struct CvdwContents {
  CvdwHeader header;
  std::vector<std::pair<std::string, Tensor>> tensors;
};
CvdwContents read_cvdw(const std::filesystem::path& path, CvdwReadOptions options = {});

// zlib CRC-32 of `n` bytes.
uint32_t crc32_of(const void* data, size_t n);

}  // namespace cvd
