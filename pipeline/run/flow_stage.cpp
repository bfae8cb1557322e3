// The flow stage of a run (pipeline/run/run_stages.h): the paper's pair hierarchy over the
// registered frames, DIS (or FlowNet2) flow with the forward-backward check per pair, cached at the
// depth resolution in OUT/cache/flow and reread from there (or streamed from it during training).
#include <spdlog/spdlog.h>

#include <map>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/elapsed_time.h"
#include "engine/error.h"
#include "engine/process_group.h"
#include "pipeline/flow/flow_dis.h"
#include "pipeline/flow/flow_flownet2.h"
#include "pipeline/flow/flow_pair.h"
#include "pipeline/flow/pair_sampling.h"
#include "pipeline/io/atomic_file.h"
#include "pipeline/io/flow_io.h"
#include "pipeline/run/run_stages.h"

namespace cvd {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

cv::Mat resize_flow(const cv::Mat& flow, cv::Size size) {
  cv::Mat r;
  cv::resize(flow, r, size, 0, 0, cv::INTER_LINEAR);
  double sx = double(size.width) / flow.cols, sy = double(size.height) / flow.rows;
  for (int y = 0; y < r.rows; ++y)
    for (int x = 0; x < r.cols; ++x) {
      auto& v = r.at<cv::Vec2f>(y, x);
      v[0] = static_cast<float>(v[0] * sx);
      v[1] = static_cast<float>(v[1] * sy);
    }
  return r;
}

cv::Mat resize_mask(const cv::Mat& m, cv::Size size) {
  cv::Mat r;
  cv::resize(m, r, size, 0, 0, cv::INTER_NEAREST);
  return r;
}

}  // namespace

namespace {

void read_cached_flows(const fs::path& dir, const std::string& stem, FlowPairData& d) {
  d.forward = read_flo(dir / (stem + ".fwd.flo"));
  d.backward = read_flo(dir / (stem + ".bwd.flo"));
  for (auto [suffix, mat] :
       {std::pair{".fwd_mask.png", &d.forward_mask}, {".bwd_mask.png", &d.backward_mask}}) {
    const fs::path mp = dir / (stem + suffix);
    *mat = cv::imread(mp.string(), cv::IMREAD_GRAYSCALE);
    if (mat->empty())
      fail(ErrorCategory::io, "{}: cached flow mask missing or unreadable", mp.string());
  }
}

// A flow as the run holds it: CV_16FC2 when `half`, else as it is (CV_32FC2).
cv::Mat held_flow(const cv::Mat& flow, bool half) {
  if (!half || flow.empty() || flow.depth() == CV_16F) return flow;
  cv::Mat h;
  flow.convertTo(h, CV_16F);
  return h;
}

// A held flow as training and triangulation read it: CV_32FC2.
cv::Mat full_flow(const cv::Mat& flow) {
  if (flow.empty() || flow.depth() == CV_32F) return flow;
  cv::Mat f;
  flow.convertTo(f, CV_32F);
  return f;
}

}  // namespace

FlowPairData FlowStage::load(size_t k) const {
  CVD_CHECK(k < pairs.size(), "flow pair {} of {}", k, pairs.size());
  FlowPairData d = pairs[k];
  if (d.forward.empty()) {
    read_cached_flows(dir, d.stem, d);
    d.forward = held_flow(d.forward, half_precision);
    d.backward = held_flow(d.backward, half_precision);
  }
  d.forward = full_flow(d.forward);
  d.backward = full_flow(d.backward);
  return d;
}

FlowStage run_flow_stage(const RunOptions& o, const FramesStage& f, const PosesStage& poses,
                         cv::Size depth_size, const fs::path& cache, bool stream) {
  auto t0 = std::chrono::steady_clock::now();
  FlowStage st;
  fs::path dir = cache / "flow";
  fs::create_directories(dir);
  // Pairs over the registered frames only (indices map back to frames).
  std::vector<int> reg;
  for (size_t k = 0; k < poses.cameras.size(); ++k)
    if (poses.cameras[k].registered) reg.push_back(static_cast<int>(k));
  std::vector<FramePair> pairs;
  for (const FramePair& p : hierarchical_pairs(static_cast<int>(reg.size())))
    pairs.push_back({reg[p.first], reg[p.second]});
  std::unique_ptr<OpticalFlow> estimator;
  if (o.flow == "flownet2") {
    CVD_CHECK(!o.flow_model.empty(),
              "--flow flownet2 needs --flow-model FILE.cvdw (no pretrained weights ship; see cvd "
              "convert)");
    estimator = std::make_unique<FlowNet2Estimator>(o.flow_model);
  } else {
    CVD_CHECK(o.flow == "dis", "unknown flow method '{}' (dis or flownet2)", o.flow);
    DisFlowOptions dopt;
    dopt.preset = parse_dis_preset(o.dis_preset);
    estimator = std::make_unique<DisFlowEstimator>(dopt);
  }
  OpticalFlow& dis = *estimator;
  FlowPairOptions popt;
  popt.fb_threshold_px = o.fb_threshold_px;
  json key = {{"method", dis.name()},
              {"fb", o.fb_threshold_px},
              {"w", depth_size.width},
              {"h", depth_size.height},
              {"frames_w", f.width}};
  int done = 0;
  std::map<int, ImageKeypoints> keypoint_cache;
  // One pair: from the cache when it holds it, else computed and cached.
  // Streamed: only the consecutive pairs (the flow tracks' input: one per frame) keep their
  // flows in memory; the others are left in the cache until training reads them.
  auto run_pair = [&](const FramePair& p) {
    const bool keep_flows = !stream || p.second == p.first + 1;
    std::string stem = fmt::format("{}__{}", f.names[p.first], f.names[p.second]);
    fs::path meta = dir / (stem + ".json");
    FlowPairData d;
    d.pair = p;
    d.stem = stem;
    json m = read_cache_json(meta);
    if (!m.is_null() && m.value("key", json()) == key) {
      d.forward_valid = m["forward_valid"];
      d.backward_valid = m["backward_valid"];
      d.kept = m["kept"].get<bool>();
      if (d.kept && keep_flows) read_cached_flows(dir, stem, d);
    } else {
      // Keypoints are detected once per frame and reused by every pair that frame is in.
      auto keypoints = [&](int k, const cv::Mat& img) -> const ImageKeypoints& {
        auto it = keypoint_cache.find(k);
        if (it == keypoint_cache.end())
          it = keypoint_cache.emplace(k, detect_keypoints(img, popt.homography)).first;
        return it->second;
      };
      cv::Mat img_i = f.load(p.first), img_j = f.load(p.second);
      FlowPairResult r = compute_pair_flow(dis, img_i, img_j, popt, &keypoints(p.first, img_i),
                                           &keypoints(p.second, img_j));
      d.forward_valid = r.forward_valid_fraction;
      d.backward_valid = r.backward_valid_fraction;
      const bool kept = d.kept = r.both_directions_keep(o.min_valid_fraction);
      if (kept) {
        d.forward = resize_flow(r.forward, depth_size);
        d.backward = resize_flow(r.backward, depth_size);
        d.forward_mask = resize_mask(r.forward_mask, depth_size);
        d.backward_mask = resize_mask(r.backward_mask, depth_size);
        write_flo(dir / (stem + ".fwd.flo"), d.forward);
        write_flo(dir / (stem + ".bwd.flo"), d.backward);
        for (auto [suffix, mat] :
             {std::pair{".fwd_mask.png", &d.forward_mask}, {".bwd_mask.png", &d.backward_mask}}) {
          fs::path mp = dir / (stem + suffix);
          write_atomically(mp, [&](const fs::path& tmp) {
            if (!cv::imwrite(tmp.string(), *mat))
              fail(ErrorCategory::io, "{}: cannot write", mp.string());
          });
        }
      }
      json mj = {{"key", key},
                 {"kept", kept},
                 {"forward_valid", d.forward_valid},
                 {"backward_valid", d.backward_valid},
                 {"homography_fallback", r.homography.reason}};
      write_text_file(meta, mj.dump());
      if (!keep_flows) d.forward = d.backward = d.forward_mask = d.backward_mask = cv::Mat();
    }
    d.forward = held_flow(d.forward, o.pair_precision == "f16");
    d.backward = held_flow(d.backward, o.pair_precision == "f16");
    report_stage_progress(o, "flow", ++done, static_cast<int>(pairs.size()), stem);
    return d;
  };
  // Several processes (mpirun): pair k is computed by rank k % R; after all finished, each
  // reads the others' pairs from the cache (same files as one process writes, so a rerun with
  // another R resumes).
  ProcessGroup& pg = process_group();
  std::vector<FlowPairData> results(pairs.size());
  for (size_t k = static_cast<size_t>(pg.rank()); k < pairs.size(); k += size_t(pg.size()))
    results[k] = run_pair(pairs[k]);
  if (pg.size() > 1) {
    pg.barrier();
    for (size_t k = 0; k < pairs.size(); ++k)
      if (static_cast<int>(k % size_t(pg.size())) != pg.rank()) results[k] = run_pair(pairs[k]);
  }
  for (FlowPairData& d : results) {
    if (d.kept)
      st.pairs.push_back(std::move(d));
    else
      ++st.dropped;
  }
  st.dir = dir;
  st.streamed = stream;
  st.half_precision = o.pair_precision == "f16";
  if (st.pairs.empty())
    fail(ErrorCategory::invalid_argument,
         "flow: no frame pair kept {:.0f}% consistent pixels in both directions ({} pairs tried); "
         "the video may be too short, too blurry or too fast",
         100 * o.min_valid_fraction, pairs.size());
  st.seconds = seconds_since(t0);
  return st;
}

}  // namespace cvd
