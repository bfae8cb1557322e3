/// \file cvd.h
/// The umbrella header of libcvd's public API: `#include <cvd/cvd.h>`.
///
/// - cvd::DepthModel  single-image depth (cvd/depth_model.h)
/// - cvd::FlowEstimator  optical flow with consistency masks (cvd/flow_estimator.h)
/// - cvd::Pipeline  the whole consistent-video-depth run (cvd/pipeline.h)
/// - cvd::Error  the one exception type, with a category (cvd/error.h)
///
/// The public headers include only the C++ standard library.
#pragma once
#include "cvd/depth_model.h"
#include "cvd/error.h"
#include "cvd/export.h"
#include "cvd/flow_estimator.h"
#include "cvd/pipeline.h"
#include "cvd/types.h"
