#!/usr/bin/python3
"""Generates tests/data/optimizer_fixture.json: ten steps of torch.optim.Adam and torch.optim.SGD
(torch 1.13, float64, CPU single-tensor path) on a tiny set of parameters with a fixed gradient
sequence, for tests/test_optimizers.cpp.

Some gradients are None (the parameter is skipped on that step, so parameters have different
step counts), which exercises the per-parameter state of both optimizers.

Usage: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/gen_optimizer_fixture.py
"""
import json
import os

import torch

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "tests", "data", "optimizer_fixture.json")
STEPS = 10

PARAM_SHAPES = [("conv.weight", [2, 3, 1, 2]), ("conv.bias", [2]), ("fc.weight", [3, 4]),
                ("scale", [])]
# (step, parameter index) pairs without a gradient.
NO_GRAD = {(0, 3), (1, 3), (3, 1), (6, 1), (7, 2)}

RUNS = [
    ("adam", "Adam", dict(lr=0.01, betas=(0.9, 0.999), eps=1e-8, weight_decay=0.0)),
    ("adam_weight_decay", "Adam", dict(lr=0.02, betas=(0.8, 0.95), eps=1e-6, weight_decay=0.1)),
    ("sgd", "SGD", dict(lr=0.1, momentum=0.0, dampening=0.0, weight_decay=0.0, nesterov=False)),
    ("sgd_momentum", "SGD",
     dict(lr=0.1, momentum=0.9, dampening=0.1, weight_decay=0.0, nesterov=False)),
    ("sgd_nesterov_weight_decay", "SGD",
     dict(lr=0.05, momentum=0.8, dampening=0.0, weight_decay=0.01, nesterov=True)),
    ("sgd_momentum_weight_decay", "SGD",
     dict(lr=0.03, momentum=0.5, dampening=0.0, weight_decay=0.2, nesterov=False)),
]


def flat(t):
    return [float(x) for x in t.detach().reshape(-1).tolist()]


def main():
    torch.manual_seed(20200717)
    init = [torch.randn(shape, dtype=torch.float64) for _, shape in PARAM_SHAPES]
    grads = [[None if (s, i) in NO_GRAD else torch.randn(shape, dtype=torch.float64) * (1.0 + s)
              for i, (_, shape) in enumerate(PARAM_SHAPES)] for s in range(STEPS)]
    runs = []
    for run_name, kind, options in RUNS:
        params = [torch.nn.Parameter(t.clone()) for t in init]
        opt_class = torch.optim.Adam if kind == "Adam" else torch.optim.SGD
        opt = opt_class(params, **options)
        trajectory = []
        for s in range(STEPS):
            opt.zero_grad(set_to_none=True)
            for p, g in zip(params, grads[s]):
                p.grad = None if g is None else g.clone()
            opt.step()
            trajectory.append([flat(p) for p in params])
        opts = dict(options)
        if "betas" in opts:
            opts["beta1"], opts["beta2"] = opts.pop("betas")
        runs.append({"name": run_name, "optimizer": kind, "options": opts,
                     "trajectory": trajectory})
    fixture = {
        "generator": "tools/reference/gen_optimizer_fixture.py",
        "torch_version": torch.__version__,
        "dtype": "float64",
        "params": [{"name": n, "shape": s, "values": flat(t)}
                   for (n, s), t in zip(PARAM_SHAPES, init)],
        "grads": [[None if g is None else flat(g) for g in step] for step in grads],
        "runs": runs,
    }
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as f:
        json.dump(fixture, f, indent=None, separators=(",", ":"))
        f.write("\n")
    print(f"wrote {OUT}: {len(runs)} runs x {STEPS} steps")


if __name__ == "__main__":
    main()
