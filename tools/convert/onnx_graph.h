// An ONNX model file (ModelProto) read into plain structs: the graph's nodes (op type, domain,
// inputs, outputs, attributes), initializers, inputs / outputs and the opset imports.
//
// The file is decoded by libonnx's generated ModelProto (protobuf; only this converter layer,
// not libcvd, links them) and the message types a weights converter needs are copied out; fields
// it does not need (doc strings, value_info, metadata, training info) are ignored.
//
// Tensors: FLOAT and DOUBLE data (raw_data, float_data or double_data) become CPU f32 / f64
// Tensors; integer and bool data (shape plumbing) become int64 values. Other element types
// (FLOAT16, BFLOAT16, STRING, ...) are kept without data; a converter that needs one reports it.
// External data (data_location EXTERNAL) is refused with a message that says how to re-save.
// Every malformed file is an Error(format) naming the file and what is wrong.
#pragma once
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "engine/tensor.h"

namespace cvd {

// TensorProto.DataType values used here.
enum class OnnxDataType : int32_t {
  undefined = 0,
  float32 = 1,
  uint8 = 2,
  int8 = 3,
  uint16 = 4,
  int16 = 5,
  int32 = 6,
  int64 = 7,
  string = 8,
  boolean = 9,
  float16 = 10,
  float64 = 11,
  uint32 = 12,
  uint64 = 13,
  bfloat16 = 16,
};
// "FLOAT", "INT64", ... ("type 42" for unknown values).
std::string onnx_data_type_name(int32_t data_type);

struct OnnxTensor {
  std::string name;
  int32_t data_type = 0;  // OnnxDataType
  std::vector<int64_t> dims;
  Tensor values;              // FLOAT / DOUBLE: CPU f32 / f64 tensor of shape `dims`
  std::vector<int64_t> ints;  // integer / bool types: the elements
  bool has_data() const { return values.defined() || !ints.empty() || numel() == 0; }
  int64_t numel() const;
};

enum class OnnxAttributeType : int32_t {
  undefined = 0,
  float32 = 1,
  int64 = 2,
  string = 3,
  tensor = 4,
  graph = 5,
  floats = 6,
  ints = 7,
  strings = 8,
  tensors = 9,
  graphs = 10,
};

struct OnnxAttribute {
  std::string name;
  OnnxAttributeType type = OnnxAttributeType::undefined;
  float f = 0;
  int64_t i = 0;
  std::string s;
  std::vector<float> floats;
  std::vector<int64_t> ints;
  std::vector<std::string> strings;
  std::shared_ptr<OnnxTensor> t;  // type tensor
};

struct OnnxNode {
  std::string name;
  std::string op_type;
  std::string domain;               // "" (= "ai.onnx") for standard operators
  std::vector<std::string> inputs;  // "" = an omitted optional input
  std::vector<std::string> outputs;
  std::vector<OnnxAttribute> attributes;

  const OnnxAttribute* attribute(std::string_view attr_name) const;
  int64_t int_attribute(std::string_view attr_name, int64_t fallback) const;
  float float_attribute(std::string_view attr_name, float fallback) const;
  std::string string_attribute(std::string_view attr_name, const std::string& fallback) const;
  std::vector<int64_t> ints_attribute(std::string_view attr_name) const;
  // "Conv 'name'" or "Conv #12" when unnamed, for messages.
  std::string describe(size_t index) const;
};

struct OnnxGraph {
  std::string name;
  std::vector<OnnxNode> nodes;  // in file order
  std::vector<OnnxTensor> initializers;
  std::vector<std::string> inputs;  // graph input names (may include initializers, IR < 4)
  std::vector<std::string> outputs;
  // The initializer called `name`, or null.
  const OnnxTensor* initializer(const std::string& name) const;
  // Index of `name` in `initializers` (rebuilt on demand after edits).
  void reindex();

 private:
  std::map<std::string, size_t> index_;
};

struct OnnxModel {
  std::filesystem::path path;  // where it was read from (for messages)
  int64_t ir_version = 0;
  std::string producer_name, producer_version;
  std::vector<std::pair<std::string, int64_t>> opset_imports;  // (domain, version)
  OnnxGraph graph;
  // The version of the default ("" / "ai.onnx") operator set, 0 when not imported.
  int64_t default_opset() const;
};

// Reads and decodes `path`. Error(io) when it cannot be read, Error(format) when it is not a
// well-formed ONNX model (naming the file and what is wrong), Error(unsupported) for external
// tensor data.
OnnxModel read_onnx(const std::filesystem::path& path);

// Decodes a serialized ModelProto held in memory; `source` names it in messages.
OnnxModel parse_onnx(std::string_view bytes, const std::filesystem::path& source);

}  // namespace cvd
