// Shared by the api/*.cpp sources: the internal headers, the public headers, and the conversions
// between the public plain types and cv::Mat. The internal names differ from the public ones (cvd::DeviceId vs the
// public cvd::Device, cvd::OpticalFlow vs cvd::FlowEstimator, cvd::NamedCamera vs
// cvd::FrameCamera), so either can be named after both are included.
#pragma once
// cvd::Error is thrown across the shared library's boundary: give its type info default visibility.
#pragma GCC visibility push(default)
#include "engine/error.h"
#pragma GCC visibility pop

#include <opencv2/core.hpp>

// Every internal header any api/*.cpp needs is included here.
#include "engine/autograd.h"
#include "engine/backend_info.h"
#include "engine/cvdw.h"
#include "engine/dtype.h"
#include "engine/module_weights.h"
#include "engine/ops.h"
#include "engine/random.h"
#include "models/depth_net.h"
#include "pipeline/flow/flow_dis.h"
#include "pipeline/flow/flow_flownet2.h"
#include "pipeline/flow/flow_pair.h"
#include "pipeline/flow/optical_flow.h"
#include "pipeline/geometry/camera.h"
#include "pipeline/io/frame_source.h"
#include "pipeline/run/quality_preset.h"
#include "pipeline/run/run_pipeline.h"
#include "pipeline/run/run_stages.h"

namespace cvd::api_bridge {
using CoreIntrinsics = ::cvd::Intrinsics;
}  // namespace cvd::api_bridge

#include "cvd/cvd.h"

namespace cvd::api_bridge {

// 8-bit BGR copy of an RGB / gray / RGBA view (what the pipeline's stages take).
cv::Mat bgr_from_view(const v1::ImageView& view, const char* what);
v1::Image image_from_bgr(const cv::Mat& bgr);
// A CV_32F matrix as a DepthMap.
v1::DepthMap depth_map_from_mat(const cv::Mat& depth);
CoreIntrinsics to_core(const v1::CameraIntrinsics& k);
v1::CameraIntrinsics to_public(const CoreIntrinsics& k);

}  // namespace cvd::api_bridge
