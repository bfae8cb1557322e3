// Stage 4b of run_pipeline: the flow pairs whose flow contradicts their cameras
// (pipeline/geometry/epipolar_distance.h), named in a warning and, on request, left out of the
// sparse points and of training. Given poses from another sensor can jump between two frames (a
// tracking glitch); every pair across the jump then asks the depth for the impossible.
//
// Measured on 7-Scenes kitchen frames 0-149 every 3rd with its poses (one documented glitch
// between frames 121 and 122; README "Pairs that contradict their cameras"): dropping the five
// pairs the check names helps short training (4 epochs at 192 px: AbsRel 0.138 / 0.169 per
// frame / video -> 0.122 / 0.125) and hurts the default preset's (16 epochs at 256 px: 0.094 /
// 0.103 -> 0.114 / 0.118 and 0.093 / 0.103 -> 0.102 / 0.106 over two seeds): those pairs span
// the widest baselines near the glitch and still constrain depth. So the default only warns.
#pragma once
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

#include "pipeline/run/run_stages.h"

namespace cvd {

// Every kept pair of a FlowStage measured against one camera set.
struct PairDistances {
  std::vector<double> px;  // per pair, in flow.pairs' order; negative: nothing to measure
  int long_side = 0;       // of the flows' images, pixels
};

// Measures every kept pair of `flow` against each of `camera_sets` (at the depth resolution;
// indices are frame indices) in one pass over the pairs, so each pair's flow is loaded once
// (from the cache when streamed) however many sets are compared.
std::vector<PairDistances> measure_pairs_against_cameras(
    const FlowStage& flow, const std::vector<std::vector<NamedCamera>>& camera_sets);

// Measures every kept pair of `flow` against `cams` unless o.epipolar_check is "off" (or takes
// `measured`, that measure already made against these cameras), warns naming the pairs that
// contradict them and, with "drop", removes those pairs. Returns the record for run.json
// (pairs.epipolar_check).
nlohmann::json check_pairs_against_cameras(const RunOptions& o, FlowStage& flow,
                                           const std::vector<NamedCamera>& cams,
                                           const std::vector<std::string>& frame_names,
                                           const PairDistances* measured = nullptr);

}  // namespace cvd
