#include "pipeline/run/sparse_point_stage.h"

#include <spdlog/spdlog.h>

#include "pipeline/geometry/flow_depth_level.h"
#include "pipeline/geometry/flow_tracks.h"
#include "pipeline/geometry/flow_triangulation.h"
#include "pipeline/run/flow_pair_source.h"

namespace cvd {

SparsePointsStage run_sparse_points_stage(const PosesStage& poses, const FlowStage& flow,
                                          const std::vector<NamedCamera>& cams,
                                          const std::vector<cv::Mat>& usable) {
  SparsePointsStage st;
  st.points = poses.points;
  for (const auto& p : st.points) st.from_sfm |= !p.empty();
  if (st.from_sfm) return st;
  const size_t n = cams.size();
  st.points.resize(n);
  const FlowPairSource masked(flow, cams, usable);
  std::vector<cv::Mat> next_flow(n), next_mask(n);
  for (size_t k = 0; k < flow.pairs.size(); ++k)
    if (flow.pairs[k].pair.second == flow.pairs[k].pair.first + 1) {
      const FlowPairData p = masked.flows(k);  // consecutive pairs stay in memory
      next_flow[size_t(p.pair.first)] = p.forward;
      next_mask[size_t(p.pair.first)] = p.forward_mask;
    }
  // Fewer tracks kept than frames: a slow clip; longer tracks are tried.
  const FlowTrackStats ts = triangulate_flow_tracks_lengthening(cams, next_flow, next_mask,
                                                                st.points, static_cast<int>(n));
  st.triangulation = {{"method", "flow tracks"},
                      {"tracks", ts.tracks},
                      {"kept", ts.kept},
                      {"max_track_length", ts.max_length}};
  spdlog::info("sparse points: {} of {} flow tracks triangulated (tracks of up to {} frames)",
               ts.kept, ts.tracks, ts.max_length);
  if (ts.kept == 0) {
    // Pair by pair; each trusted pixel's inverse depth is gathered in the same pass (flows are
    // streamed from the cache), for the flat start's level should not one point be kept.
    int kept = 0;
    InverseDepthSamples samples;
    for (size_t k = 0; k < flow.pairs.size(); ++k) {
      const FlowPairData p = masked.flows(k);
      const NamedCamera &ci = cams[p.pair.first], &cj = cams[p.pair.second];
      kept += triangulate_flow_points(ci, cj, p.pair.first, p.pair.second, p.forward,
                                      p.forward_mask, st.points);
      add_inverse_depth_samples(ci, cj, p.forward, p.forward_mask, samples);
    }
    st.triangulation = {{"method", "flow pairs (no track could be triangulated)"}, {"kept", kept}};
    spdlog::warn("sparse points: no flow track could be triangulated; {} points from pairs", kept);
    if (kept == 0) {
      const FlowDepthLevel level = flow_depth_level(samples, cams);
      st.fallback_depth = level.depth;
      st.triangulation["fallback_level"] = level.info();
    }
  }
  return st;
}

}  // namespace cvd
