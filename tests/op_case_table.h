// The table of op cases used by tests/test_ops.cpp: every differentiable op of engine/ops.h with
// the shapes and parameters the models use. Adding an op to the engine = adding a line here.
#pragma once
#include <functional>
#include <ostream>
#include <string>
#include <vector>

#include "engine/ops.h"

namespace cvd::test {

// How an input is drawn: normal; positive in [0.5, 2]; |x| in [0.2, 1.2] with random sign (keeps
// finite differences away from kinks at 0); uniform in [-1.1, 1.1] (sampling grids); a 0/1 mask.
enum class Init { normal, positive, away_from_zero, grid, mask };

struct InputSpec {
  Shape shape;
  Init init = Init::normal;
  bool differentiable = true;
};

struct OpCase {
  std::string name;
  std::vector<InputSpec> inputs;
  std::function<Tensor(const std::vector<Tensor>&)> fn;
  double f32_tol = 2e-5;  // max abs error of f32 vs the f64 reference, relative to max(1, |ref|max)
};

// gtest prints a case by its name.
inline void PrintTo(const OpCase& c, std::ostream* os) { *os << c.name; }

std::vector<OpCase> all_op_cases();

}  // namespace cvd::test
