// Crash consistency and training faults of `cvd run` (issue 8), on a tiny generated clip
// (`cvd scene`, 6 frames of 128x96 with its TUM poses and intrinsics):
//  * a run killed with SIGKILL during training, then rerun, resumes from the last epoch
//    checkpoint and writes the same depth maps as an uninterrupted run;
//  * a run killed with SIGKILL during the flow stage (a larger 10-frame 640x480 clip, so the
//    stage lasts seconds), then rerun, keeps the flow pairs already done and writes the same flow
//    and depth as an uninterrupted run;
//  * a rerun with other training settings ignores the checkpoint, one with more epochs continues;
//  * NaN losses injected with CVD_FAULT_NAN_LOSS_STEPS are skipped and counted in run.json, and a
//    run whose every loss is NaN ends with exit code 6 and a clear message.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <thread>

#include "pipeline/io/pfm_io.h"
#include "tests/run_output_compare.h"
#include "tests/test_support.h"

namespace cvd::test {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

// Single-quoted for the shell (test paths hold no quotes).
std::string q(const fs::path& p) {
  std::string s = "'";
  s += p.string();
  s += "'";
  return s;
}

class TinyClip : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    CommandResult r = run_cvd("scene --out " + q(scene()) + " --frames 6 --width 128 --height 96");
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path scene() { return dir_->path() / "scene"; }
  static fs::path work() { return dir_->path(); }

  // Arguments of `cvd run` on the clip into `out` (2 epochs, the smallest network).
  static std::string run_args(const fs::path& out, int epochs = 2) {
    const std::string intr = intrinsics_flag_value(scene() / "intrinsics.json");
    return "run " + q(scene() / "rgb") + " -o " + q(out) + " --epochs " + std::to_string(epochs) +
           " --warmup 1 --width 0.0625 --depth-size 64 --no-videos --no-ply --poses " +
           q(scene() / "poses.txt") + " --poses-format tum --intrinsics " + intr;
  }

 private:
  static TempDir* dir_;
};
TempDir* TinyClip::dir_ = nullptr;

// Starts `cvd <args>` (stdout and stderr to `log`) and returns its pid; `exec` makes the shell
// become cvd, so the pid is cvd's own.
pid_t spawn_cvd(const std::string& args, const fs::path& log) {
  std::string cmd = "exec " + cli_path() + " " + args + " > " + q(log) + " 2>&1";
  pid_t pid = fork();
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Expects the two-epoch runs in `ref` (uninterrupted) and `out` (resumed or continued) to have
// trained alike: the same epoch losses and depth maps. Returns the largest relative depth
// difference.
double expect_same_two_epochs(const fs::path& ref, const fs::path& out) {
  const json a = read_json(ref / "run.json"), b = read_json(out / "run.json");
  auto la = a["training"]["epoch_losses"].get<std::vector<double>>();
  auto lb = b["training"]["epoch_losses"].get<std::vector<double>>();
  EXPECT_EQ(la.size(), 2u);
  EXPECT_EQ(lb.size(), 2u);
  // Tolerance: measured bit-identical (largest difference 0) with the CPU kernels, which reduce in
  // a fixed order; 1e-5 relative leaves room only for float rounding in other thread counts.
  for (size_t e = 0; e < std::min(la.size(), lb.size()); ++e)
    EXPECT_NEAR(lb[e], la[e], 1e-5 * std::abs(la[e])) << e;
  int files = 0;
  const double worst = max_relative_depth_difference(ref, out, files);
  EXPECT_EQ(files, 6);
  EXPECT_LE(worst, 1e-5) << "largest relative depth difference, " << out << " vs " << ref;
  return worst;
}

TEST_F(TinyClip, KilledDuringTrainingResumesToTheSameDepth) {
  // 1. Uninterrupted reference run.
  fs::path ref = work() / "uninterrupted";
  CommandResult r = run_cvd(run_args(ref));
  ASSERT_EQ(r.exit_code, 0) << r.output;

  // 2. The same run, killed with SIGKILL as soon as the first epoch checkpoint exists.
  fs::path out = work() / "killed";
  pid_t pid = spawn_cvd(run_args(out), work() / "killed.log");
  ASSERT_GT(pid, 0);
  fs::path index = out / "cache" / "training" / "checkpoint.json";
  int status = 0;
  bool exited = false;
  auto t0 = std::chrono::steady_clock::now();
  while (!fs::exists(index)) {
    if (waitpid(pid, &status, WNOHANG) == pid) {
      exited = true;
      break;
    }
    ASSERT_LT(std::chrono::steady_clock::now() - t0, std::chrono::minutes(10)) << "no checkpoint";
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_FALSE(exited) << "cvd finished before it could be killed:\n"
                       << slurp(work() / "killed.log");
  kill(pid, SIGKILL);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
      << "cvd was not killed during training:\n"
      << slurp(work() / "killed.log");
  EXPECT_FALSE(fs::exists(out / "run.json"));
  EXPECT_FALSE(fs::exists(out / "depth"));

  // 3. Rerun: resumes from the checkpoint and finishes.
  r = run_cvd(run_args(out));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("resuming from the checkpoint"), std::string::npos) << r.output;
  json a = read_json(ref / "run.json"), b = read_json(out / "run.json");
  EXPECT_EQ(a["training"]["resumed_from_epoch"], 0);
  EXPECT_GE(b["training"]["resumed_from_epoch"].get<int>(), 1);
  const double worst = expect_same_two_epochs(ref, out);
  std::printf("[resume] largest relative depth difference %.3g\n", worst);
}

// Streamed pairs (read from cache/flow per batch on a background thread) are the same data in
// the same order as pairs held in memory: the same losses and depth, bit for bit with the CPU
// kernels (tolerance as above); run.json says which storage a run used. With user masks, the
// masks are applied as each pair is loaded: the same pixels cleared.
TEST_F(TinyClip, StreamedPairsTrainExactlyAsPairsInMemory) {
  const fs::path masks = work() / "stream_masks";
  fs::create_directories(masks);
  // A mask on frame 2: its left third ignored.
  cv::Mat m(96, 128, CV_8U, cv::Scalar(255));
  m.colRange(0, 43).setTo(0);
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(scene() / "rgb")) names.push_back(e.path().stem());
  std::sort(names.begin(), names.end());
  ASSERT_GE(names.size(), 3u);
  ASSERT_TRUE(cv::imwrite((masks / (names[2] + ".png")).string(), m));
  json runs[2];
  const char* modes[2] = {"memory", "stream"};
  for (int k = 0; k < 2; ++k) {
    const fs::path out = work() / (std::string("pairs_") + modes[k]);
    CommandResult r = run_cvd(run_args(out) + " --masks " + q(masks) + " --pairs " + modes[k]);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    runs[k] = read_json(out / "run.json");
  }
  EXPECT_EQ(runs[0]["pairs"]["storage"], "memory");
  EXPECT_EQ(runs[1]["pairs"]["storage"], "streamed from cache/flow");
  EXPECT_GT(runs[0]["user_masks"]["flow_pixels_cleared"].get<long long>(), 0);
  EXPECT_EQ(runs[0]["user_masks"]["flow_pixels_cleared"],
            runs[1]["user_masks"]["flow_pixels_cleared"]);
  auto la = runs[0]["training"]["epoch_losses"].get<std::vector<double>>();
  auto lb = runs[1]["training"]["epoch_losses"].get<std::vector<double>>();
  ASSERT_EQ(la.size(), lb.size());
  for (size_t e = 0; e < la.size(); ++e) EXPECT_NEAR(lb[e], la[e], 1e-5 * std::abs(la[e])) << e;
  int files = 0;
  EXPECT_LE(max_relative_depth_difference(work() / "pairs_stream", work() / "pairs_memory", files),
            1e-5);
  EXPECT_EQ(files, 6);
}

TEST_F(TinyClip, InterruptPrintsWhatWasKeptAndASecondRunOnTheFolderIsRefused) {
  // Many epochs, so the run is still training when it is interrupted.
  fs::path out = work() / "interrupted";
  const fs::path log = work() / "interrupted.log";
  pid_t pid = spawn_cvd(run_args(out, 500), log);
  ASSERT_GT(pid, 0);
  fs::path index = out / "cache" / "training" / "checkpoint.json";
  int status = 0;
  auto t0 = std::chrono::steady_clock::now();
  while (!fs::exists(index)) {
    ASSERT_NE(waitpid(pid, &status, WNOHANG), pid) << "cvd ended early:\n" << slurp(log);
    ASSERT_LT(std::chrono::steady_clock::now() - t0, std::chrono::minutes(10)) << "no checkpoint";
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  // A second run on the same folder fails at once (exit 4), naming the first.
  CommandResult second = run_cvd(run_args(out, 500));
  EXPECT_EQ(second.exit_code, 4) << second.output;
  EXPECT_NE(second.output.find("in use by process " + std::to_string(pid)), std::string::npos)
      << second.output;
  // Ctrl-C: exit 130, what was kept and the command that resumes.
  kill(pid, SIGINT);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << slurp(log);
  EXPECT_EQ(WEXITSTATUS(status), 130) << slurp(log);
  const std::string text = slurp(log);
  EXPECT_NE(text.find("interrupted; kept in"), std::string::npos) << text;
  EXPECT_NE(text.find("training checkpoint after epoch"), std::string::npos) << text;
  EXPECT_NE(text.find("rerun the same command to resume: " + cli_path() + " run "),
            std::string::npos)
      << text;
  EXPECT_FALSE(fs::exists(out / "run.json"));
}

TEST_F(TinyClip, ARerunWithOtherTrainingSettingsStartsOverAndMoreEpochsContinue) {
  fs::path out = work() / "settings";
  CommandResult r = run_cvd(run_args(out, 1));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Another learning rate: the epoch-1 checkpoint does not belong to this run.
  r = run_cvd(run_args(out, 1) + " --lr 1e-3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("made with other settings"), std::string::npos) << r.output;
  EXPECT_EQ(read_json(out / "run.json")["training"]["resumed_from_epoch"], 0);
  // Same settings, one more epoch: continues from the checkpoint.
  r = run_cvd(run_args(out, 2) + " --lr 1e-3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("made with other settings"), std::string::npos) << r.output;
  EXPECT_EQ(read_json(out / "run.json")["training"]["resumed_from_epoch"], 1);
}

// Cameras estimated by the run itself (the flow's; COLMAP's go through the same text model) are
// cached as a COLMAP text model, whose rotations are quaternions. The first run uses what it
// wrote, read back, so a rerun sees the same cameras bit for bit and continues from the
// checkpoint (its key holds a checksum of the cameras) instead of starting over.
TEST_F(TinyClip, EstimatedCamerasContinueFromTheCheckpoint) {
  const fs::path out = work() / "flow_cameras";
  const std::string intr = intrinsics_flag_value(scene() / "intrinsics.json");
  auto args = [&](int epochs) {
    return "run " + q(scene() / "rgb") + " -o " + q(out) + " --epochs " + std::to_string(epochs) +
           " --warmup 1 --width 0.0625 --depth-size 64 --no-videos --no-ply --poses-source flow" +
           " --intrinsics " + intr;
  };
  CommandResult r = run_cvd(args(1));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Without --poses the defaults of the flags that need it (--given-poses auto, --sparse-points
  // flow) raise no warning.
  EXPECT_EQ(r.output.find("apply to --poses only"), std::string::npos) << r.output;
  r = run_cvd(args(2));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("made with other settings"), std::string::npos) << r.output;
  EXPECT_EQ(read_json(out / "run.json")["training"]["resumed_from_epoch"], 1);
  // Asked for explicitly, they warn that they are not used.
  r = run_cvd(args(2) + " --given-poses fixed");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("apply to --poses only"), std::string::npos) << r.output;
}

TEST_F(TinyClip, RefinedCamerasContinueFromTheCheckpointToTheSameResult) {
  // The refined cameras are part of the epoch checkpoint: one epoch, then a rerun with two,
  // ends where an uninterrupted two-epoch run does (poses, focal and depth).
  const std::string refine = " --refine-poses full --refine-focal";
  fs::path ref = work() / "refine_uninterrupted";
  CommandResult r = run_cvd(run_args(ref, 2) + refine);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  fs::path out = work() / "refine_continued";
  r = run_cvd(run_args(out, 1) + refine);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = run_cvd(run_args(out, 2) + refine);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  json a = read_json(ref / "run.json"), b = read_json(out / "run.json");
  EXPECT_EQ(b["training"]["resumed_from_epoch"], 1);
  ASSERT_TRUE(a.contains("camera_refinement")) << a.dump(2);
  const json& ca = a["camera_refinement"];
  const json& cb = b["camera_refinement"];
  EXPECT_GT(ca["rotation_change_deg"]["max"].get<double>(), 0.0) << "the cameras moved";
  EXPECT_NEAR(cb["focal_scale"].get<double>(), ca["focal_scale"].get<double>(), 1e-9);
  EXPECT_NEAR(cb["rotation_change_deg"]["mean"].get<double>(),
              ca["rotation_change_deg"]["mean"].get<double>(), 1e-6);
  // The refined focal reaches intrinsics.json; poses.txt carries the refined poses.
  json ka = read_json(ref / "intrinsics.json"), kb = read_json(out / "intrinsics.json");
  EXPECT_NEAR(kb["fx"].get<double>(), ka["fx"].get<double>(), 1e-6 * ka["fx"].get<double>());
  EXPECT_EQ(slurp(ref / "poses.txt"), slurp(out / "poses.txt"));
  int files = 0;
  double worst = max_relative_depth_difference(ref, out, files);
  EXPECT_EQ(files, 6);
  EXPECT_LE(worst, 1e-5) << "largest relative depth difference continued vs uninterrupted";
}

// A step budget (--steps) draws each epoch's batches from one running shuffle of the pairs,
// carried in the checkpoint: one epoch, then a rerun with two (the same steps per epoch), ends
// where an uninterrupted two-epoch run does. The clip has more pairs than two steps take, so the
// second epoch's batches run past the end of the first shuffle.
TEST_F(TinyClip, AStepBudgetContinuesFromTheCheckpointToTheSameResult) {
  fs::path ref = work() / "budget_uninterrupted";
  CommandResult r = run_cvd(run_args(ref, 2) + " --steps 4");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json a = read_json(ref / "run.json");
  EXPECT_EQ(a["training"]["steps_per_epoch"], 2) << a["training"].dump(2);
  EXPECT_EQ(a["training"]["pairs_per_epoch"], "step budget (--steps)");
  const int pairs = a["pairs"]["kept"].get<int>();
  ASSERT_GT(pairs, 2 * 4) << "the clip must have more pairs than one epoch of 2 steps x 4 pairs";
  ASSERT_LT(pairs, 4 * 4) << "the second epoch must run past the first shuffle";

  fs::path out = work() / "budget_continued";
  r = run_cvd(run_args(out, 1) + " --steps 2");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(read_json(out / "run.json")["training"]["steps_per_epoch"], 2);
  r = run_cvd(run_args(out, 2) + " --steps 4");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const json b = read_json(out / "run.json");
  EXPECT_EQ(b["training"]["resumed_from_epoch"], 1) << r.output;
  expect_same_two_epochs(ref, out);

  // Without the budget an epoch is every pair: another training, so the checkpoint is not used.
  r = run_cvd(run_args(out, 2));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("made with other settings"), std::string::npos) << r.output;
  EXPECT_EQ(read_json(out / "run.json")["training"]["steps_per_epoch"], (pairs + 3) / 4);
}

// Flow pairs finished in `out`: each pair's .json is written last (atomically); a dot-named
// .json is a temporary still being written (or left by a kill), not a finished pair.
std::map<std::string, fs::file_time_type> finished_flow_pairs(const fs::path& out) {
  std::map<std::string, fs::file_time_type> done;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(out / "cache" / "flow", ec)) {
    const std::string name = e.path().filename().string();
    if (e.path().extension() == ".json" && name[0] != '.') done[name] = e.last_write_time();
  }
  return done;
}

// Dot-named temporaries anywhere under `out` (pipeline/io/atomic_file.h).
int temporaries_under(const fs::path& out) {
  int n = 0;
  for (const auto& e : fs::recursive_directory_iterator(out))
    if (e.is_regular_file() && e.path().filename().string().find(".tmp-") != std::string::npos) ++n;
  return n;
}

class FlowClip : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    CommandResult r = run_cvd("scene --out " + q(dir_->path() / "scene") +
                              " --frames 10 --width 640 --height 480");
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path work() { return dir_->path(); }
  // One epoch on the smallest network; flow at the full 640x480, which dominates the run time.
  static std::string run_args(const fs::path& out) {
    fs::path scene = work() / "scene";
    const std::string intr = intrinsics_flag_value(scene / "intrinsics.json");
    return "run " + q(scene / "rgb") + " -o " + q(out) +
           " --epochs 1 --warmup 1 --width 0.0625 --depth-size 64 --no-videos --no-ply --poses " +
           q(scene / "poses.txt") + " --poses-format tum --intrinsics " + intr;
  }

 private:
  static TempDir* dir_;
};
TempDir* FlowClip::dir_ = nullptr;

TEST_F(FlowClip, KilledDuringFlowResumesToTheSameFlowAndDepth) {
  fs::path ref = work() / "uninterrupted";
  CommandResult r = run_cvd(run_args(ref));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const size_t total = finished_flow_pairs(ref).size();
  ASSERT_GE(total, 10u);

  // Killed with SIGKILL once 2 flow pairs are finished.
  fs::path out = work() / "killed";
  pid_t pid = spawn_cvd(run_args(out), work() / "killed.log");
  ASSERT_GT(pid, 0);
  int status = 0;
  bool exited = false;
  auto t0 = std::chrono::steady_clock::now();
  while (finished_flow_pairs(out).size() < 2) {
    if (waitpid(pid, &status, WNOHANG) == pid) {
      exited = true;
      break;
    }
    ASSERT_LT(std::chrono::steady_clock::now() - t0, std::chrono::minutes(10)) << "no flow pair";
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_FALSE(exited) << "cvd finished before it could be killed:\n"
                       << slurp(work() / "killed.log");
  kill(pid, SIGKILL);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << slurp(work() / "killed.log");
  auto before = finished_flow_pairs(out);
  ASSERT_LT(before.size(), total) << "the flow stage was over before the kill";
  EXPECT_FALSE(fs::exists(out / "cache" / "training" / "checkpoint.json"));
  EXPECT_FALSE(fs::exists(out / "run.json"));
  EXPECT_FALSE(fs::exists(out / "depth"));

  // Rerun: the finished pairs are kept (not recomputed), the rest computed, the run completes.
  r = run_cvd(run_args(out));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto after = finished_flow_pairs(out);
  EXPECT_EQ(after.size(), total);
  EXPECT_EQ(temporaries_under(out), 0) << "an unfinished file of the killed run was left behind";
  for (const auto& [name, time] : before) {
    ASSERT_TRUE(after.count(name)) << name;
    EXPECT_EQ(after[name], time) << name << " was recomputed instead of resumed";
  }
  // Flow files byte-identical to the uninterrupted run's (DIS is deterministic).
  int flows = 0;
  for (const auto& e : fs::directory_iterator(ref / "cache" / "flow")) {
    if (e.path().extension() != ".flo") continue;
    EXPECT_EQ(slurp(e.path()), slurp(out / "cache" / "flow" / e.path().filename()))
        << e.path().filename();
    ++flows;
  }
  EXPECT_GE(flows, 2);
  json a = read_json(ref / "run.json"), b = read_json(out / "run.json");
  EXPECT_EQ(a["pairs"], b["pairs"]);
  // Same tolerance as the training case (measured: identical).
  auto la = a["training"]["epoch_losses"].get<std::vector<double>>();
  auto lb = b["training"]["epoch_losses"].get<std::vector<double>>();
  ASSERT_EQ(la.size(), 1u);
  ASSERT_EQ(lb.size(), 1u);
  EXPECT_NEAR(lb[0], la[0], 1e-5 * std::abs(la[0]));
  int files = 0;
  double worst = max_relative_depth_difference(ref, out, files);
  EXPECT_EQ(files, 10);
  EXPECT_LE(worst, 1e-5) << "largest relative depth difference resumed vs uninterrupted";
  std::printf(
      "[resume-flow] killed after %zu of %zu pairs; %d flow files, %d depth maps, largest "
      "relative depth difference %.3g\n",
      before.size(), total, flows, files, worst);
}

TEST_F(TinyClip, InjectedNanLossStepsAreSkippedAndCounted) {
  fs::path out = work() / "nan_some";
  CommandResult r =
      run_command("CVD_FAULT_NAN_LOSS_STEPS=1,2 " + cli_path() + " " + run_args(out, 1));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("non-finite loss, step skipped"), std::string::npos) << r.output;
  json j = read_json(out / "run.json");
  EXPECT_EQ(j["training"]["skipped_steps"], 2);
  ASSERT_EQ(j["training"]["epoch_losses"].size(), 1u);
  EXPECT_TRUE(std::isfinite(j["training"]["epoch_losses"][0].get<double>()));
  EXPECT_TRUE(fs::exists(out / "depth"));
}

TEST_F(TinyClip, AllLossesNanIsANumericalErrorWithNoOutputs) {
  fs::path out = work() / "nan_all";
  CommandResult r =
      run_command("CVD_FAULT_NAN_LOSS_STEPS=all " + cli_path() + " " + run_args(out, 1));
  EXPECT_EQ(r.exit_code, 6) << r.output;
  EXPECT_NE(
      r.output.find("cvd: error: training diverged: every step of epoch 1 had a non-finite loss"),
      std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(out / "run.json"));
  EXPECT_FALSE(fs::exists(out / "depth"));
  if (size_t p = r.output.rfind("cvd: error: "); p != std::string::npos)
    std::printf("[bad-input] all_losses_nan | exit %d | %s\n", r.exit_code,
                r.output.substr(p, r.output.find('\n', p) - p).c_str());
}

}  // namespace
}  // namespace cvd::test
