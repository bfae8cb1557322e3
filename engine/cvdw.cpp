#include "engine/cvdw.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <set>

#include "engine/autograd.h"

namespace cvd {

static_assert(std::endian::native == std::endian::little,
              ".cvdw blobs are little-endian; big-endian hosts are not supported");

namespace {

constexpr char kMagic[4] = {'C', 'V', 'D', 'W'};
constexpr uint64_t kPreambleBytes = 16;  // magic + version + header length

uint64_t align_up(uint64_t x) { return (x + kCvdwAlignment - 1) / kCvdwAlignment * kCvdwAlignment; }

std::string errno_text() { return std::strerror(errno); }

// Writes all of `n` bytes or throws Error(io).
void write_all(int fd, const void* data, size_t n, const std::filesystem::path& path) {
  const char* p = static_cast<const char*>(data);
  while (n > 0) {
    ssize_t w = ::write(fd, p, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      fail(ErrorCategory::io, "{}: write failed: {}", path.string(), errno_text());
    }
    p += w;
    n -= static_cast<size_t>(w);
  }
}

// Reads exactly `n` bytes at `offset` or throws.
void read_all(int fd, void* data, size_t n, uint64_t offset, const std::filesystem::path& path) {
  char* p = static_cast<char*>(data);
  while (n > 0) {
    ssize_t r = ::pread(fd, p, n, static_cast<off_t>(offset));
    if (r < 0) {
      if (errno == EINTR) continue;
      fail(ErrorCategory::io, "{}: read failed: {}", path.string(), errno_text());
    }
    if (r == 0)
      fail(ErrorCategory::format, "{}: unexpected end of file (truncated)", path.string());
    p += r;
    n -= static_cast<size_t>(r);
    offset += static_cast<uint64_t>(r);
  }
}

std::string printable_magic(const char* m) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    unsigned char c = static_cast<unsigned char>(m[i]);
    if (c >= 32 && c < 127) {
      s += static_cast<char>(c);
    } else {
      s += fmt::format("\\x{:02x}", c);
    }
  }
  return s;
}

// The dtype named `s`, or throws for tensor `name` of `path`.
DType parse_dtype(const std::string& s, const std::string& name,
                  const std::filesystem::path& path) {
  if (s == "f32") return DType::f32;
  if (s == "f64") return DType::f64;
  fail(ErrorCategory::format, "{}: tensor '{}': unknown dtype '{}' (expected f32 or f64)",
       path.string(), name, s);
}

// Reads a non-negative integer field of a tensor entry.
uint64_t entry_uint(const nlohmann::json& e, const char* field, const std::string& name,
                    const std::filesystem::path& path) {
  auto it = e.find(field);
  if (it == e.end() || !it->is_number_unsigned()) {
    if (it != e.end() && it->is_number_integer() && it->get<int64_t>() >= 0) {
      return it->get<uint64_t>();
    }
    fail(ErrorCategory::format, "{}: tensor '{}': field '{}' missing or not a non-negative integer",
         path.string(), name, field);
  }
  return it->get<uint64_t>();
}

CvdwEntry parse_entry(const nlohmann::json& e, size_t index, const std::filesystem::path& path) {
  if (!e.is_object()) {
    fail(ErrorCategory::format, "{}: tensor table entry {} is not a JSON object", path.string(),
         index);
  }
  CvdwEntry out;
  auto name_it = e.find("name");
  if (name_it == e.end() || !name_it->is_string() || name_it->get<std::string>().empty()) {
    fail(ErrorCategory::format, "{}: tensor table entry {} has no name", path.string(), index);
  }
  out.name = name_it->get<std::string>();
  const std::string& name = out.name;
  auto dt = e.find("dtype");
  if (dt == e.end() || !dt->is_string()) {
    fail(ErrorCategory::format, "{}: tensor '{}': field 'dtype' missing", path.string(), name);
  }
  out.dtype = parse_dtype(dt->get<std::string>(), name, path);
  auto sh = e.find("shape");
  if (sh == e.end() || !sh->is_array()) {
    fail(ErrorCategory::format, "{}: tensor '{}': field 'shape' missing or not an array",
         path.string(), name);
  }
  if (sh->size() > static_cast<size_t>(kMaxDims)) {
    fail(ErrorCategory::format, "{}: tensor '{}': {} dimensions (at most {} supported)",
         path.string(), name, sh->size(), kMaxDims);
  }
  uint64_t numel = 1;
  for (const auto& d : *sh) {
    if (!d.is_number_integer() || d.get<int64_t>() < 0) {
      fail(ErrorCategory::format, "{}: tensor '{}': shape {} has a negative or non-integer size",
           path.string(), name, sh->dump());
    }
    uint64_t v = d.get<uint64_t>();
    if (v != 0 && numel > UINT64_MAX / v) {
      fail(ErrorCategory::format, "{}: tensor '{}': shape {} overflows", path.string(), name,
           sh->dump());
    }
    numel *= v;
    out.shape.push_back(static_cast<int64_t>(v));
  }
  out.offset = entry_uint(e, "offset", name, path);
  out.nbytes = entry_uint(e, "nbytes", name, path);
  uint64_t crc = entry_uint(e, "crc32", name, path);
  if (crc > 0xffffffffull) {
    fail(ErrorCategory::format, "{}: tensor '{}': crc32 {} does not fit 32 bits", path.string(),
         name, crc);
  }
  out.crc32 = static_cast<uint32_t>(crc);
  if (numel > UINT64_MAX / dtype_size(out.dtype) || numel * dtype_size(out.dtype) != out.nbytes) {
    fail(ErrorCategory::format, "{}: tensor '{}': nbytes {} does not match {} {} ({} bytes)",
         path.string(), name, out.nbytes, dtype_name(out.dtype), shape_str(out.shape),
         numel * dtype_size(out.dtype));
  }
  if (auto k = e.find("kind"); k != e.end()) {
    if (!k->is_string()) {
      fail(ErrorCategory::format, "{}: tensor '{}': field 'kind' is not a string", path.string(),
           name);
    }
    out.kind = k->get<std::string>();
  }
  return out;
}

}  // namespace

uint32_t crc32_of(const void* data, size_t n) {
  uLong crc = ::crc32_z(0L, Z_NULL, 0);
  if (n > 0) crc = ::crc32_z(crc, static_cast<const Bytef*>(data), n);
  return static_cast<uint32_t>(crc);
}

// ---- Writer -------------------------------------------------------------------------------------

void write_cvdw(const std::filesystem::path& path, const std::string& model,
                const nlohmann::json& config, const std::vector<CvdwTensor>& tensors) {
  CVD_CHECK(config.is_object() || config.is_null(), "{}: config must be a JSON object, got {}",
            path.string(), config.type_name());
  std::set<std::string> names;
  std::vector<Tensor> blobs;
  blobs.reserve(tensors.size());
  {
    NoGradGuard no_grad;
    for (const auto& t : tensors) {
      CVD_CHECK(!t.name.empty(), "{}: a tensor has an empty name", path.string());
      CVD_CHECK(names.insert(t.name).second, "{}: tensor name '{}' appears twice", path.string(),
                t.name);
      CVD_CHECK(t.tensor.defined(), "{}: tensor '{}' is undefined", path.string(), t.name);
      Tensor b = t.tensor.detach();
      if (!b.device().is_cpu()) b = b.to(DeviceId::cpu());
      blobs.push_back(b.contiguous());
    }
  }
  std::vector<uint32_t> crcs(blobs.size());
  for (size_t i = 0; i < blobs.size(); ++i)
    crcs[i] = crc32_of(blobs[i].data_ptr(), blobs[i].nbytes());

  // Offsets are absolute, so the header's length depends on them: grow the data start until the
  // header fits in front of it, then pad the header with spaces (valid trailing JSON whitespace).
  std::vector<uint64_t> offsets(blobs.size());
  std::string header;
  uint64_t data_start = kCvdwAlignment;
  for (;;) {
    uint64_t off = data_start;
    nlohmann::json table = nlohmann::json::array();
    for (size_t i = 0; i < blobs.size(); ++i) {
      offsets[i] = off;
      nlohmann::json e = {{"name", tensors[i].name},
                          {"dtype", dtype_name(blobs[i].dtype())},
                          {"shape", blobs[i].shape()},
                          {"offset", off},
                          {"nbytes", static_cast<uint64_t>(blobs[i].nbytes())},
                          {"crc32", crcs[i]}};
      if (!tensors[i].kind.empty()) e["kind"] = tensors[i].kind;
      table.push_back(std::move(e));
      off = align_up(off + blobs[i].nbytes());
    }
    nlohmann::json h = {{"format", "cvdw"},
                        {"model", model},
                        {"config", config.is_null() ? nlohmann::json::object() : config},
                        {"tensors", std::move(table)}};
    header = h.dump();
    uint64_t need = align_up(kPreambleBytes + header.size());
    if (need <= data_start) break;
    data_start = need;
  }
  header.resize(data_start - kPreambleBytes, ' ');

  std::filesystem::path dir = path.parent_path().empty() ? "." : path.parent_path();
  std::string tmpl = (dir / (path.filename().string() + ".tmp-XXXXXX")).string();
  int fd = ::mkstemp(tmpl.data());
  if (fd < 0) {
    fail(ErrorCategory::io, "{}: cannot create a temporary file in {}: {}", path.string(),
         dir.string(), errno_text());
  }
  try {
    ::fchmod(fd, 0644);
    char pre[kPreambleBytes];
    std::memcpy(pre, kMagic, 4);
    uint32_t version = kCvdwVersion;
    uint64_t hlen = header.size();
    std::memcpy(pre + 4, &version, 4);
    std::memcpy(pre + 8, &hlen, 8);
    write_all(fd, pre, sizeof pre, path);
    write_all(fd, header.data(), header.size(), path);
    uint64_t pos = data_start;
    static const char zeros[kCvdwAlignment] = {};
    for (size_t i = 0; i < blobs.size(); ++i) {
      CVD_ASSERT(offsets[i] >= pos && offsets[i] - pos < kCvdwAlignment);
      write_all(fd, zeros, offsets[i] - pos, path);
      write_all(fd, blobs[i].data_ptr(), blobs[i].nbytes(), path);
      pos = offsets[i] + blobs[i].nbytes();
    }
    if (::fsync(fd) != 0)
      fail(ErrorCategory::io, "{}: fsync failed: {}", path.string(), errno_text());
    if (::close(fd) != 0) {
      fd = -1;
      fail(ErrorCategory::io, "{}: close failed: {}", path.string(), errno_text());
    }
    fd = -1;
    std::error_code ec;
    std::filesystem::rename(tmpl, path, ec);
    if (ec)
      fail(ErrorCategory::io, "{}: cannot rename {} into place: {}", path.string(), tmpl,
           ec.message());
  } catch (...) {
    if (fd >= 0) ::close(fd);
    ::unlink(tmpl.c_str());
    throw;
  }
}

// ---- Reader -------------------------------------------------------------------------------------

struct CvdwReader::Mapping {
  void* base = nullptr;
  size_t size = 0;
  ~Mapping() {
    if (base) ::munmap(base, size);
  }
};

CvdwReader::CvdwReader(const std::filesystem::path& path, CvdwReadOptions options)
    : path_(path), options_(options) {
  const std::string file = path.string();
  fd_ = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) fail(ErrorCategory::io, "{}: cannot open: {}", file, errno_text());
  try {
    struct stat st {};
    if (::fstat(fd_, &st) != 0) fail(ErrorCategory::io, "{}: cannot stat: {}", file, errno_text());
    if (!S_ISREG(st.st_mode)) fail(ErrorCategory::io, "{}: not a regular file", file);
    const uint64_t size = static_cast<uint64_t>(st.st_size);
    header_.file_size = size;
    if (size < kPreambleBytes) {
      fail(ErrorCategory::format, "{}: {} bytes is too short for a cvdw file (truncated?)", file,
           size);
    }
    char pre[kPreambleBytes];
    read_all(fd_, pre, sizeof pre, 0, path);
    if (std::memcmp(pre, kMagic, 4) != 0) {
      fail(ErrorCategory::format, "{}: not a cvdw file (magic '{}', expected 'CVDW')", file,
           printable_magic(pre));
    }
    std::memcpy(&header_.version, pre + 4, 4);
    if (header_.version != kCvdwVersion) {
      fail(ErrorCategory::format, "{}: unsupported cvdw version {} (this build reads version {})",
           file, header_.version, kCvdwVersion);
    }
    uint64_t hlen = 0;
    std::memcpy(&hlen, pre + 8, 8);
    if (hlen > size - kPreambleBytes) {
      fail(ErrorCategory::format, "{}: header length {} exceeds the file ({} bytes; truncated?)",
           file, hlen, size);
    }
    header_.data_start = kPreambleBytes + hlen;
    std::string text(hlen, '\0');
    read_all(fd_, text.data(), hlen, kPreambleBytes, path);
    nlohmann::json h;
    try {
      h = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception& e) {
      fail(ErrorCategory::format, "{}: malformed JSON header: {}", file, e.what());
    }
    if (!h.is_object()) fail(ErrorCategory::format, "{}: JSON header is not an object", file);
    if (auto f = h.find("format"); f != h.end() && *f != "cvdw") {
      fail(ErrorCategory::format, "{}: header format is {}, expected \"cvdw\"", file, f->dump());
    }
    if (auto m = h.find("model"); m != h.end()) {
      if (!m->is_string()) fail(ErrorCategory::format, "{}: header 'model' is not a string", file);
      header_.model = m->get<std::string>();
    }
    if (auto c = h.find("config"); c != h.end() && !c->is_null()) {
      if (!c->is_object())
        fail(ErrorCategory::format, "{}: header 'config' is not an object", file);
      header_.config = *c;
    }
    auto t = h.find("tensors");
    if (t == h.end() || !t->is_array()) {
      fail(ErrorCategory::format, "{}: header has no 'tensors' array", file);
    }
    std::set<std::string> names;
    for (size_t i = 0; i < t->size(); ++i) {
      CvdwEntry e = parse_entry((*t)[i], i, path);
      if (!names.insert(e.name).second) {
        fail(ErrorCategory::format, "{}: tensor '{}' appears twice in the tensor table", file,
             e.name);
      }
      if (e.offset % kCvdwAlignment != 0) {
        fail(ErrorCategory::format, "{}: tensor '{}': offset {} is not {}-byte aligned", file,
             e.name, e.offset, kCvdwAlignment);
      }
      if (e.offset < header_.data_start) {
        fail(ErrorCategory::format,
             "{}: tensor '{}': offset {} lies inside the header (data starts at {})", file, e.name,
             e.offset, header_.data_start);
      }
      if (e.offset > size || e.nbytes > size - e.offset) {
        fail(ErrorCategory::format,
             "{}: tensor '{}': bytes [{}, {}) lie outside the file of {} bytes (file truncated or "
             "offset corrupt)",
             file, e.name, e.offset, e.offset + e.nbytes, size);
      }
      header_.tensors.push_back(std::move(e));
    }
    // Blobs must not overlap.
    std::vector<const CvdwEntry*> by_offset;
    for (const auto& e : header_.tensors) {
      if (e.nbytes > 0) by_offset.push_back(&e);
    }
    std::sort(by_offset.begin(), by_offset.end(),
              [](auto* a, auto* b) { return a->offset < b->offset; });
    for (size_t i = 1; i < by_offset.size(); ++i) {
      if (by_offset[i - 1]->offset + by_offset[i - 1]->nbytes > by_offset[i]->offset) {
        fail(ErrorCategory::format, "{}: tensor '{}' overlaps tensor '{}'", file,
             by_offset[i]->name, by_offset[i - 1]->name);
      }
    }
    if (options_.use_mmap) {
      void* base = ::mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE, fd_, 0);
      if (base != MAP_FAILED) {
        mapping_ = std::make_shared<Mapping>();
        mapping_->base = base;
        mapping_->size = size;
        ::close(fd_);
        fd_ = -1;
      }  // else fall back to reading
    }
  } catch (...) {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    throw;
  }
}

CvdwReader::~CvdwReader() {
  if (fd_ >= 0) ::close(fd_);
}

bool CvdwReader::contains(const std::string& name) const {
  return std::any_of(header_.tensors.begin(), header_.tensors.end(),
                     [&](const CvdwEntry& e) { return e.name == name; });
}

const CvdwEntry& CvdwReader::entry(const std::string& name) const {
  for (const auto& e : header_.tensors) {
    if (e.name == name) return e;
  }
  fail(ErrorCategory::invalid_argument, "{}: no tensor named '{}'", path_.string(), name);
}

const uint8_t* CvdwReader::blob(const CvdwEntry& e) const {
  return static_cast<const uint8_t*>(mapping_->base) + e.offset;
}

uint32_t CvdwReader::computed_crc32(size_t i) const {
  CVD_CHECK(i < header_.tensors.size(), "{}: tensor index {} out of range", path_.string(), i);
  const CvdwEntry& e = header_.tensors[i];
  if (mapping_) return crc32_of(blob(e), e.nbytes);
  std::vector<uint8_t> buf(e.nbytes);
  read_all(fd_, buf.data(), e.nbytes, e.offset, path_);
  return crc32_of(buf.data(), buf.size());
}

Tensor CvdwReader::load(const CvdwEntry& e) const {
  Tensor t;
  if (mapping_) {
    void* p = const_cast<uint8_t*>(blob(e));
    auto keep = mapping_;
    auto storage = std::make_shared<Storage>(p, e.nbytes, DeviceId::cpu(), [keep]() {});
    t = Tensor::from_storage(std::move(storage), e.shape, e.dtype);
  } else {
    t = Tensor::empty(e.shape, e.dtype);
    if (e.nbytes > 0) read_all(fd_, t.data_ptr(), e.nbytes, e.offset, path_);
  }
  if (options_.verify_crc) {
    uint32_t crc = crc32_of(t.data_ptr(), e.nbytes);
    if (crc != e.crc32) {
      fail(ErrorCategory::format,
           "{}: tensor '{}': CRC mismatch (stored {:08x}, computed {:08x}; file truncated or "
           "corrupt)",
           path_.string(), e.name, e.crc32, crc);
    }
  }
  return t;
}

Tensor CvdwReader::tensor(const std::string& name) const { return load(entry(name)); }

std::vector<std::pair<std::string, Tensor>> CvdwReader::tensors() const {
  std::vector<std::pair<std::string, Tensor>> out;
  out.reserve(header_.tensors.size());
  for (const auto& e : header_.tensors) out.emplace_back(e.name, load(e));
  return out;
}

CvdwContents read_cvdw(const std::filesystem::path& path, CvdwReadOptions options) {
  CvdwReader r(path, options);
  CvdwContents c;
  c.tensors = r.tensors();
  c.header = r.header();
  return c;
}

}  // namespace cvd
