#include "pipeline/training/test_time_training.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <future>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>

#include "engine/adam.h"
#include "engine/autograd.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "engine/process_group.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/training/data_parallel_step.h"

namespace cvd {

namespace {

namespace fs = std::filesystem;

struct Checkpoint {
  int epoch = 0;
  std::string rng_state;
  std::vector<double> losses;
  int skipped = 0;
  std::string key;
  nlohmann::json cameras;  // CameraRefinement::state(), null when cameras are not refined
  // Steps per epoch set (TrainingOptions::steps_per_epoch): the running shuffle of the pairs and
  // how far the epochs so far have drawn from it.
  std::vector<size_t> order;
  size_t cursor = 0;
};

fs::path weights_path(const fs::path& dir, int epoch) {
  return dir / ("checkpoint_epoch" + std::to_string(epoch) + "_weights.cvdw");
}
fs::path optim_path(const fs::path& dir, int epoch) {
  return dir / ("checkpoint_epoch" + std::to_string(epoch) + "_adam.cvdw");
}

// The index file is written last (atomically), so it always names a complete checkpoint.
void save_checkpoint(const fs::path& dir, DepthNet& net, const Adam& adam, const Checkpoint& c) {
  fs::create_directories(dir);
  save_weights(net, weights_path(dir, c.epoch), net.arch());
  adam.save(optim_path(dir, c.epoch));
  nlohmann::json j = {{"epoch", c.epoch},
                      {"rng_state", c.rng_state},
                      {"epoch_losses", c.losses},
                      {"skipped_steps", c.skipped},
                      {"key", c.key}};
  if (!c.cameras.is_null()) j["cameras"] = c.cameras;
  if (!c.order.empty()) {
    j["pair_order"] = c.order;
    j["pair_cursor"] = c.cursor;
  }
  write_text_file(dir / "checkpoint.json", j.dump(2));
  for (int e = 0; e < c.epoch; ++e) {
    std::error_code ec;
    fs::remove(weights_path(dir, e), ec);
    fs::remove(optim_path(dir, e), ec);
  }
}

bool load_checkpoint(const fs::path& dir, DepthNet& net, Adam& adam, Checkpoint& c) {
  fs::path index = dir / "checkpoint.json";
  if (dir.empty() || !fs::exists(index)) return false;
  std::ifstream in(index);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
    c.epoch = j.at("epoch").get<int>();
    c.rng_state = j.at("rng_state").get<std::string>();
    c.losses = j.at("epoch_losses").get<std::vector<double>>();
    c.skipped = j.at("skipped_steps").get<int>();
    if (j.contains("cameras")) c.cameras = j.at("cameras");
    if (j.contains("pair_order")) {
      c.order = j.at("pair_order").get<std::vector<size_t>>();
      c.cursor = j.at("pair_cursor").get<size_t>();
    }
    const std::string stored = j.value("key", std::string());
    if (stored != c.key) {
      spdlog::warn(
          "training: the checkpoint in {} was made with other settings; training starts over",
          dir.string());
      c = Checkpoint{0, {}, {}, 0, c.key, nullptr, {}, 0};
      return false;
    }
  } catch (const nlohmann::json::exception& e) {
    fail(ErrorCategory::format, "{}: malformed checkpoint index ({}); delete it to start over",
         index.string(), e.what());
  }
  load_weights(net, weights_path(dir, c.epoch), true);
  adam.load(optim_path(dir, c.epoch));
  return true;
}

std::vector<Tensor> camera_parameters(const CameraRefinement& cameras) {
  std::vector<Tensor> all;
  for (const auto& group : {cameras.rotation_parameters(), cameras.translation_parameters(),
                            cameras.focal_parameters()})
    all.insert(all.end(), group.begin(), group.end());
  return all;
}

// The cameras' parameter groups, each with its own step size.
void add_camera_groups(Adam& adam, const CameraRefinement& cameras, const AdamOptions& base) {
  const CameraRefinementOptions& co = cameras.options();
  std::pair<std::vector<Tensor>, double> groups[] = {
      {cameras.rotation_parameters(), co.lr_rotation},
      {cameras.translation_parameters(), co.lr_translation},
      {cameras.focal_parameters(), co.lr_focal}};
  for (auto& [params, lr] : groups) {
    if (params.empty()) continue;
    AdamOptions ao = base;
    ao.lr = lr;
    adam.add_param_group(params, ao);
  }
}

// Fault injection for the reliability tests: CVD_FAULT_NAN_LOSS_STEPS="1,3" treats the loss of
// those training steps (1-based, counted over all epochs: epoch e's step s is
// (e - 1) * steps_per_epoch + s) as NaN; "all" makes every loss NaN. Unset: no effect.
struct NanLossFault {
  bool all = false;
  std::vector<int> steps;
  bool hits(int step) const {
    return all || std::find(steps.begin(), steps.end(), step) != steps.end();
  }
};

NanLossFault nan_loss_fault_from_env() {
  NanLossFault f;
  const char* v = std::getenv("CVD_FAULT_NAN_LOSS_STEPS");
  if (!v || !*v) return f;
  std::string s(v);
  if (s == "all") {
    f.all = true;
  } else {
    size_t pos = 0;
    while (pos <= s.size()) {
      size_t end = s.find(',', pos);
      if (end == std::string::npos) end = s.size();
      std::string item = s.substr(pos, end - pos);
      try {
        f.steps.push_back(std::stoi(item));
      } catch (...) {
        fail(ErrorCategory::invalid_argument,
             "CVD_FAULT_NAN_LOSS_STEPS='{}': '{}' is not a step number (use e.g. 1,3 or all)", s,
             item);
      }
      pos = end + 1;
    }
  }
  spdlog::warn("fault injection: CVD_FAULT_NAN_LOSS_STEPS={} (these training losses become NaN)",
               s);
  return f;
}

// Fault injection for the multi-process tests: CVD_FAULT_KILL_RANK="1:3" makes rank 1 kill
// itself (SIGKILL, no clean-up) at training step 3 (counted as for CVD_FAULT_NAN_LOSS_STEPS).
void maybe_kill_this_rank(int step) {
  static const std::pair<int, int> fault = [] {
    const char* v = std::getenv("CVD_FAULT_KILL_RANK");
    int rank = -1, at = -1;
    if (v && std::sscanf(v, "%d:%d", &rank, &at) != 2)
      fail(ErrorCategory::invalid_argument, "CVD_FAULT_KILL_RANK='{}': expected RANK:STEP", v);
    return std::pair<int, int>{rank, at};
  }();
  if (fault.first == process_group().rank() && fault.second == step) {
    spdlog::warn("fault injection: CVD_FAULT_KILL_RANK kills rank {} at step {}", fault.first,
                 step);
    std::raise(SIGKILL);
  }
}

}  // namespace

TrainingResult train_test_time(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const std::vector<TrainingPair>& pairs, const TrainingOptions& o) {
  return train_test_time(net, load_frame, PairsInMemory(pairs), o);
}

double evaluate_geometric_loss(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const std::vector<TrainingPair>& pairs,
                               const GeometricLossOptions& loss, const CameraRefinement* cameras) {
  return evaluate_geometric_loss(net, load_frame, PairsInMemory(pairs), loss, cameras);
}

TrainingResult train_test_time(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const PairSource& pairs, const TrainingOptions& o) {
  CVD_CHECK(pairs.size() > 0, "test-time training needs at least one frame pair");
  CVD_CHECK(o.batch_pairs >= 1 && o.epochs >= 0 && o.lr > 0 && o.steps_per_epoch >= 0,
            "bad training options");
  AdamOptions ao;
  ao.lr = o.lr;
  ao.beta1 = 0.9;
  ao.beta2 = 0.999;
  Adam adam(net.parameters(), ao);
  const size_t camera_groups_from = adam.num_groups();
  if (o.cameras) add_camera_groups(adam, *o.cameras, ao);
  std::vector<double> camera_lrs;
  for (size_t g = camera_groups_from; g < adam.num_groups(); ++g) camera_lrs.push_back(adam.lr(g));
  Generator rng(o.seed);
  TrainingResult result;
  Checkpoint ck;
  ck.key = o.resume_key;
  if (load_checkpoint(o.checkpoint_dir, net, adam, ck)) {
    if (o.cameras) {
      if (ck.cameras.is_null())
        fail(ErrorCategory::format, "{}: the checkpoint has no refined cameras; delete it",
             o.checkpoint_dir.string());
      o.cameras->load_state(ck.cameras);
    }
    rng.set_state(ck.rng_state);
    result.epoch_losses = ck.losses;
    result.skipped_steps = ck.skipped;
    result.resumed_from_epoch = ck.epoch;
    spdlog::info("training: resuming from the checkpoint after epoch {} in {}", ck.epoch,
                 o.checkpoint_dir.string());
  }
  const GeometricLossOptions& lo = o.loss;
  const NanLossFault nan_fault = nan_loss_fault_from_env();
  net.train(true);
  ProcessGroup& pg = process_group();
  std::vector<Tensor> trained = net.parameters();
  if (o.cameras)
    for (const Tensor& t : camera_parameters(*o.cameras)) trained.push_back(t);
  const size_t bp = static_cast<size_t>(o.batch_pairs);
  const bool budget = o.steps_per_epoch > 0;
  const int steps_per_epoch =
      budget ? o.steps_per_epoch : static_cast<int>((pairs.size() + bp - 1) / bp);
  // A step budget draws its batches from one running shuffle (every pair once before any pair
  // again), carried across epochs and checkpoints.
  std::vector<size_t> order = ck.order;
  size_t cursor = ck.cursor;
  if (budget && order.size() != pairs.size()) {
    order.resize(pairs.size());
    cursor = pairs.size();  // shuffled on the first draw
  }
  for (int epoch = ck.epoch; epoch < o.epochs; ++epoch) {
    // The cameras join after their start epoch (step size 0 before; Adam's moments stay zero).
    for (size_t g = 0; g < camera_lrs.size(); ++g)
      adam.set_lr(camera_groups_from + g,
                  epoch >= o.cameras->options().start_epoch ? camera_lrs[g] : 0.0);
    // The pair indices of each step of this epoch.
    std::vector<std::vector<size_t>> batches(static_cast<size_t>(steps_per_epoch));
    if (!budget) {
      std::vector<size_t> shuffled(pairs.size());
      for (size_t k = 0; k < shuffled.size(); ++k) shuffled[k] = k;
      std::shuffle(shuffled.begin(), shuffled.end(), rng.engine());
      for (size_t k = 0; k < shuffled.size(); ++k) batches[k / bp].push_back(shuffled[k]);
    } else {
      for (auto& b : batches)
        while (b.size() < std::min(bp, pairs.size())) {
          if (cursor >= order.size()) {
            for (size_t k = 0; k < order.size(); ++k) order[k] = k;
            std::shuffle(order.begin(), order.end(), rng.engine());
            cursor = 0;
          }
          b.push_back(order[cursor++]);
        }
    }
    double sum = 0;
    int counted = 0;
    // The pairs of step s, loaded on a background thread one step ahead.
    auto load_batch = [&pairs, &batches](size_t s) {
      std::vector<TrainingPair> b;
      for (size_t k : batches[s]) b.push_back(pairs.load(k));
      return b;
    };
    std::future<std::vector<TrainingPair>> next =
        std::async(std::launch::async, load_batch, size_t(0));
    for (int s = 0; s < steps_per_epoch; ++s) {
      const std::vector<TrainingPair> loaded = next.get();
      if (s + 1 < steps_per_epoch) next = std::async(std::launch::async, load_batch, size_t(s + 1));
      std::vector<const TrainingPair*> batch;
      for (const TrainingPair& p : loaded) batch.push_back(&p);
      adam.zero_grad();
      maybe_kill_this_rank(epoch * steps_per_epoch + s + 1);
      const bool inject_nan = nan_fault.hits(epoch * steps_per_epoch + s + 1);
      const BatchStep step = batch_gradients(net, load_frame, batch, lo, o.cameras, trained,
                                             o.cancelled && o.cancelled(), inject_nan);
      if (step.stop) fail(ErrorCategory::cancelled, "training cancelled");
      const double v = step.loss;
      if (!step.applied) {
        ++result.skipped_steps;
        spdlog::warn("training: epoch {} step {}: non-finite loss, step skipped", epoch + 1, s + 1);
        continue;
      }
      result.bytes_per_step = step.bytes_all_reduced;
      adam.step();
      ++result.steps;
      sum += v;
      ++counted;
      if (o.on_step) o.on_step(epoch + 1, s + 1, steps_per_epoch, sum / counted);
    }
    if (counted == 0)
      fail(ErrorCategory::numerical,
           "training diverged: every step of epoch {} had a non-finite loss ({} steps skipped in "
           "all); try a lower --lr, or check the poses and flow",
           epoch + 1, result.skipped_steps);
    if (pg.size() > 1) {
      // Every process took the same steps; rank 0's values remove any rounding difference
      // between the processes' sums, and its batch-norm statistics count the steps that ran on
      // rank 0 alone (fewer frames than processes).
      broadcast_module(net, 0);
      if (o.cameras) broadcast_tensors(camera_parameters(*o.cameras), 0);
    }
    if (o.cameras) o.cameras->relinearize();
    double mean_loss = sum / counted;
    result.epoch_losses.push_back(mean_loss);
    if (o.on_epoch) o.on_epoch(epoch + 1, mean_loss);
    if (!o.checkpoint_dir.empty() && pg.rank() == 0) {  // rank 0 writes, for every process
      ck.epoch = epoch + 1;
      ck.rng_state = rng.state();
      ck.losses = result.epoch_losses;
      ck.skipped = result.skipped_steps;
      if (budget) {
        ck.order = order;
        ck.cursor = cursor;
      }
      if (o.cameras) ck.cameras = o.cameras->state();
      save_checkpoint(o.checkpoint_dir, net, adam, ck);
    }
    if (o.stop_after_epochs >= 0 && epoch + 1 >= o.stop_after_epochs) break;
  }
  return result;
}

std::vector<size_t> loss_evaluation_pairs(size_t num_pairs, size_t max_pairs) {
  const size_t m = max_pairs > 0 ? std::min(num_pairs, max_pairs) : num_pairs;
  std::vector<size_t> chosen(m);
  for (size_t i = 0; i < m; ++i) chosen[i] = i * num_pairs / m;  // strictly increasing
  return chosen;
}

double evaluate_geometric_loss(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const PairSource& pairs, const GeometricLossOptions& lo,
                               const CameraRefinement* cameras, size_t max_pairs) {
  NoGradGuard ng;
  bool was_training = net.is_training();
  net.eval();
  std::map<int, Tensor> cache;
  double sum = 0;
  const std::vector<size_t> chosen = loss_evaluation_pairs(pairs.size(), max_pairs);
  // Every R-th chosen pair on each process, the sum over processes.
  ProcessGroup& pg = process_group();
  for (size_t c = static_cast<size_t>(pg.rank()); c < chosen.size(); c += size_t(pg.size())) {
    const TrainingPair p = pairs.load(chosen[c]);
    for (int f : {p.i, p.j})
      if (!cache.count(f)) cache[f] = net.depth(load_frame(f).unsqueeze(0)).squeeze(0).squeeze(0);
    sum += pair_loss(cache[p.i], cache[p.j], p, lo, cameras).item();
  }
  pg.all_reduce_sum(&sum, 1);
  net.train(was_training);
  return chosen.empty() ? 0.0 : sum / static_cast<double>(chosen.size());
}

}  // namespace cvd
