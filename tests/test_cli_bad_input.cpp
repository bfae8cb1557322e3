// Bad input to the `cvd` CLI (issue 8): every case must end with one clear message that names the
// file (or flag) and the cause, the documented exit code (tools/cli/command.h), and nothing under
// the final output names. Inputs are tiny (a few 64x48 frames written here) and the pipeline flags
// are the smallest ones, so each case runs in about a second.
#include <gtest/gtest.h>

#include <unistd.h>
#include <fstream>
#include <functional>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "engine/cvdw.h"
#include "tests/test_support.h"

namespace cvd::test {
namespace {

namespace fs = std::filesystem;

const char* kFastFlags = "--epochs 1 --warmup 1 --width 0.0625 --depth-size 64 --no-videos";

// Names `cvd run` writes into its output folder once complete; none may exist after a failure.
const char* kFinalOutputs[] = {"depth",     "depth_png16", "depth_color",     "depth_initial",
                               "poses.txt", "colmap",      "intrinsics.json", "points.ply",
                               "run.json",  "depth.mp4",   "side_by_side.mp4"};

// Single-quoted for the shell (test paths hold no quotes).
std::string q(const fs::path& p) {
  std::string s = "'";
  s += p.string();
  s += "'";
  return s;
}

// A textured frame (smooth noise) shifted by `shift` pixels, so consecutive frames have flow.
cv::Mat textured_frame(int width, int height, int shift) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> d(0, 255);
  cv::Mat big(height, width + 16, CV_8UC3);
  for (int y = 0; y < big.rows; ++y)
    for (int x = 0; x < big.cols; ++x) big.at<cv::Vec3b>(y, x) = cv::Vec3b(d(rng), d(rng), d(rng));
  return big(cv::Rect(shift, 0, width, height)).clone();
}

fs::path write_frames(const fs::path& dir, int n, int width = 64, int height = 48) {
  fs::create_directories(dir);
  for (int k = 0; k < n; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d.png", k);
    EXPECT_TRUE(cv::imwrite((dir / name).string(), textured_frame(width, height, k)));
  }
  return dir;
}

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

// TUM poses, camera-to-world, a small sideways motion.
std::string tum_lines(int n) {
  std::string s = "# timestamp tx ty tz qx qy qz qw\n";
  for (int k = 0; k < n; ++k)
    s += std::to_string(k * 0.1) + " " + std::to_string(0.05 * k) + " 0 0 0 0 0 1\n";
  return s;
}

const char* kIntrinsics = "--intrinsics 60,60,31.5,23.5";

// A valid weights file of the default network (width 1/16), converted from the ONNX fixture.
fs::path converted_weights(const TempDir& t) {
  fs::path w = t / "weights.cvdw";
  CommandResult r = run_cvd("convert " + q(source_dir() / "tests/data/onnx/mannequin_tiny.onnx") +
                            " --arch mannequin --width 0.0625 -o " + q(w));
  EXPECT_EQ(r.exit_code, 0) << r.output;
  return w;
}

// Poses and intrinsics for 3 frames, so a run does not need COLMAP.
std::string tum_args(const TempDir& t) {
  write_text(t / "poses.txt", tum_lines(3));
  return " --poses " + q(t / "poses.txt") + " --poses-format tum " + kIntrinsics;
}

// A wrapper around the real `colmap` (POSIX sh; @REAL_COLMAP@ is replaced by its path): feature
// extraction and matching run for real (cvd edits the database between mapper runs), but the
// mapper writes a fake model (images.bin is only looked for, never read) and model_converter its
// text form, registering the first two of the images cvd handed to COLMAP.
const char* kFakeColmapTwoFrames = R"SH(#!/bin/sh
cmd=$1
case $cmd in
  feature_extractor | *_matcher) exec "@REAL_COLMAP@" "$@" ;;
esac
shift
out=
in=
while [ $# -gt 0 ]; do
  case $1 in
    --output_path) out=$2; shift ;;
    --input_path) in=$2; shift ;;
  esac
  shift
done
case $cmd in
  mapper) mkdir -p "$out/0" && echo fake > "$out/0/images.bin" ;;
  model_converter)
    set -- $(ls "$(dirname "$(dirname "$in")")/colmap_images" | head -n 2)
    echo "1 PINHOLE 64 48 60 60 31.5 23.5" > "$out/cameras.txt"
    printf '1 1 0 0 0 0 0 0 1 %s\n\n2 1 0 0 0 -0.05 0 0 1 %s\n\n' "$1" "$2" > "$out/images.txt"
    : > "$out/points3D.txt"
    ;;
esac
exit 0
)SH";

struct BadInputCase {
  std::string name;
  // Builds the inputs under the temp dir and returns the arguments of `cvd` (output: t/"out").
  std::function<std::string(const TempDir&)> setup;
  int exit_code;
  // Substrings the output must contain; "$T" is replaced by the temp dir.
  std::vector<std::string> messages;
  // Extra paths (relative to the temp dir) that must not exist afterwards.
  std::vector<std::string> absent = {};
  // Environment assignments for the command ("$T" = the temp dir), e.g. a PATH without colmap.
  std::string env = "";
};

std::string run_args(const TempDir& t, const fs::path& input, const std::string& extra = "") {
  return "run " + q(input) + " -o " + q(t / "out") + " " + kFastFlags + " " + extra;
}

std::vector<BadInputCase> cases() {
  return {
      {"missing_input_path",
       [](const TempDir& t) { return run_args(t, t / "no_such_video.mp4"); },
       4,
       {"$T/no_such_video.mp4", "no such file or directory"},
       {"out"}},
      {"zero_byte_video",
       [](const TempDir& t) {
         write_text(t / "empty.mp4", "");
         return run_args(t, t / "empty.mp4");
       },
       3,
       {"$T/empty.mp4", "cannot open the video"}},
      {"garbage_video",
       [](const TempDir& t) {
         std::string junk(4096, '\0');
         for (size_t i = 0; i < junk.size(); ++i) junk[i] = static_cast<char>((i * 7919) % 251);
         write_text(t / "garbage.mp4", junk);
         return run_args(t, t / "garbage.mp4");
       },
       3,
       {"$T/garbage.mp4", "cannot open the video"}},
      {"one_frame",
       [](const TempDir& t) { return run_args(t, write_frames(t / "frames", 1)); },
       3,
       {"$T/frames", "1 frame(s) selected", "at least 2"}},
      {"frames_of_different_sizes",
       [](const TempDir& t) {
         fs::path d = write_frames(t / "frames", 2);
         cv::imwrite((d / "frame_0002.png").string(), textured_frame(80, 48, 0));
         return run_args(t, d);
       },
       3,
       {"$T/frames/frame_0002.png", "80x48 differs from the first frame's 64x48"}},
      {"non_image_files_only",
       [](const TempDir& t) {
         fs::create_directories(t / "frames");
         write_text(t / "frames/notes.txt", "hello");
         write_text(t / "frames/data.bin", "\x01\x02");
         return run_args(t, t / "frames");
       },
       3,
       {"$T/frames", "the folder holds no images"}},
      {"undecodable_image",
       [](const TempDir& t) {
         fs::path d = write_frames(t / "frames", 2);
         write_text(d / "frame_0002.png", "not a png");
         return run_args(t, d);
       },
       3,
       {"$T/frames/frame_0002.png", "cannot decode the image"}},
      {"intrinsics_negative",
       [](const TempDir& t) {
         return run_args(t, write_frames(t / "frames", 3), "--intrinsics=-60,60,31.5,23.5");
       },
       3,
       {"--intrinsics '-60,60,31.5,23.5'", "must be positive"}},
      {"unknown_quality_preset",
       [](const TempDir& t) {
         return run_args(t, write_frames(t / "frames", 3), "--quality ultra");
       },
       2,
       {"--quality", "ultra", "fast,default,best"},
       {"out"}},
      {"unknown_given_poses_mode",
       [](const TempDir& t) {
         return run_args(t, write_frames(t / "frames", 3), "--given-poses refined");
       },
       2,
       {"--given-poses", "refined", "fixed", "adjusted"},
       {"out"}},
      {"unknown_warmup_scale",
       [](const TempDir& t) {
         return run_args(t, write_frames(t / "frames", 3), "--warmup-scale scene");
       },
       2,
       {"--warmup-scale", "scene", "frame", "video"},
       {"out"}},
      {"intrinsics_three_numbers",
       [](const TempDir& t) {
         return run_args(t, write_frames(t / "frames", 3), "--intrinsics 60,60,31.5");
       },
       3,
       {"--intrinsics '60,60,31.5'", "expected 4 numbers"}},
      {"intrinsics_letters",
       [](const TempDir& t) {
         return run_args(t, write_frames(t / "frames", 3), "--intrinsics fx,fy,cx,cy");
       },
       3,
       {"--intrinsics 'fx,fy,cx,cy'", "'fx' is not a number"}},
      {"intrinsics_principal_point_outside",
       [](const TempDir& t) {
         write_text(t / "poses.txt", tum_lines(3));
         return run_args(t, write_frames(t / "frames", 3),
                         "--poses " + q(t / "poses.txt") + " --intrinsics 60,60,500,23.5");
       },
       3,
       {"--intrinsics", "principal point"}},
      {"tum_fewer_poses_than_frames",
       [](const TempDir& t) {
         write_text(t / "poses.txt", tum_lines(2));
         return run_args(t, write_frames(t / "frames", 3),
                         "--poses " + q(t / "poses.txt") + " --poses-format tum " + kIntrinsics);
       },
       3,
       {"$T/poses.txt", "2 poses", "fewer poses than frames"}},
      {"tum_malformed_line",
       [](const TempDir& t) {
         write_text(t / "poses.txt",
                    "0 0 0 0 0 0 0 1\n0.1 0.05 zero 0 0 0 0 1\n0.2 0.1 0 0 0 0 0 1\n");
         return run_args(t, write_frames(t / "frames", 3),
                         "--poses " + q(t / "poses.txt") + " --poses-format tum " + kIntrinsics);
       },
       3,
       {"$T/poses.txt:2", "'zero' is not a number"}},
      {"output_under_a_regular_file",
       [](const TempDir& t) {
         write_text(t / "a_file", "x");
         return "run " + q(write_frames(t / "frames", 3)) + " -o " + q(t / "a_file/out") + " " +
                kFastFlags + tum_args(t);
       },
       4,
       {"$T/a_file/out", "cannot create the output directory"}},
      {"weights_truncated_run",
       [](const TempDir& t) {
         fs::path w = converted_weights(t);
         fs::resize_file(w, fs::file_size(w) / 2);
         return run_args(t, write_frames(t / "frames", 3), "--model " + q(w) + tum_args(t));
       },
       3,
       {"$T/weights.cvdw", "truncated"}},
      {"weights_truncated_inspect",
       [](const TempDir& t) {
         fs::path w = converted_weights(t);
         fs::resize_file(w, fs::file_size(w) / 2);
         return "inspect " + q(w);
       },
       3,
       {"$T/weights.cvdw", "truncated"}},
      {"weights_crc_mismatch_run",
       [](const TempDir& t) {
         fs::path w = converted_weights(t);
         uint64_t at;
         {
           CvdwReader r(w);
           at = r.header().tensors.back().offset;
         }
         std::fstream f(w, std::ios::in | std::ios::out | std::ios::binary);
         f.seekp(static_cast<std::streamoff>(at));
         f.write("\x5a\xa5\x5a\xa5", 4);
         f.close();
         return run_args(t, write_frames(t / "frames", 3), "--model " + q(w) + tum_args(t));
       },
       3,
       {"$T/weights.cvdw", "CRC mismatch"}},
      {"weights_crc_mismatch_inspect",
       [](const TempDir& t) {
         fs::path w = converted_weights(t);
         uint64_t at;
         {
           CvdwReader r(w);
           at = r.header().tensors.front().offset;
         }
         std::fstream f(w, std::ios::in | std::ios::out | std::ios::binary);
         f.seekp(static_cast<std::streamoff>(at));
         f.write("\x5a\xa5\x5a\xa5", 4);
         f.close();
         return "inspect " + q(w);
       },
       3,
       {"$T/weights.cvdw", "CRC mismatch in tensor"}},
      {"weights_wrong_architecture",
       [](const TempDir& t) {
         return run_args(t, write_frames(t / "frames", 3),
                         "--model " + q(source_dir() / "tests/data/models/flownet2_fixture.cvdw") +
                             tum_args(t));
       },
       3,
       {"flownet2_fixture.cvdw", "not a depth network weights file"}},
      {"weights_other_network_size",
       [](const TempDir& t) {
         // A mannequin file whose layers do not match the network it names (wrong width).
         return run_args(t, write_frames(t / "frames", 3),
                         "--model " +
                             q(source_dir() / "tests/data/onnx/mannequin_tiny.expected.cvdw") +
                             tum_args(t));
       },
       3,
       {"mannequin_tiny.expected.cvdw", "cannot load state"}},
      {"onnx_unsupported_ops",
       [](const TempDir& t) {
         return "convert " + q(source_dir() / "tests/data/onnx/unsupported_ops.onnx") +
                " --arch mannequin --width 0.0625 -o " + q(t / "converted.cvdw");
       },
       7,
       {"unsupported_ops.onnx", "unsupported op types", "FancyOp"},
       {"converted.cvdw"}},
      {"onnx_wrong_architecture",
       [](const TempDir& t) {
         return "convert " + q(source_dir() / "tests/data/onnx/mannequin_tiny.onnx") +
                " --arch mannequin --width 0.25 -o " + q(t / "converted.cvdw");
       },
       3,
       {"mannequin_tiny.onnx", "cannot convert to mannequin", "has shape"},
       {"converted.cvdw"}},
      {"onnx_fuzz_regression_shape_overflow",
       [](const TempDir& t) {
         // Found by tests/fuzz/fuzz_onnx: a tensor shape whose element count overflows int64.
         // The three fuzzer files are not valid protobuf: since the reader decodes with libonnx's
         // ModelProto they stop there; tests/data/onnx/bad_tensors/ holds the same defects as
         // valid ModelProtos (test_convert, ImpossibleTensorsAreRefusedNamingTheCause).
         return "convert " +
                q(source_dir() / "tests/data/fuzz_regressions/onnx_shape_overflow.onnx") +
                " --arch mannequin --width 0.0625 -o " + q(t / "converted.cvdw");
       },
       3,
       {"onnx_shape_overflow.onnx", "not a valid ONNX model"},
       {"converted.cvdw"}},
      {"onnx_fuzz_regression_zero_dim_stride_overflow",
       [](const TempDir& t) {
         // Found by the 1 M-execution run of tests/fuzz/fuzz_onnx under UBSan: a shape with a zero
         // dimension passed the element-count bound while its other dimensions overflowed the
         // strides (signed overflow in contiguous_strides).
         return "convert " +
                q(source_dir() / "tests/data/fuzz_regressions/onnx_zero_dim_stride_overflow.onnx") +
                " --arch mannequin --width 0.0625 -o " + q(t / "converted.cvdw");
       },
       3,
       {"onnx_zero_dim_stride_overflow.onnx", "not a valid ONNX model"},
       {"converted.cvdw"}},
      {"onnx_fuzz_regression_empty_packed_floats",
       [](const TempDir& t) {
         // Found by tests/fuzz/fuzz_onnx under UBSan: an empty packed float_data field made the
         // reader memcpy from a null pointer (undefined behaviour; the sanitizer build of this
         // test catches a regression, the Release build checks the message).
         return "convert " +
                q(source_dir() / "tests/data/fuzz_regressions/onnx_empty_packed_floats.onnx") +
                " --arch mannequin --width 0.0625 -o " + q(t / "converted.cvdw");
       },
       3,
       {"onnx_empty_packed_floats.onnx: not a valid ONNX model", "protobuf cannot decode"},
       {"converted.cvdw"}},
      {"colmap_failing",
       [](const TempDir& t) {
         fs::create_directories(t / "bin");
         write_text(t / "bin/colmap", "#!/bin/sh\necho 'simulated COLMAP failure' >&2\nexit 1\n");
         fs::permissions(t / "bin/colmap", fs::perms::owner_all);
         return run_args(t, write_frames(t / "frames", 3), "--poses-source colmap");
       },
       5,
       {"COLMAP feature_extractor failed with exit code 1", "$T/out/cache/colmap/work/colmap.log",
        "simulated COLMAP failure"},
       {},
       "PATH='$T/bin':\"$PATH\""},
      {"colmap_registers_too_few_frames",
       [](const TempDir& t) {
         // A fake COLMAP whose mapper "registers" only the first 2 of 4 frames (3 are required:
         // max(min_registered_frames 3, half of 4)); the relaxed retry gets the same model.
         fs::create_directories(t / "bin");
         std::string script = kFakeColmapTwoFrames;
         std::string real = run_command("command -v colmap").output;
         real.erase(real.find_last_not_of(" \n") + 1);
         script.replace(script.find("@REAL_COLMAP@"), 13, real);
         write_text(t / "bin/colmap", script);
         fs::permissions(t / "bin/colmap", fs::perms::owner_all);
         return run_args(t, write_frames(t / "frames", 4), "--poses-source colmap");
       },
       5,
       {"COLMAP registered only 2 of 4 frames (at least 3 required)",
        "unregistered: frame_0002, "
        "frame_0003",
        "$T/out/cache/colmap/work/colmap.log"},
       {},
       "PATH='$T/bin':\"$PATH\""},
      {"colmap_absent",
       [](const TempDir& t) {
         fs::create_directories(t / "empty_bin");
         return run_args(t, write_frames(t / "frames", 3), "--poses-source colmap");
       },
       7,
       {"colmap not found on PATH", "give the poses and intrinsics yourself"},
       {},
       "PATH='$T/empty_bin'"},
  };
}

class CliBadInput : public ::testing::TestWithParam<BadInputCase> {};

TEST_P(CliBadInput, ClearMessageExitCodeAndNoOutputs) {
  const BadInputCase& c = GetParam();
  TempDir t;
  std::string args = c.setup(t);
  std::string env = c.env;
  for (auto p = env.find("$T"); p != std::string::npos; p = env.find("$T"))
    env.replace(p, 2, t.path().string());
  CommandResult r =
      env.empty() ? run_cvd(args) : run_command("env " + env + " " + cli_path() + " " + args);
  EXPECT_EQ(r.exit_code, c.exit_code) << r.output;
  EXPECT_NE(r.output.find("cvd: error: "), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("internal error"), std::string::npos) << r.output;
  for (std::string m : c.messages) {
    if (auto p = m.find("$T"); p != std::string::npos) m.replace(p, 2, t.path().string());
    EXPECT_NE(r.output.find(m), std::string::npos) << "expected '" << m << "' in:\n" << r.output;
  }
  for (const char* name : kFinalOutputs)
    EXPECT_FALSE(fs::exists(t / "out" / name)) << "out/" << name << " left after a failure";
  for (const auto& a : c.absent) EXPECT_FALSE(fs::exists(t / a)) << a << " left after a failure";
  // The README table is built from these lines.
  std::string last;
  if (size_t p = r.output.rfind("cvd: error: "); p != std::string::npos)
    last = r.output.substr(p, r.output.find('\n', p) - p);
  std::printf("[bad-input] %s | exit %d | %s\n", c.name.c_str(), r.exit_code, last.c_str());
}

INSTANTIATE_TEST_SUITE_P(Cases, CliBadInput, ::testing::ValuesIn(cases()),
                         [](const auto& info) { return info.param.name; });

// ---- Disk full ---------------------------------------------------------------------------------
// A run whose stages are all cached (copied from a complete run) fails while writing its outputs:
// on a tmpfs with 8 KiB free (ENOSPC; needs a mount namespace: root, or unprivileged user
// namespaces) and under an 8 KiB file-size limit (EFBIG; works everywhere). Either way the first
// output, depth/frame_0000.pfm (12 KiB), cannot be written: exit code 4, a message naming it, and
// no partial output or temporary file left.
class CliDiskFull : public ::testing::Test {
 protected:
  // One complete run, shared by the tests, whose cache each test copies.
  static void SetUpTestSuite() {
    shared_ = new TempDir();
    frames_ = write_frames(*shared_ / "frames", 3);
    CommandResult r = run_cvd(run_args(*shared_ / "complete"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static void TearDownTestSuite() {
    delete shared_;
    shared_ = nullptr;
  }
  static std::string run_args(const fs::path& out) {
    return "run " + q(frames_) + " -o " + q(out) + " " + kFastFlags + tum_args(*shared_);
  }
  // Runs a shell script (through `launcher`) that runs `prologue` (which limits the disk), copies
  // the complete run's cache into `out`, runs cvd there under `limit` and lists what is left.
  CommandResult run_with_limited_disk(const std::string& launcher, const std::string& prologue,
                                      const std::string& limit, const fs::path& out) const {
    std::string script = prologue + "\nmkdir -p " + q(out) + " && cp -r " +
                         q(*shared_ / "complete/cache") + " " + q(out / "cache") + " || exit 98\n" +
                         "(trap '' XFSZ; " + limit + "exec " + cli_path() + " " + run_args(out) +
                         ")\nrc=$?\n";
    for (const char* name : kFinalOutputs)
      script += "[ -e " + q(out / name) + " ] && echo 'LEFT: " + name + "'\n";
    script += "find " + q(out) + " -name '.*tmp-*' -exec echo 'TEMPORARY: {}' ';'\nexit $rc\n";
    write_text(t_ / "disk_full.sh", script);
    return run_command(launcher + " sh " + q(t_ / "disk_full.sh"));
  }
  void expect_clean_io_failure(const CommandResult& r, const fs::path& out) const {
    EXPECT_EQ(r.exit_code, 4) << r.output;
    std::string pfm = (out / "depth/frame_0000.pfm").string();
    EXPECT_NE(r.output.find("cvd: error: writing PFM file '" + pfm + "' failed"), std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find("disk full"), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("LEFT: "), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("TEMPORARY: "), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("internal error"), std::string::npos) << r.output;
  }

  TempDir t_;
  static TempDir* shared_;
  static fs::path frames_;
};
TempDir* CliDiskFull::shared_ = nullptr;
fs::path CliDiskFull::frames_;

TEST_F(CliDiskFull, FullTmpfsFailsCleanlyWithExitCode4) {
  // Size the tmpfs to the cache (whole 4 KiB pages per file) plus 8 KiB.
  uintmax_t kib = 8;
  for (const auto& e : fs::recursive_directory_iterator(*shared_ / "complete/cache"))
    if (e.is_regular_file()) kib += (e.file_size() + 4095) / 4096 * 4;
  fs::path mnt = t_ / "small_disk";
  fs::create_directories(mnt);
  std::string prologue = "mount -t tmpfs -o size=" + std::to_string(kib) + "k cvd-test-tmpfs " +
                         q(mnt) + " || exit 99";
  // A private mount namespace: the tmpfs disappears with the shell.
  std::string launcher = ::getuid() == 0 ? "unshare -m" : "unshare -rm";
  CommandResult r = run_with_limited_disk(launcher, prologue, "", mnt / "out");
  if (r.exit_code == 99 || r.output.find("unshare: ") != std::string::npos)
    GTEST_SKIP() << "cannot mount a tmpfs in a private mount namespace here:\n" << r.output;
  expect_clean_io_failure(r, mnt / "out");
  if (size_t p = r.output.rfind("cvd: error: "); p != std::string::npos)
    std::printf("[bad-input] disk_full_tmpfs | exit %d | %s\n", r.exit_code,
                r.output.substr(p, r.output.find('\n', p) - p).c_str());
}

TEST_F(CliDiskFull, FileSizeLimitFailsCleanlyWithExitCode4) {
  // 16 blocks of 512 bytes (POSIX sh); SIGXFSZ is ignored, so write() fails with EFBIG.
  CommandResult r = run_with_limited_disk("", "", "ulimit -f 16; ", t_ / "limited/out");
  expect_clean_io_failure(r, t_ / "limited/out");
  if (size_t p = r.output.rfind("cvd: error: "); p != std::string::npos)
    std::printf("[bad-input] file_size_limit | exit %d | %s\n", r.exit_code,
                r.output.substr(p, r.output.find('\n', p) - p).c_str());
}

}  // namespace
}  // namespace cvd::test
