// Element-wise ops: unary (with scalar parameters), broadcasting binaries, comparisons, where.
#include "engine/elementwise_math.h"
#include "engine/op_support.h"

namespace cvd {

using detail::check_same_kind;
using detail::empty_like_kind;

static const char* unary_name(UnaryOp op) {
  switch (op) {
#define CVD_X(name, cost) \
  case UnaryOp::name:     \
    return #name;
    CVD_UNARY_OPS(CVD_X)
#undef CVD_X
  }
  return "unary";
}

Tensor unary(const Tensor& x_in, const UnaryParams& p) {
  Tensor x = x_in.contiguous();
  Tensor y = empty_like_kind(x.shape(), x);
  dispatch(OpId::unary, x, KernelArgs{{x}, {y}, &p});
  if (!any_requires_grad({x})) return y;
  // Save only what the op's derivative reads (engine/elementwise_math.h): relu-like ops and
  // sigmoid / tanh / exp / sqrt / reciprocal read the output, so an activation's input (e.g. a
  // batch norm's output) is not kept alive for backward; scalar ops read neither.
  const UnaryOperands reads = unary_backward_reads(p.op);
  return record(unary_name(p.op), y, {x},
                [xs = reads.x ? x.detach() : Tensor(), ys = reads.y ? y.detach() : Tensor(),
                 shape = x.shape(), p](const Tensor& g, const std::vector<bool>&) {
                  Tensor gc = g.contiguous();
                  Tensor gx = empty_like_kind(shape, gc);
                  dispatch(OpId::unary_backward, gc, KernelArgs{{gc, xs, ys}, {gx}, &p});
                  return std::vector<Tensor>{gx};
                });
}

Shape broadcast_shapes(const Shape& a, const Shape& b) {
  size_t n = std::max(a.size(), b.size());
  Shape r(n);
  for (size_t i = 0; i < n; ++i) {
    int64_t da = i < n - a.size() ? 1 : a[i - (n - a.size())];
    int64_t db = i < n - b.size() ? 1 : b[i - (n - b.size())];
    CVD_CHECK(da == db || da == 1 || db == 1, "shapes {} and {} do not broadcast", shape_str(a),
              shape_str(b));
    r[i] = da == 1 ? db : da;
  }
  return r;
}

static Tensor binary_raw(const Tensor& a, const Tensor& b, BinaryOp op, const Shape& out_shape) {
  Tensor av = a.detach().expand(out_shape);
  Tensor bv = b.detach().expand(out_shape);
  Tensor c = empty_like_kind(out_shape, a);
  BinaryParams p{op};
  dispatch(OpId::binary, a, KernelArgs{{av, bv}, {c}, &p});
  return c;
}

static Tensor binary(const Tensor& a, const Tensor& b, BinaryOp op, const char* name) {
  check_same_kind(name, a, b);
  Shape out = broadcast_shapes(a.shape(), b.shape());
  Tensor c = binary_raw(a, b, op, out);
  if (!any_requires_grad({a, b})) return c;
  // add and sub need only the shapes: keeping their inputs alive until backward would hold
  // activations (e.g. both branches of a residual sum) that nothing else needs.
  const bool save_inputs = op != BinaryOp::add && op != BinaryOp::sub;
  return record(
      name, c, {a, b},
      [as = save_inputs ? a.detach() : Tensor(), bs = save_inputs ? b.detach() : Tensor(),
       sa = a.shape(), sb = b.shape(), op](const Tensor& g, const std::vector<bool>& need) {
        Tensor ga, gb;
        switch (op) {
          case BinaryOp::add:
            ga = g;
            gb = g;
            break;
          case BinaryOp::sub:
            ga = g;
            if (need[1]) gb = neg(g);
            break;
          case BinaryOp::mul:
            if (need[0]) ga = mul(g, bs);
            if (need[1]) gb = mul(g, as);
            break;
          case BinaryOp::div:
            if (need[0]) ga = div(g, bs);
            if (need[1]) gb = neg(div(mul(g, as), mul(bs, bs)));
            break;
          case BinaryOp::minimum:
          case BinaryOp::maximum: {
            // The gradient goes to a where a wins (ties: a), else to b.
            Tensor a_wins = op == BinaryOp::minimum ? le(as, bs) : ge(as, bs);
            Tensor zero = Tensor::zeros({}, g.dtype(), g.device());
            if (need[0]) ga = where(a_wins, g, zero);
            if (need[1]) gb = where(a_wins, zero, g);
            break;
          }
          default:
            break;
        }
        if (ga.defined() && need[0])
          ga = sum_to(ga, sa);
        else
          ga = Tensor();
        if (gb.defined() && need[1])
          gb = sum_to(gb, sb);
        else
          gb = Tensor();
        return std::vector<Tensor>{ga, gb};
      });
}

Tensor add(const Tensor& a, const Tensor& b) { return binary(a, b, BinaryOp::add, "add"); }
Tensor sub(const Tensor& a, const Tensor& b) { return binary(a, b, BinaryOp::sub, "sub"); }
Tensor mul(const Tensor& a, const Tensor& b) { return binary(a, b, BinaryOp::mul, "mul"); }
Tensor div(const Tensor& a, const Tensor& b) { return binary(a, b, BinaryOp::div, "div"); }
Tensor minimum(const Tensor& a, const Tensor& b) {
  return binary(a, b, BinaryOp::minimum, "minimum");
}
Tensor maximum(const Tensor& a, const Tensor& b) {
  return binary(a, b, BinaryOp::maximum, "maximum");
}

static Tensor compare(const Tensor& a, const Tensor& b, BinaryOp op, const char* name) {
  check_same_kind(name, a, b);
  return binary_raw(a, b, op, broadcast_shapes(a.shape(), b.shape()));
}
Tensor gt(const Tensor& a, const Tensor& b) { return compare(a, b, BinaryOp::gt, "gt"); }
Tensor ge(const Tensor& a, const Tensor& b) { return compare(a, b, BinaryOp::ge, "ge"); }
Tensor lt(const Tensor& a, const Tensor& b) { return compare(a, b, BinaryOp::lt, "lt"); }
Tensor le(const Tensor& a, const Tensor& b) { return compare(a, b, BinaryOp::le, "le"); }
Tensor eq(const Tensor& a, const Tensor& b) { return compare(a, b, BinaryOp::eq, "eq"); }

Tensor where(const Tensor& cond, const Tensor& a, const Tensor& b) {
  check_same_kind("where", a, b);
  check_same_kind("where", a, cond);
  Shape out = broadcast_shapes(broadcast_shapes(cond.shape(), a.shape()), b.shape());
  Tensor c = empty_like_kind(out, a);
  Tensor cv = cond.detach().expand(out), av = a.detach().expand(out), bv = b.detach().expand(out);
  dispatch(OpId::where, a, KernelArgs{{cv, av, bv}, {c}, nullptr});
  if (!any_requires_grad({a, b})) return c;
  return record("where", c, {a, b},
                [cs = cond.detach(), ashape = a.shape(), bshape = b.shape()](
                    const Tensor& g, const std::vector<bool>& need) {
                  Tensor zero = Tensor::zeros({}, g.dtype(), g.device());
                  Tensor ga, gb;
                  if (need[0]) ga = sum_to(where(cs, g, zero), ashape);
                  if (need[1]) gb = sum_to(where(cs, zero, g), bshape);
                  return std::vector<Tensor>{ga, gb};
                });
}

}  // namespace cvd
