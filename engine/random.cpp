#include "engine/random.h"

#include <sstream>

#include "engine/error.h"

namespace cvd {

std::string Generator::state() const {
  std::ostringstream os;
  os << eng_;
  return os.str();
}

void Generator::set_state(const std::string& s) {
  std::istringstream is(s);
  std::mt19937_64 e;
  is >> e;
  if (is.fail()) fail(ErrorCategory::format, "malformed random generator state");
  eng_ = e;
}

}  // namespace cvd
