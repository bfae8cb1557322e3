#include "tools/convert/onnx_graph.h"

#include <onnx/checker.h>
#include <onnx/onnx_pb.h>

#include <climits>
#include <cstring>
#include <fstream>
#include <limits>

#include "engine/error.h"

namespace cvd {

namespace {

// ONNX files are decoded by libonnx's generated ModelProto (protobuf); this file maps the few
// message types a weights converter needs into plain structs and checks what protobuf cannot:
// shapes against data sizes, external data, an empty graph.

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

[[noreturn]] void corrupt(const std::filesystem::path& file, const std::string& what) {
  fail(ErrorCategory::format, "{}: not a valid ONNX model: {}", file.string(), what);
}

OnnxTensor read_tensor(const onnx::TensorProto& p, const std::filesystem::path& file) {
  OnnxTensor t;
  t.name = p.name();
  t.data_type = p.data_type();
  t.dims.assign(p.dims().begin(), p.dims().end());
  const bool external = p.data_location() == onnx::TensorProto::EXTERNAL || p.external_data_size();
  if (external) {
    std::string location;
    for (const auto& e : p.external_data())
      if (e.key() == "location") location = e.value();
    fail(ErrorCategory::unsupported,
         "{}: tensor '{}' stores its data outside the .onnx file (external data{}), which cvd "
         "does not read; re-save it inline with Python: m = onnx.load(path); "
         "onnx.save_model(m, 'inline.onnx', save_as_external_data=False)",
         file.string(), t.name, location.empty() ? "" : fmt::format(" in '{}'", location));
  }
  for (int64_t d : t.dims)
    if (d < 0) corrupt(file, fmt::format("tensor '{}' has negative dimension {}", t.name, d));
  // Bound the element count before using it (a corrupt shape must not overflow int64 or size an
  // allocation: found by tests/fuzz/fuzz_onnx). The product of the non-zero dimensions is bounded
  // too: with a zero dimension the count is 0, but the strides still multiply the others (found
  // by the 1 M-execution fuzz run, tests/data/fuzz_regressions/onnx_zero_dim_stride_overflow.onnx).
  int64_t n = 1, nonzero = 1;
  for (int64_t d : t.dims) {
    if (d != 0 && nonzero > std::numeric_limits<int64_t>::max() / 16 / d)
      corrupt(file, fmt::format("tensor '{}' has an impossibly large shape [{}]", t.name,
                                fmt::join(t.dims, ", ")));
    if (d != 0) nonzero *= d;
    n *= d;
  }
  const auto count_error = [&](size_t got, const char* field) {
    corrupt(file, fmt::format("tensor '{}' of shape [{}] holds {} values in {}", t.name,
                              fmt::join(t.dims, ", "), got, field));
  };
  const std::string& raw = p.raw_data();
  const bool has_raw = p.has_raw_data();
  if (is_float_type(t.data_type)) {
    const bool f32 = t.data_type == static_cast<int32_t>(OnnxDataType::float32);
    const size_t esize = f32 ? 4 : 8;
    // Sizes are checked before allocating, so a corrupt shape cannot request a huge buffer.
    if (has_raw) {
      if (raw.size() != static_cast<size_t>(n) * esize) count_error(raw.size() / esize, "raw_data");
    } else if (f32) {
      if (p.float_data_size() != n) count_error(p.float_data_size(), "float_data");
    } else {
      if (p.double_data_size() != n) count_error(p.double_data_size(), "double_data");
    }
    t.values = Tensor::empty(Shape(t.dims.begin(), t.dims.end()), f32 ? DType::f32 : DType::f64);
    void* dst = t.values.data_ptr();
    if (n == 0) {
      // An empty tensor: nothing to copy (and memcpy must not see null pointers).
    } else if (has_raw) {
      std::memcpy(dst, raw.data(), raw.size());
    } else if (f32) {
      std::memcpy(dst, p.float_data().data(), static_cast<size_t>(n) * 4);
    } else {
      std::memcpy(dst, p.double_data().data(), static_cast<size_t>(n) * 8);
    }
  } else if (integer_type_size(t.data_type) > 0) {
    if (has_raw) {
      const size_t es = integer_type_size(t.data_type);
      if (raw.size() != static_cast<size_t>(n) * es) count_error(raw.size() / es, "raw_data");
      t.ints.resize(n);
      for (int64_t i = 0; i < n; ++i) t.ints[i] = raw_integer(raw.data() + i * es, t.data_type);
    } else {
      // Each integer type has its own repeated field (int32_data also holds the narrower ones).
      std::vector<int64_t> ints;
      const auto t64 = static_cast<OnnxDataType>(t.data_type);
      if (t64 == OnnxDataType::int64)
        ints.assign(p.int64_data().begin(), p.int64_data().end());
      else if (t64 == OnnxDataType::uint64 || t64 == OnnxDataType::uint32)
        ints.assign(p.uint64_data().begin(), p.uint64_data().end());
      else
        ints.assign(p.int32_data().begin(), p.int32_data().end());
      if (ints.size() != static_cast<size_t>(n)) count_error(ints.size(), "int data");
      t.ints = std::move(ints);
    }
  }
  return t;
}

OnnxAttribute read_attribute(const onnx::AttributeProto& p, const std::filesystem::path& file) {
  OnnxAttribute a;
  a.name = p.name();
  a.type = static_cast<OnnxAttributeType>(p.type());
  a.f = p.f();
  a.i = p.i();
  a.s = p.s();
  a.floats.assign(p.floats().begin(), p.floats().end());
  a.ints.assign(p.ints().begin(), p.ints().end());
  a.strings.assign(p.strings().begin(), p.strings().end());
  if (p.has_t()) a.t = std::make_shared<OnnxTensor>(read_tensor(p.t(), file));
  // Subgraphs and the rest are not read: such ops are refused by the converter.
  return a;
}

OnnxNode read_node(const onnx::NodeProto& p, const std::filesystem::path& file, size_t index) {
  OnnxNode n;
  n.name = p.name();
  n.op_type = p.op_type();
  n.domain = p.domain();
  n.inputs.assign(p.input().begin(), p.input().end());
  n.outputs.assign(p.output().begin(), p.output().end());
  for (const auto& a : p.attribute()) n.attributes.push_back(read_attribute(a, file));
  if (n.op_type.empty()) corrupt(file, fmt::format("graph.node[{}] has no op_type", index));
  if (n.domain == "ai.onnx") n.domain.clear();
  return n;
}

OnnxGraph read_graph(const onnx::GraphProto& p, const std::filesystem::path& file) {
  if (p.sparse_initializer_size())
    fail(ErrorCategory::unsupported,
         "{}: the graph has sparse initializers, which cvd does not read", file.string());
  OnnxGraph g;
  g.name = p.name();
  for (int i = 0; i < p.node_size(); ++i) g.nodes.push_back(read_node(p.node(i), file, i));
  for (const auto& t : p.initializer()) g.initializers.push_back(read_tensor(t, file));
  for (const auto& v : p.input()) g.inputs.push_back(v.name());
  for (const auto& v : p.output()) g.outputs.push_back(v.name());
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
  if (bytes.size() > static_cast<size_t>(INT_MAX))
    fail(ErrorCategory::unsupported,
         "{}: {} bytes; protobuf decodes at most 2 GiB in one message and cvd does not read "
         "external data",
         source.string(), bytes.size());
  onnx::ModelProto p;
  if (!p.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())))
    corrupt(source,
            "protobuf cannot decode it as an ONNX ModelProto (the file is truncated or "
            "corrupt, or not an ONNX file)");
  if (!p.has_graph()) corrupt(source, "no graph (is this an ONNX file?)");
  if (p.ir_version() <= 0) corrupt(source, "no ir_version");
  m.ir_version = p.ir_version();
  m.producer_name = p.producer_name();
  m.producer_version = p.producer_version();
  for (const auto& o : p.opset_import()) m.opset_imports.emplace_back(o.domain(), o.version());
  m.graph = read_graph(p.graph(), source);
  if (m.graph.nodes.empty()) corrupt(source, "the graph has no nodes");
  // Then the ONNX checker (graph structure, node attributes and inputs against the op schemas),
  // after the checks above, so that their messages (tensor sizes, external data) come first.
  try {
    onnx::checker::check_model(p);
  } catch (const std::exception& e) {
    std::string what = e.what();
    if (const size_t nl = what.find('\n'); nl != std::string::npos) what.resize(nl);
    corrupt(source, "the ONNX checker rejects it: " + what);
  }
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
