// Test-time training (paper section 4.3): fine-tunes a depth network on one video with the
// geometric loss over sampled frame pairs. Adam, batches of pairs, BatchNorm in train mode,
// seeded shuffling, non-finite losses skipped and counted, a checkpoint after every epoch and
// resumption from the last one.
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "models/depth_net.h"
#include "pipeline/training/camera_refinement.h"
#include "pipeline/training/geometric_loss.h"
#include "pipeline/training/pair_source.h"
#include "pipeline/training/training_pair.h"

namespace cvd {

struct TrainingOptions {
  int epochs = 20;
  int batch_pairs = 4;
  // 0: an epoch takes every pair once. > 0: an epoch is this many steps, their pairs drawn from
  // one running shuffle (every pair once before any pair again, carried across epochs), so that
  // a long clip's thousands of pairs need not all be seen per epoch (a step budget).
  int steps_per_epoch = 0;
  double lr = 4e-4;
  GeometricLossOptions loss;  // lambda and the depth unit
  uint64_t seed = 1;
  // Where checkpoints go (empty: none). A rerun with the same directory resumes.
  std::filesystem::path checkpoint_dir;
  // What the checkpoint must have been made with (the caller's settings, serialised): a
  // checkpoint with another key is ignored and training starts over. `epochs` is not part of it,
  // so a rerun with more epochs continues.
  std::string resume_key;
  // Progress: (epoch, step, steps per epoch, running mean loss of the epoch).
  std::function<void(int, int, int, double)> on_step;
  // Called after each epoch with (epoch, mean loss).
  std::function<void(int, double)> on_epoch;
  // Polled between steps; returning true stops with Error(cancelled).
  std::function<bool()> cancelled;
  // Cameras refined with the network (null: the pairs' poses are constants). Its frame indices
  // are the pairs' frame indices; it is relinearised after every epoch and checkpointed with it.
  CameraRefinement* cameras = nullptr;
  // Test hook: stop (as if killed) after this many completed epochs; <0 = never.
  int stop_after_epochs = -1;
};

struct TrainingResult {
  std::vector<double> epoch_losses;  // mean loss per completed epoch (all epochs, resumed too)
  int skipped_steps = 0;             // steps skipped for a non-finite loss
  int resumed_from_epoch = 0;        // 0 = fresh start
  int steps = 0;                     // optimizer steps taken in this call
  // Several processes (mpirun): bytes each process all-reduced per step (depths, their
  // gradients and the gradient bucket; the batch-norm statistics are a few KB more).
  size_t bytes_per_step = 0;
};

// `load_frame(k)` returns frame k as RGB in [0, 1], [3, H, W] f32; `pairs` index into frames.
// The next batch's pairs are loaded on a background thread while a step runs.
TrainingResult train_test_time(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const PairSource& pairs, const TrainingOptions& options);
TrainingResult train_test_time(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const std::vector<TrainingPair>& pairs,
                               const TrainingOptions& options);

// Mean geometric loss with the network as it is (eval mode, no gradients), over every pair or,
// with `max_pairs` > 0 and more pairs than that, over `max_pairs` pairs evenly spaced in the
// pair order (the same ones on every call; each of their frames' depth computed once). With
// `cameras`, the loss of the refined cameras.
double evaluate_geometric_loss(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const PairSource& pairs, const GeometricLossOptions& loss,
                               const CameraRefinement* cameras = nullptr, size_t max_pairs = 0);

// The pairs evaluate_geometric_loss uses: all of `num_pairs`, or `max_pairs` evenly spaced.
std::vector<size_t> loss_evaluation_pairs(size_t num_pairs, size_t max_pairs);
double evaluate_geometric_loss(DepthNet& net, const std::function<Tensor(int)>& load_frame,
                               const std::vector<TrainingPair>& pairs,
                               const GeometricLossOptions& loss,
                               const CameraRefinement* cameras = nullptr);

}  // namespace cvd
