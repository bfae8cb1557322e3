#include "pipeline/training/network_start.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "engine/adam.h"
#include "engine/autograd.h"
#include "engine/error.h"
#include "engine/ops.h"
#include "engine/random.h"
#include "pipeline/geometry/median.h"

namespace cvd {

namespace {

// The warm-up's training and held-out points, frame by frame.
struct SparseSplit {
  std::vector<SparseDepth> train, held_out;
  std::vector<int> train_frames, held_out_frames;  // frames with points on each side
  std::string how;
};

void append_point(SparseDepth& s, const SparseDepth& from, size_t k) {
  s.u.push_back(from.u[k]);
  s.v.push_back(from.v[k]);
  s.z.push_back(from.z[k]);
}

SparseSplit split_sparse(const std::vector<SparseDepth>& sparse) {
  constexpr size_t kMinPoints = 8;
  // Each check runs the network on every held-out frame: on long clips (a 2,000-frame clip whose
  // flow tracks reach every frame) every 4th frame made the checks cost more than the warm-up.
  constexpr size_t kMaxHeldOutFrames = 64;
  SparseSplit s;
  s.train.resize(sparse.size());
  s.held_out.resize(sparse.size());
  std::vector<int> usable;
  for (size_t k = 0; k < sparse.size(); ++k)
    if (sparse[k].z.size() >= kMinPoints) usable.push_back(static_cast<int>(k));
  if (usable.size() >= 4) {
    // Whole frames held out: a warm-up that fits one frame's points (or their frame-to-frame
    // scale drift) rather than what images show does not carry over to other frames.
    const size_t every =
        std::max<size_t>(4, (usable.size() + kMaxHeldOutFrames - 1) / kMaxHeldOutFrames);
    for (size_t q = 0; q < usable.size(); ++q) {
      const int f = usable[q];
      if (q % every == every - 1) {
        s.held_out[f] = sparse[f];
        s.held_out_frames.push_back(f);
      } else {
        s.train[f] = sparse[f];
        s.train_frames.push_back(f);
      }
    }
    s.how = fmt::format("every {}th frame with sparse points held out", every);
  } else {
    for (int f : usable) {
      for (size_t k = 0; k < sparse[f].z.size(); ++k)
        append_point(k % 5 == 4 ? s.held_out[f] : s.train[f], sparse[f], k);
      s.train_frames.push_back(f);
      s.held_out_frames.push_back(f);
    }
    s.how = "every 5th sparse point held out (fewer than 4 frames have points)";
  }
  return s;
}

// The warm-up loss of a batch of depth maps [B, 1, H, W] at the points of `frames`: the mean over
// frames of mean |log D - log z|, or, scale-free, of mean |r - mean r| (r = log D - log z) plus
// |mean over frames of mean r| (one level for the batch, none per frame).
Tensor sparse_loss(const Tensor& depth, const std::vector<SparseDepth>& points,
                   const std::vector<int>& frames, bool scale_free) {
  const int64_t H = depth.size(2), W = depth.size(3);
  Tensor total, level;
  for (size_t b = 0; b < frames.size(); ++b) {
    const SparseDepth& s = points[frames[b]];
    const int64_t n = static_cast<int64_t>(s.z.size());
    std::vector<double> g(2 * n), lz(n);
    for (int64_t k = 0; k < n; ++k) {
      g[2 * k] = 2.0 * s.u[k] / std::max<int64_t>(W - 1, 1) - 1.0;
      g[2 * k + 1] = 2.0 * s.v[k] / std::max<int64_t>(H - 1, 1) - 1.0;
      lz[k] = std::log(s.z[k]);
    }
    Tensor grid = Tensor::from_vector(g, {1, 1, n, 2});
    Tensor d = grid_sample(depth.narrow(0, static_cast<int64_t>(b), 1), grid,
                           GridSampleParams{GridPadding::border, true})
                   .reshape({n});
    Tensor r = sub(log(d), Tensor::from_vector(lz, {n}));
    Tensor l;
    if (scale_free) {
      Tensor c = mean(r, {0}, true);
      l = mean(abs(sub(r, c)));
      level = level.defined() ? add(level, c) : c;
    } else {
      l = mean(abs(r));
    }
    total = total.defined() ? add(total, l) : l;
  }
  const double inv = 1.0 / static_cast<double>(frames.size());
  total = mul_scalar(total, inv);
  if (scale_free) total = add(total, abs(mul_scalar(level, inv)).reshape({}));
  return total;
}

// The held-out error of the network as it is now (eval mode, one frame at a time).
double held_out_error(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                      const SparseSplit& split, bool scale_free) {
  NoGradGuard ng;
  const bool was_training = net.is_training();
  net.eval();
  double sum = 0;
  int count = 0;
  for (int f : split.held_out_frames) {
    if (split.held_out[f].z.empty()) continue;
    Tensor depth = net.depth(load_frame(f).unsqueeze(0));
    sum += sparse_loss(depth, split.held_out, {f}, scale_free).item();
    ++count;
  }
  net.train(was_training);
  return count ? sum / count : 0.0;
}

std::map<std::string, Tensor> copy_state(const DepthNet& net) {
  std::map<std::string, Tensor> state;
  for (const auto& [name, t] : net.state_dict()) state[name] = t.clone();
  return state;
}

}  // namespace

nlohmann::json start_default_network(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                                     const std::vector<SparseDepth>& sparse,
                                     const NetworkStartOptions& o,
                                     std::vector<std::string>* warnings) {
  nlohmann::json info;
  std::vector<double> all;
  for (const SparseDepth& s : sparse) all.insert(all.end(), s.z.begin(), s.z.end());
  double level_depth = upper_median(all);
  if (all.empty()) {
    level_depth = o.fallback_depth;
    const std::string w = fmt::format(
        "no sparse 3-D points (SfM gave none, or the baseline is too small to triangulate the "
        "flow): the default network starts as a flat plane at depth {} (units of the poses) and "
        "test-time training alone shapes it",
        level_depth);
    spdlog::warn("{}", w);
    if (warnings) warnings->push_back(w);
  }
  // The flat plane: a zero head, so the output is the bias everywhere.
  {
    NoGradGuard ng;
    net.output_weight().zero_();
    const double level =
        net.output_kind() == DepthOutputKind::log_depth ? std::log(level_depth) : 1.0 / level_depth;
    net.output_bias().fill_(level);
  }
  info["initial_depth_level"] = level_depth;
  info["initial_depth_source"] = all.empty() ? "fallback" : "median sparse depth";
  info["start"] = "flat plane";
  info["warmup_steps"] = 0;

  const SparseSplit split = split_sparse(sparse);
  if (o.warmup_steps <= 0 || split.train_frames.empty() || split.held_out_frames.empty())
    return info;

  const double flat_error = held_out_error(net, load_frame, split, o.scale_free_per_frame);
  double best_error = flat_error;
  int best_step = 0;
  std::map<std::string, Tensor> best_state;  // empty: the flat plane (the state set above)
  const std::map<std::string, Tensor> flat_state = copy_state(net);
  nlohmann::json checks = nlohmann::json::array();
  checks.push_back({{"step", 0}, {"held_out_error", flat_error}});

  AdamOptions ao;
  ao.lr = o.lr;
  Adam adam(net.parameters(), ao);
  Generator rng(o.seed + 17);
  net.train(true);
  const int check_every = std::max(10, o.warmup_steps / 8);
  const int batch_size = std::min<int>(4, static_cast<int>(split.train_frames.size()));
  double last = 0;
  for (int step = 1; step <= o.warmup_steps; ++step) {
    std::vector<int> batch;
    std::vector<Tensor> imgs;
    for (int b = 0; b < batch_size; ++b) {
      const int f = split.train_frames[static_cast<size_t>(
          rng.randint(0, static_cast<int64_t>(split.train_frames.size())))];
      batch.push_back(f);
      imgs.push_back(load_frame(f).unsqueeze(0));
    }
    Tensor loss =
        sparse_loss(net.depth(concat(imgs, 0)), split.train, batch, o.scale_free_per_frame);
    adam.zero_grad();
    last = loss.item();
    if (std::isfinite(last)) {
      loss.backward();
      adam.step();
    }
    if (step % check_every == 0 || step == o.warmup_steps) {
      const double e = held_out_error(net, load_frame, split, o.scale_free_per_frame);
      checks.push_back({{"step", step}, {"held_out_error", e}});
      if (e < best_error) {
        best_error = e;
        best_step = step;
        best_state = copy_state(net);
      }
    }
    if (o.progress) {
      o.progress(step, o.warmup_steps,
                 fmt::format("sparse loss {:.4f}, held-out best {:.4f} (flat {:.4f})", last,
                             best_error, flat_error));
    }
  }
  const LoadStateReport r = net.load_state(best_state.empty() ? flat_state : best_state);
  CVD_ASSERT(r.missing.empty() && r.unexpected.empty());
  info["warmup_steps"] = o.warmup_steps;
  info["warmup_final_loss"] = last;
  info["warmup_held_out"] = split.how;
  info["warmup_held_out_frames"] = split.held_out_frames.size();
  info["warmup_loss"] =
      o.scale_free_per_frame ? "log depth up to one scale per frame" : "absolute log depth";
  info["warmup_checks"] = checks;
  info["warmup_kept_step"] = best_step;
  info["held_out_error_flat_plane"] = flat_error;
  info["held_out_error_kept"] = best_error;
  info["start"] = best_step == 0 ? "flat plane (the warm-up did not beat it on held-out points)"
                                 : fmt::format("warm-up, step {}", best_step);
  spdlog::info("default network start: {} (held-out sparse error {:.4f}, flat plane {:.4f})",
               info["start"].get<std::string>(), best_error, flat_error);
  return info;
}

}  // namespace cvd
