#include "pipeline/run/pair_camera_check.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <utility>

#include "engine/error.h"
#include "pipeline/geometry/epipolar_distance.h"

namespace cvd {

using json = nlohmann::json;

std::vector<PairDistances> measure_pairs_against_cameras(
    const FlowStage& flow, const std::vector<std::vector<NamedCamera>>& camera_sets) {
  std::vector<PairDistances> out(camera_sets.size());
  for (auto& d : out) d.px.assign(flow.pairs.size(), -1.0);
  for (size_t k = 0; k < flow.pairs.size(); ++k) {
    const FramePair p = flow.pairs[k].pair;
    const FlowPairData d = flow.load(k);  // from the cache when streamed
    for (size_t s = 0; s < camera_sets.size(); ++s) {
      const std::vector<NamedCamera>& cams = camera_sets[s];
      out[s].long_side = std::max({out[s].long_side, d.forward.cols, d.forward.rows});
      out[s].px[k] = median_epipolar_distance(d.forward, d.forward_mask, cams[size_t(p.first)],
                                              cams[size_t(p.second)]);
    }
  }
  return out;
}

json check_pairs_against_cameras(const RunOptions& o, FlowStage& flow,
                                 const std::vector<NamedCamera>& cams,
                                 const std::vector<std::string>& frame_names,
                                 const PairDistances* measured) {
  CVD_CHECK(o.epipolar_check == "warn" || o.epipolar_check == "drop" || o.epipolar_check == "off",
            "epipolar_check must be warn, drop or off, got '{}'", o.epipolar_check);
  if (o.epipolar_check == "off" || flow.pairs.empty()) return {{"mode", o.epipolar_check}};
  const bool drop = o.epipolar_check == "drop";
  PairDistances own;  // measured here when not handed in
  if (!measured) own = std::move(measure_pairs_against_cameras(flow, {cams}).front());
  const PairDistances& measure = measured ? *measured : own;
  CVD_CHECK(measure.px.size() == flow.pairs.size(),
            "pairs: {} epipolar distances measured for {} pairs", measure.px.size(),
            flow.pairs.size());
  const std::vector<double>& distances = measure.px;
  const EpipolarCheck check = check_epipolar_distances(distances, measure.long_side);
  json named = json::array();
  std::vector<FlowPairData> kept;
  size_t worst = flow.pairs.size();
  for (size_t k = 0; k < flow.pairs.size(); ++k) {
    if (!check.drop[k]) {
      kept.push_back(std::move(flow.pairs[k]));
      continue;
    }
    const FramePair p = flow.pairs[k].pair;
    named.push_back({{"pair", {frame_names[size_t(p.first)], frame_names[size_t(p.second)]}},
                     {"px", distances[k]}});
    if (worst == flow.pairs.size() || distances[k] > distances[worst]) worst = k;
    if (!drop) kept.push_back(std::move(flow.pairs[k]));
  }
  json r = {{"mode", o.epipolar_check},
            {"measure",
             "median Sampson distance of the forward flow's consistent pixels from the "
             "cameras' epipolar geometry, in depth-resolution pixels"},
            {"median_px", check.median_px},
            {"threshold_px", check.threshold_px},
            {"pairs_checked", flow.pairs.size()},
            {"contradicting", named},
            {"dropped", drop ? named.size() : 0},
            {"above_threshold_not_named", check.capped}};
  if (!named.empty()) {
    const FramePair w = flow.pairs[worst].pair;
    spdlog::warn(
        "pairs: {} of {} frame pairs contradict their cameras (median epipolar distance above "
        "{:.2f} px, {:.1f}x the clip's median; worst {} -> {}: {:.2f} px){}; the poses may jump "
        "between some frames (run.json: pairs.epipolar_check)",
        named.size(), flow.pairs.size(), check.threshold_px,
        check.threshold_px / std::max(check.median_px, 1e-12), frame_names[size_t(w.first)],
        frame_names[size_t(w.second)], distances[worst],
        drop ? " and were left out of the sparse points and training"
             : "; --epipolar-check drop leaves them out of training");
  }
  if (check.capped > 0)
    spdlog::warn(
        "pairs: {} more pairs are above the epipolar threshold (the check names at most a "
        "quarter of the pairs): the cameras disagree with much of the flow",
        check.capped);
  if (drop) flow.dropped_epipolar = static_cast<int>(named.size());
  flow.pairs = std::move(kept);
  CVD_CHECK(!flow.pairs.empty(), "pairs: the epipolar check left no pair");
  return r;
}

}  // namespace cvd
