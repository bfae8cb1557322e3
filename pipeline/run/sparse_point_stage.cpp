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
    int kept = 0;
    for (size_t k = 0; k < flow.pairs.size(); ++k) {
      const FlowPairData p = masked.flows(k);
      kept += triangulate_flow_points(cams[p.pair.first], cams[p.pair.second], p.pair.first,
                                      p.pair.second, p.forward, p.forward_mask, st.points);
    }
    st.triangulation = {{"method", "flow pairs (no track could be triangulated)"}, {"kept", kept}};
    spdlog::warn("sparse points: no flow track could be triangulated; {} points from pairs", kept);
    if (kept == 0) {
      // Not one point: the flat start's level from every trusted flow pixel's inverse depth.
      InverseDepthSamples samples;
      for (size_t k = 0; k < flow.pairs.size(); ++k) {
        const FlowPairData p = masked.flows(k);
        add_inverse_depth_samples(cams[p.pair.first], cams[p.pair.second], p.forward,
                                  p.forward_mask, samples);
      }
      const FlowDepthLevel level = flow_depth_level(samples, cams);
      st.fallback_depth = level.depth;
      st.triangulation["fallback_level"] = level.info();
    }
  }
  return st;
}

}  // namespace cvd
