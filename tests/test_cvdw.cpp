// The .cvdw weights file: round trips (mmap and read), and every kind of corruption rejected with
// an Error(format) naming the file and the tensor at fault.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>

#include "engine/autograd.h"
#include "engine/cvdw.h"
#include "engine/random.h"
#include "tests/test_support.h"

namespace cvd {
namespace {

using test::TempDir;

std::string read_bytes(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

void write_bytes(const std::filesystem::path& p, const std::string& bytes) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// The JSON header of a file and a way to put a modified one back at the same length (offsets are
// absolute, so the header must not change size). The config is dropped to make room for edits
// that lengthen the header.
nlohmann::json header_of(const std::string& bytes) {
  uint64_t len = 0;
  std::memcpy(&len, bytes.data() + 8, 8);
  nlohmann::json h = nlohmann::json::parse(bytes.substr(16, len));
  h["config"] = nlohmann::json::object();
  return h;
}

std::string with_header(std::string bytes, const nlohmann::json& h) {
  uint64_t len = 0;
  std::memcpy(&len, bytes.data() + 8, 8);
  std::string text = h.dump();
  EXPECT_LE(text.size(), len) << "modified header does not fit";
  text.resize(len, ' ');
  bytes.replace(16, len, text);
  return bytes;
}

// Expects `fn` to throw Error(category) whose message contains every string of `parts`.
template <class Fn>
void expect_error(Fn&& fn, ErrorCategory category, const std::vector<std::string>& parts) {
  try {
    fn();
    ADD_FAILURE() << "no error thrown";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), category) << e.what();
    for (const auto& p : parts) {
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos)
          << "message '" << e.what() << "' lacks '" << p << "'";
    }
  }
}

struct Fixture {
  std::vector<CvdwTensor> tensors;
  nlohmann::json config = {{"width", 0.25}, {"features", 64}, {"name", "tiny"}};
};

Fixture make_tensors() {
  Generator gen(7);
  Fixture f;
  f.tensors.push_back({"layer1.0.conv1.weight", Tensor::randn({3, 5, 7, 1}, gen), "parameter"});
  f.tensors.push_back({"layer1.0.bn1.running_var", Tensor::randn({13}, gen, DType::f64), "buffer"});
  f.tensors.push_back({"scalar_f32", Tensor::scalar(3.25), ""});
  f.tensors.push_back({"scalar_f64", Tensor::scalar(-1.0 / 3.0, DType::f64), ""});
  f.tensors.push_back({"empty", Tensor::zeros({0, 4}), ""});
  f.tensors.push_back({"odd", Tensor::randn({2, 3, 1, 5, 1, 3}, gen, DType::f64), ""});
  // A non-contiguous view: written in its logical row-major order.
  f.tensors.push_back({"transposed", Tensor::randn({4, 3}, gen).transpose(0, 1), ""});
  f.tensors.push_back({"last.weight", Tensor::randn({17, 3}, gen), "parameter"});
  return f;
}

void expect_same(const Tensor& a, const Tensor& b, const std::string& name) {
  EXPECT_EQ(a.dtype(), b.dtype()) << name;
  EXPECT_EQ(a.shape(), b.shape()) << name;
  EXPECT_EQ(a.to_vector(), b.to_vector()) << name;  // bit-exact
}

class CvdwRoundTrip : public ::testing::TestWithParam<bool> {};

TEST_P(CvdwRoundTrip, TensorsModelAndConfigSurvive) {
  TempDir dir;
  const auto path = dir / "model.cvdw";
  Fixture f = make_tensors();
  write_cvdw(path, "tiny_net", f.config, f.tensors);

  CvdwReader r(path, CvdwReadOptions{.use_mmap = GetParam(), .verify_crc = true});
  EXPECT_EQ(r.header().model, "tiny_net");
  EXPECT_EQ(r.header().config, f.config);
  EXPECT_EQ(r.header().version, kCvdwVersion);
  EXPECT_EQ(r.header().file_size, std::filesystem::file_size(path));
  ASSERT_EQ(r.header().tensors.size(), f.tensors.size());
  for (size_t i = 0; i < f.tensors.size(); ++i) {
    const CvdwEntry& e = r.header().tensors[i];
    EXPECT_EQ(e.name, f.tensors[i].name);  // file order = write order
    EXPECT_EQ(e.kind, f.tensors[i].kind);
    EXPECT_EQ(e.offset % kCvdwAlignment, 0u) << e.name;
    EXPECT_GE(e.offset, r.header().data_start) << e.name;
    Tensor t = r.tensor(e.name);
    expect_same(t, f.tensors[i].tensor, e.name);
    if (t.numel() > 0) {
      EXPECT_EQ(reinterpret_cast<uintptr_t>(t.data_ptr()) % kCvdwAlignment, 0u) << e.name;
    }
    EXPECT_EQ(r.computed_crc32(i), e.crc32) << e.name;
  }
  EXPECT_EQ(r.header().tensors[2].shape, Shape{});  // 0-d stays 0-d
  EXPECT_EQ(r.header().tensors[4].nbytes, 0u);
}

INSTANTIATE_TEST_SUITE_P(MmapAndRead, CvdwRoundTrip, ::testing::Values(true, false),
                         [](const auto& info) { return info.param ? "mmap" : "read"; });

TEST(Cvdw, MappedTensorsOutliveTheReaderAndWritesStayPrivate) {
  TempDir dir;
  const auto path = dir / "w.cvdw";
  write_cvdw(path, "m", {}, {{"a", Tensor::from_vector(std::vector<double>{1, 2, 3}, {3}), ""}});
  Tensor a;
  {
    CvdwReader r(path);
    a = r.tensor("a");
  }
  EXPECT_EQ(a.to_vector(), (std::vector<double>{1, 2, 3}));
  a.fill_(9.0);  // copy-on-write: the file is unchanged
  EXPECT_EQ(a.to_vector(), (std::vector<double>{9, 9, 9}));
  EXPECT_EQ(read_cvdw(path).tensors[0].second.to_vector(), (std::vector<double>{1, 2, 3}));
}

TEST(Cvdw, OverwritesAtomicallyAndLeavesNoTemporaryFiles) {
  TempDir dir;
  const auto path = dir / "w.cvdw";
  write_cvdw(path, "first", {}, {{"a", Tensor::ones({2}), ""}});
  write_cvdw(path, "second", {}, {{"b", Tensor::zeros({5}), ""}});
  EXPECT_EQ(read_cvdw(path).header.model, "second");
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) {
    ++files;
    EXPECT_EQ(e.path().filename(), "w.cvdw");
  }
  EXPECT_EQ(files, 1);
}

TEST(Cvdw, WriterRejectsDuplicateNamesAndUnwritableTargets) {
  TempDir dir;
  expect_error(
      [&] {
        write_cvdw(dir / "d.cvdw", "m", {},
                   {{"a", Tensor::ones({1}), ""}, {"a", Tensor::ones({1}), ""}});
      },
      ErrorCategory::invalid_argument, {"'a'", "twice"});
  expect_error([&] { write_cvdw(dir / "no" / "such" / "dir.cvdw", "m", {}, {}); },
               ErrorCategory::io, {"dir.cvdw"});
  EXPECT_FALSE(std::filesystem::exists(dir / "d.cvdw"));
}

class CvdwCorruption : public ::testing::Test {
 protected:
  void SetUp() override {
    Fixture f = make_tensors();
    write_cvdw(path_, "tiny_net", f.config, f.tensors);
    bytes_ = read_bytes(path_);
  }
  TempDir dir_;
  std::filesystem::path path_ = dir_ / "model.cvdw";
  std::string bytes_;
};

TEST_F(CvdwCorruption, MissingFileIsAnIoError) {
  expect_error([&] { CvdwReader r(dir_ / "absent.cvdw"); }, ErrorCategory::io, {"absent.cvdw"});
}

TEST_F(CvdwCorruption, TruncatedInsideTheLastTensorNamesIt) {
  write_bytes(path_, bytes_.substr(0, bytes_.size() - 10));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"model.cvdw", "tensor 'last.weight'", "outside the file", "truncated"});
}

TEST_F(CvdwCorruption, TruncatedInsideTheHeader) {
  write_bytes(path_, bytes_.substr(0, 40));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"model.cvdw", "header length", "truncated"});
  write_bytes(path_, bytes_.substr(0, 9));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format, {"model.cvdw", "too short"});
}

TEST_F(CvdwCorruption, FlippedBitIsACrcMismatchNamingTheTensor) {
  CvdwReader clean(path_);
  const CvdwEntry e = clean.entry("layer1.0.conv1.weight");
  std::string bad = bytes_;
  bad[e.offset + 37] ^= 0x10;
  write_bytes(path_, bad);
  for (bool mmap : {true, false}) {
    CvdwReader r(path_, CvdwReadOptions{.use_mmap = mmap, .verify_crc = true});
    expect_error(
        [&] { r.tensor("layer1.0.conv1.weight"); }, ErrorCategory::format,
        {"model.cvdw: tensor 'layer1.0.conv1.weight': CRC mismatch", "file truncated or corrupt"});
    EXPECT_NO_THROW(r.tensor("last.weight"));  // the others are intact
    EXPECT_NE(r.computed_crc32(0), r.header().tensors[0].crc32);
  }
  expect_error([&] { read_cvdw(path_); }, ErrorCategory::format, {"'layer1.0.conv1.weight'"});
  // Without verification the (corrupt) data loads.
  EXPECT_NO_THROW(read_cvdw(path_, CvdwReadOptions{.use_mmap = true, .verify_crc = false}));
}

TEST_F(CvdwCorruption, WrongMagic) {
  std::string bad = bytes_;
  bad[0] = 'P';
  bad[3] = '\x01';
  write_bytes(path_, bad);
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"model.cvdw", "not a cvdw file", "magic 'PVD\\x01'"});
}

TEST_F(CvdwCorruption, WrongVersion) {
  std::string bad = bytes_;
  uint32_t v = kCvdwVersion + 1;
  std::memcpy(bad.data() + 4, &v, 4);
  write_bytes(path_, bad);
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"model.cvdw", fmt::format("unsupported cvdw version {}", v)});
}

TEST_F(CvdwCorruption, OffsetOutOfRangeNamesTheTensor) {
  nlohmann::json h = header_of(bytes_);
  h["tensors"][1]["offset"] = uint64_t{1} << 40;
  write_bytes(path_, with_header(bytes_, h));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"model.cvdw", "tensor 'layer1.0.bn1.running_var'", "outside the file"});
}

TEST_F(CvdwCorruption, MisalignedOverlappingOrHeaderOffsetsAreRejected) {
  nlohmann::json h = header_of(bytes_);
  nlohmann::json h1 = h;
  h1["tensors"][0]["offset"] = h["tensors"][0]["offset"].get<uint64_t>() + 8;
  write_bytes(path_, with_header(bytes_, h1));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"tensor 'layer1.0.conv1.weight'", "not 64-byte aligned"});
  nlohmann::json h2 = h;
  h2["tensors"][7]["offset"] = h["tensors"][0]["offset"];
  write_bytes(path_, with_header(bytes_, h2));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format, {"overlaps"});
  nlohmann::json h3 = h;
  h3["tensors"][0]["offset"] = 0;
  write_bytes(path_, with_header(bytes_, h3));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"tensor 'layer1.0.conv1.weight'", "inside the header"});
}

TEST_F(CvdwCorruption, InconsistentEntriesNameTheTensor) {
  nlohmann::json h = header_of(bytes_);
  nlohmann::json a = h;
  a["tensors"][1]["nbytes"] = 12;
  write_bytes(path_, with_header(bytes_, a));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"tensor 'layer1.0.bn1.running_var'", "nbytes 12"});
  nlohmann::json b = h;
  b["tensors"][2]["dtype"] = "i8";
  write_bytes(path_, with_header(bytes_, b));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"tensor 'scalar_f32'", "unknown dtype 'i8'"});
  nlohmann::json c = h;
  c["tensors"][3]["shape"] = {-1};
  write_bytes(path_, with_header(bytes_, c));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format, {"tensor 'scalar_f64'"});
  nlohmann::json d = h;
  d["tensors"][5]["name"] = "empty";
  write_bytes(path_, with_header(bytes_, d));
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format, {"'empty' appears twice"});
}

TEST_F(CvdwCorruption, MalformedJsonHeader) {
  std::string bad = bytes_;
  bad[16] = '[';
  bad[17] = '}';
  write_bytes(path_, bad);
  expect_error([&] { CvdwReader r(path_); }, ErrorCategory::format,
               {"model.cvdw", "malformed JSON header"});
}

TEST_F(CvdwCorruption, InspectCliReportsContentsAndCrcStatus) {
  auto ok = test::run_cvd("inspect --tensors " + path_.string());
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  for (const char* part :
       {"model:       tiny_net", "tensors:     8", "CRC:         all ok", "\"features\":64",
        "layer1.0.conv1.weight", "[3, 5, 7, 1]", "parameters:  156"}) {
    EXPECT_NE(ok.output.find(part), std::string::npos) << "lacks '" << part << "':\n" << ok.output;
  }
  CvdwReader clean(path_);
  std::string bad = bytes_;
  bad[clean.entry("odd").offset + 5] ^= 0x01;
  write_bytes(path_, bad);
  auto corrupt = test::run_cvd("inspect --tensors " + path_.string());
  EXPECT_EQ(corrupt.exit_code, 3) << corrupt.output;  // kExitBadInput
  EXPECT_NE(corrupt.output.find("1 of 8 tensors corrupt"), std::string::npos) << corrupt.output;
  EXPECT_NE(corrupt.output.find("MISMATCH"), std::string::npos) << corrupt.output;
  EXPECT_NE(corrupt.output.find("CRC mismatch in tensor 'odd'"), std::string::npos)
      << corrupt.output;
  auto missing = test::run_cvd("inspect " + (dir_ / "absent.cvdw").string());
  EXPECT_EQ(missing.exit_code, 4) << missing.output;  // kExitIo
}

}  // namespace
}  // namespace cvd
