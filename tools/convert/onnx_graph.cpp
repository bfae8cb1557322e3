#include "tools/convert/onnx_graph.h"

#include <cstring>
#include <fstream>
#include <functional>
#include <limits>

#include "engine/error.h"

namespace cvd {

namespace {

// Protobuf wire types.
enum WireType : uint32_t { kVarint = 0, kFixed64 = 1, kLengthDelimited = 2, kFixed32 = 5 };

// A bounded view of the file's bytes with the position and the field path (for messages).
class WireReader {
 public:
  WireReader(std::string_view bytes, size_t base, const std::filesystem::path* file,
             std::string context)
      : bytes_(bytes), base_(base), file_(file), context_(std::move(context)) {}

  bool done() const { return pos_ >= bytes_.size(); }
  size_t offset() const { return base_ + pos_; }
  const std::string& context() const { return context_; }
  const std::filesystem::path& file() const { return *file_; }

  [[noreturn]] void corrupt(const std::string& what) const {
    fail(ErrorCategory::format, "{}: not a valid ONNX model: {} at byte {} (in {})",
         file_->string(), what, offset(), context_);
  }

  uint64_t varint() {
    uint64_t v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (pos_ >= bytes_.size()) corrupt("truncated varint");
      const uint8_t b = static_cast<uint8_t>(bytes_[pos_++]);
      v |= static_cast<uint64_t>(b & 0x7f) << shift;
      if (!(b & 0x80)) return v;
    }
    corrupt("varint longer than 10 bytes");
  }
  // Reads a field key; returns false at the end of the message.
  bool key(uint32_t& field, uint32_t& wire) {
    if (done()) return false;
    const uint64_t k = varint();
    field = static_cast<uint32_t>(k >> 3);
    wire = static_cast<uint32_t>(k & 7);
    if (field == 0) corrupt("field number 0");
    return true;
  }
  std::string_view bytes_field() {
    const uint64_t n = varint();
    if (n > bytes_.size() - pos_)
      corrupt(fmt::format("length {} runs past the end of the data (file truncated?)", n));
    std::string_view v = bytes_.substr(pos_, n);
    pos_ += n;
    return v;
  }
  // A sub-message reader for a length-delimited field; `what` extends the context.
  WireReader message(const std::string& what) {
    const size_t start = pos_;
    std::string_view v = bytes_field();
    return WireReader(v, base_ + start + (pos_ - start - v.size()), file_, context_ + "." + what);
  }
  uint32_t fixed32() {
    if (bytes_.size() - pos_ < 4) corrupt("truncated fixed32");
    uint32_t v;
    std::memcpy(&v, bytes_.data() + pos_, 4);
    pos_ += 4;
    return v;
  }
  uint64_t fixed64() {
    if (bytes_.size() - pos_ < 8) corrupt("truncated fixed64");
    uint64_t v;
    std::memcpy(&v, bytes_.data() + pos_, 8);
    pos_ += 8;
    return v;
  }
  void skip(uint32_t wire) {
    switch (wire) {
      case kVarint:
        varint();
        return;
      case kFixed64:
        fixed64();
        return;
      case kLengthDelimited:
        bytes_field();
        return;
      case kFixed32:
        fixed32();
        return;
      default:
        corrupt(fmt::format("unsupported wire type {}", wire));
    }
  }
  void expect(uint32_t wire, uint32_t wanted, const char* field) {
    if (wire != wanted)
      corrupt(fmt::format("field '{}' has wire type {} (expected {})", field, wire, wanted));
  }
  std::string string_field(uint32_t wire, const char* field) {
    expect(wire, kLengthDelimited, field);
    return std::string(bytes_field());
  }
  int64_t int_field(uint32_t wire, const char* field) {
    expect(wire, kVarint, field);
    return static_cast<int64_t>(varint());
  }
  // A repeated int64 / int32 / uint64 element or packed run, appended to `out`.
  void ints_field(uint32_t wire, std::vector<int64_t>& out, const char* field) {
    if (wire == kVarint) {
      out.push_back(static_cast<int64_t>(varint()));
    } else if (wire == kLengthDelimited) {
      WireReader packed = message(field);
      while (!packed.done()) out.push_back(static_cast<int64_t>(packed.varint()));
    } else {
      corrupt(fmt::format("field '{}' has wire type {}", field, wire));
    }
  }
  // A repeated float element or packed run.
  void floats_field(uint32_t wire, std::vector<float>& out, const char* field) {
    auto to_float = [](uint32_t bits) {
      float f;
      std::memcpy(&f, &bits, 4);
      return f;
    };
    if (wire == kFixed32) {
      out.push_back(to_float(fixed32()));
    } else if (wire == kLengthDelimited) {
      std::string_view v = bytes_field();
      if (v.size() % 4) corrupt(fmt::format("packed '{}' of {} bytes", field, v.size()));
      const size_t n0 = out.size();
      out.resize(n0 + v.size() / 4);
      if (!v.empty()) std::memcpy(out.data() + n0, v.data(), v.size());  // no null memcpy
    } else {
      corrupt(fmt::format("field '{}' has wire type {}", field, wire));
    }
  }
  void doubles_field(uint32_t wire, std::vector<double>& out, const char* field) {
    if (wire == kFixed64) {
      const uint64_t bits = fixed64();
      double d;
      std::memcpy(&d, &bits, 8);
      out.push_back(d);
    } else if (wire == kLengthDelimited) {
      std::string_view v = bytes_field();
      if (v.size() % 8) corrupt(fmt::format("packed '{}' of {} bytes", field, v.size()));
      const size_t n0 = out.size();
      out.resize(n0 + v.size() / 8);
      if (!v.empty()) std::memcpy(out.data() + n0, v.data(), v.size());  // no null memcpy
    } else {
      corrupt(fmt::format("field '{}' has wire type {}", field, wire));
    }
  }

 private:
  std::string_view bytes_;
  size_t pos_ = 0;
  size_t base_;
  const std::filesystem::path* file_;
  std::string context_;
};

bool is_float_type(int32_t t) {
  return t == static_cast<int32_t>(OnnxDataType::float32) ||
         t == static_cast<int32_t>(OnnxDataType::float64);
}

// Bytes per element of an integer or bool type, 0 for other types.
size_t integer_type_size(int32_t t) {
  switch (static_cast<OnnxDataType>(t)) {
    case OnnxDataType::uint8:
    case OnnxDataType::int8:
    case OnnxDataType::boolean:
      return 1;
    case OnnxDataType::uint16:
    case OnnxDataType::int16:
      return 2;
    case OnnxDataType::int32:
    case OnnxDataType::uint32:
      return 4;
    case OnnxDataType::int64:
    case OnnxDataType::uint64:
      return 8;
    default:
      return 0;
  }
}

template <class T>
int64_t load_as_int64(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return static_cast<int64_t>(v);
}

// One little-endian element of integer type `t` from raw_data.
int64_t raw_integer(const char* p, int32_t t) {
  switch (static_cast<OnnxDataType>(t)) {
    case OnnxDataType::int8:
      return load_as_int64<int8_t>(p);
    case OnnxDataType::uint16:
      return load_as_int64<uint16_t>(p);
    case OnnxDataType::int16:
      return load_as_int64<int16_t>(p);
    case OnnxDataType::int32:
      return load_as_int64<int32_t>(p);
    case OnnxDataType::uint32:
      return load_as_int64<uint32_t>(p);
    case OnnxDataType::int64:
    case OnnxDataType::uint64:
      return load_as_int64<int64_t>(p);
    default:
      return load_as_int64<uint8_t>(p);  // uint8, bool
  }
}

OnnxTensor read_tensor(WireReader r) {
  OnnxTensor t;
  std::string_view raw;
  bool has_raw = false, external = false;
  std::string location;
  std::vector<float> floats;
  std::vector<double> doubles;
  std::vector<int64_t> ints;
  uint32_t field, wire;
  while (r.key(field, wire)) {
    switch (field) {
      case 1:
        r.ints_field(wire, t.dims, "dims");
        break;
      case 2:
        t.data_type = static_cast<int32_t>(r.int_field(wire, "data_type"));
        break;
      case 4:
        r.floats_field(wire, floats, "float_data");
        break;
      case 5:
        r.ints_field(wire, ints, "int32_data");
        break;
      case 7:
        r.ints_field(wire, ints, "int64_data");
        break;
      case 11:
        r.ints_field(wire, ints, "uint64_data");
        break;
      case 8:
        t.name = r.string_field(wire, "name");
        break;
      case 9:
        r.expect(wire, kLengthDelimited, "raw_data");
        raw = r.bytes_field();
        has_raw = true;
        break;
      case 10:
        r.doubles_field(wire, doubles, "double_data");
        break;
      case 13: {  // external_data: StringStringEntryProto {key = 1, value = 2}
        WireReader e = r.message("external_data");
        std::string k, v;
        uint32_t f2, w2;
        while (e.key(f2, w2)) {
          if (f2 == 1)
            k = e.string_field(w2, "key");
          else if (f2 == 2)
            v = e.string_field(w2, "value");
          else
            e.skip(w2);
        }
        if (k == "location") location = v;
        external = true;
        break;
      }
      case 14:
        if (r.int_field(wire, "data_location") == 1) external = true;
        break;
      default:
        r.skip(wire);
    }
  }
  for (int64_t d : t.dims)
    if (d < 0) r.corrupt(fmt::format("tensor '{}' has negative dimension {}", t.name, d));
  if (external)
    fail(ErrorCategory::unsupported,
         "{}: tensor '{}' stores its data outside the .onnx file (external data{}), which cvd "
         "does not read; re-save it inline with Python: m = onnx.load(path); "
         "onnx.save_model(m, 'inline.onnx', save_as_external_data=False)",
         r.file().string(), t.name, location.empty() ? "" : fmt::format(" in '{}'", location));
  // Bound the element count before using it (a corrupt shape must not overflow int64 or size an
  // allocation: found by tests/fuzz/fuzz_onnx). The product of the non-zero dimensions is bounded
  // too: with a zero dimension the count is 0, but the strides still multiply the others (found
  // by the 1 M-execution fuzz run, tests/data/fuzz_regressions/onnx_zero_dim_stride_overflow.onnx).
  int64_t n = 1, nonzero = 1;
  for (int64_t d : t.dims) {
    if (d != 0 && nonzero > std::numeric_limits<int64_t>::max() / 16 / d)
      r.corrupt(fmt::format("tensor '{}' has an impossibly large shape [{}]", t.name,
                            fmt::join(t.dims, ", ")));
    if (d != 0) nonzero *= d;
    n *= d;
  }
  const auto count_error = [&](size_t got, const char* field) {
    r.corrupt(fmt::format("tensor '{}' of shape [{}] holds {} values in {}", t.name,
                          fmt::join(t.dims, ", "), got, field));
  };
  if (is_float_type(t.data_type)) {
    const bool f32 = t.data_type == static_cast<int32_t>(OnnxDataType::float32);
    const size_t esize = f32 ? 4 : 8;
    // Sizes are checked before allocating, so a corrupt shape cannot request a huge buffer.
    if (has_raw) {
      if (raw.size() != static_cast<size_t>(n) * esize) count_error(raw.size() / esize, "raw_data");
    } else if (f32) {
      if (floats.size() != static_cast<size_t>(n)) count_error(floats.size(), "float_data");
    } else {
      if (doubles.size() != static_cast<size_t>(n)) count_error(doubles.size(), "double_data");
    }
    t.values = Tensor::empty(Shape(t.dims.begin(), t.dims.end()), f32 ? DType::f32 : DType::f64);
    void* dst = t.values.data_ptr();
    if (n == 0) {
      // An empty tensor: nothing to copy (and memcpy must not see null pointers).
    } else if (has_raw) {
      std::memcpy(dst, raw.data(), raw.size());
    } else if (f32) {
      std::memcpy(dst, floats.data(), floats.size() * 4);
    } else {
      std::memcpy(dst, doubles.data(), doubles.size() * 8);
    }
  } else if (integer_type_size(t.data_type) > 0) {
    if (has_raw) {
      const size_t es = integer_type_size(t.data_type);
      if (raw.size() != static_cast<size_t>(n) * es) count_error(raw.size() / es, "raw_data");
      t.ints.resize(n);
      for (int64_t i = 0; i < n; ++i) t.ints[i] = raw_integer(raw.data() + i * es, t.data_type);
    } else {
      if (ints.size() != static_cast<size_t>(n)) count_error(ints.size(), "int data");
      t.ints = std::move(ints);
    }
  }
  return t;
}

OnnxAttribute read_attribute(WireReader r) {
  OnnxAttribute a;
  uint32_t field, wire;
  while (r.key(field, wire)) {
    switch (field) {
      case 1:
        a.name = r.string_field(wire, "name");
        break;
      case 20:
        a.type = static_cast<OnnxAttributeType>(r.int_field(wire, "type"));
        break;
      case 2: {
        r.expect(wire, kFixed32, "f");
        const uint32_t bits = r.fixed32();
        std::memcpy(&a.f, &bits, 4);
        break;
      }
      case 3:
        a.i = r.int_field(wire, "i");
        break;
      case 4:
        a.s = r.string_field(wire, "s");
        break;
      case 5:
        r.expect(wire, kLengthDelimited, "t");
        a.t = std::make_shared<OnnxTensor>(read_tensor(r.message("t")));
        break;
      case 7:
        r.floats_field(wire, a.floats, "floats");
        break;
      case 8:
        r.ints_field(wire, a.ints, "ints");
        break;
      case 9:
        a.strings.push_back(r.string_field(wire, "strings"));
        break;
      default:
        r.skip(wire);  // subgraphs and the rest: the op is refused by the converter
    }
  }
  return a;
}

OnnxNode read_node(WireReader r) {
  OnnxNode n;
  uint32_t field, wire;
  while (r.key(field, wire)) {
    switch (field) {
      case 1:
        n.inputs.push_back(r.string_field(wire, "input"));
        break;
      case 2:
        n.outputs.push_back(r.string_field(wire, "output"));
        break;
      case 3:
        n.name = r.string_field(wire, "name");
        break;
      case 4:
        n.op_type = r.string_field(wire, "op_type");
        break;
      case 7:
        n.domain = r.string_field(wire, "domain");
        break;
      case 5:
        r.expect(wire, kLengthDelimited, "attribute");
        n.attributes.push_back(read_attribute(r.message("attribute")));
        break;
      default:
        r.skip(wire);
    }
  }
  if (n.op_type.empty()) r.corrupt("node without op_type");
  if (n.domain == "ai.onnx") n.domain.clear();
  return n;
}

std::string value_info_name(WireReader r) {
  std::string name;
  uint32_t field, wire;
  while (r.key(field, wire)) {
    if (field == 1)
      name = r.string_field(wire, "name");
    else
      r.skip(wire);
  }
  return name;
}

OnnxGraph read_graph(WireReader r) {
  OnnxGraph g;
  uint32_t field, wire;
  while (r.key(field, wire)) {
    switch (field) {
      case 1:
        r.expect(wire, kLengthDelimited, "node");
        g.nodes.push_back(read_node(r.message(fmt::format("node[{}]", g.nodes.size()))));
        break;
      case 2:
        g.name = r.string_field(wire, "name");
        break;
      case 5:
        r.expect(wire, kLengthDelimited, "initializer");
        g.initializers.push_back(
            read_tensor(r.message(fmt::format("initializer[{}]", g.initializers.size()))));
        break;
      case 15:
        fail(ErrorCategory::unsupported,
             "{}: the graph has sparse initializers, which cvd does not read", r.file().string());
      case 11:
        r.expect(wire, kLengthDelimited, "input");
        g.inputs.push_back(value_info_name(r.message("input")));
        break;
      case 12:
        r.expect(wire, kLengthDelimited, "output");
        g.outputs.push_back(value_info_name(r.message("output")));
        break;
      default:
        r.skip(wire);
    }
  }
  g.reindex();
  return g;
}

}  // namespace

std::string onnx_data_type_name(int32_t t) {
  static const std::map<int32_t, const char*> names = {
      {0, "UNDEFINED"}, {1, "FLOAT"},   {2, "UINT8"},   {3, "INT8"},    {4, "UINT16"},
      {5, "INT16"},     {6, "INT32"},   {7, "INT64"},   {8, "STRING"},  {9, "BOOL"},
      {10, "FLOAT16"},  {11, "DOUBLE"}, {12, "UINT32"}, {13, "UINT64"}, {16, "BFLOAT16"}};
  auto it = names.find(t);
  return it != names.end() ? it->second : fmt::format("type {}", t);
}

int64_t OnnxTensor::numel() const {
  int64_t n = 1;
  for (int64_t d : dims) n *= d;
  return n;
}

const OnnxAttribute* OnnxNode::attribute(std::string_view attr_name) const {
  for (const auto& a : attributes)
    if (a.name == attr_name) return &a;
  return nullptr;
}

int64_t OnnxNode::int_attribute(std::string_view attr_name, int64_t fallback) const {
  const OnnxAttribute* a = attribute(attr_name);
  return a ? a->i : fallback;
}

float OnnxNode::float_attribute(std::string_view attr_name, float fallback) const {
  const OnnxAttribute* a = attribute(attr_name);
  return a ? a->f : fallback;
}

std::string OnnxNode::string_attribute(std::string_view attr_name,
                                       const std::string& fallback) const {
  const OnnxAttribute* a = attribute(attr_name);
  return a ? a->s : fallback;
}

std::vector<int64_t> OnnxNode::ints_attribute(std::string_view attr_name) const {
  const OnnxAttribute* a = attribute(attr_name);
  return a ? a->ints : std::vector<int64_t>{};
}

std::string OnnxNode::describe(size_t index) const {
  return name.empty() ? fmt::format("{} node #{}", op_type, index)
                      : fmt::format("{} node '{}'", op_type, name);
}

const OnnxTensor* OnnxGraph::initializer(const std::string& tensor_name) const {
  auto it = index_.find(tensor_name);
  if (it == index_.end() || it->second >= initializers.size() ||
      initializers[it->second].name != tensor_name)
    return nullptr;
  return &initializers[it->second];
}

void OnnxGraph::reindex() {
  index_.clear();
  for (size_t i = 0; i < initializers.size(); ++i) index_.emplace(initializers[i].name, i);
}

int64_t OnnxModel::default_opset() const {
  for (const auto& [domain, version] : opset_imports)
    if (domain.empty() || domain == "ai.onnx") return version;
  return 0;
}

OnnxModel parse_onnx(std::string_view bytes, const std::filesystem::path& source) {
  OnnxModel m;
  m.path = source;
  if (bytes.empty())
    fail(ErrorCategory::format, "{}: not a valid ONNX model: the file is empty", source.string());
  if (bytes.size() >= 4 && bytes.substr(0, 2) == "PK")
    fail(ErrorCategory::format,
         "{}: not an ONNX model but a zip archive (a PyTorch .pt / .pth checkpoint?): export it "
         "to ONNX first (see the README, 'Converting published weights')",
         source.string());
  WireReader r(bytes, 0, &m.path, source.filename().string());
  bool has_graph = false;
  uint32_t field, wire;
  while (r.key(field, wire)) {
    switch (field) {
      case 1:
        m.ir_version = r.int_field(wire, "ir_version");
        break;
      case 2:
        m.producer_name = r.string_field(wire, "producer_name");
        break;
      case 3:
        m.producer_version = r.string_field(wire, "producer_version");
        break;
      case 7:
        r.expect(wire, kLengthDelimited, "graph");
        m.graph = read_graph(r.message("graph"));
        has_graph = true;
        break;
      case 8: {
        r.expect(wire, kLengthDelimited, "opset_import");
        WireReader o = r.message("opset_import");
        std::string domain;
        int64_t version = 0;
        uint32_t f2, w2;
        while (o.key(f2, w2)) {
          if (f2 == 1)
            domain = o.string_field(w2, "domain");
          else if (f2 == 2)
            version = o.int_field(w2, "version");
          else
            o.skip(w2);
        }
        m.opset_imports.emplace_back(domain, version);
        break;
      }
      default:
        r.skip(wire);
    }
  }
  if (!has_graph || m.ir_version <= 0)
    fail(ErrorCategory::format, "{}: not a valid ONNX model: {}", source.string(),
         has_graph ? "no ir_version" : "no graph (is this an ONNX file?)");
  if (m.graph.nodes.empty())
    fail(ErrorCategory::format, "{}: not a valid ONNX model: the graph has no nodes",
         source.string());
  return m;
}

OnnxModel read_onnx(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in)
    fail(ErrorCategory::io, "{}: cannot open the ONNX file ({})", path.string(),
         std::strerror(errno));
  std::string bytes;
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) fail(ErrorCategory::io, "{}: cannot read the ONNX file", path.string());
  in.seekg(0);
  bytes.resize(static_cast<size_t>(size));
  if (!in.read(bytes.data(), size))
    fail(ErrorCategory::io, "{}: cannot read the ONNX file", path.string());
  return parse_onnx(bytes, path);
}

}  // namespace cvd
