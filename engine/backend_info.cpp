#include "engine/backend_info.h"

#include <oneapi/dnnl/dnnl.hpp>

namespace cvd {

std::vector<std::string> compiled_backends() {
  const dnnl_version_t* v = dnnl_version();
  std::vector<std::string> r{"reference (f64, cpu)", "cpu (f32; oneDNN " +
                                                         std::to_string(v->major) + "." +
                                                         std::to_string(v->minor) + "." +
                                                         std::to_string(v->patch) + ", OpenMP)"};
#ifdef CVD_WITH_CUDA
  r.push_back("cuda (f32)");
#endif
  return r;
}

}  // namespace cvd
