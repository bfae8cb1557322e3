#!/usr/bin/env python3
"""PyTorch (cuDNN / cuBLAS) timings of the cases of bench/bench_cuda_ops.cpp on the same GPU.

Same shapes, f32, forward under no_grad and forward + backward (torch.autograd.grad of every
input with a fixed random output gradient), the device synchronised before each clock read.
TF32 is off so that both sides do f32 arithmetic. Prints one JSON line per case with the fields
of bench_cuda_ops. Flownet2's correlation has no PyTorch op; it is left out here.
   python3 tools/reference/bench_cuda_ops_torch.py [--min-seconds 0.2]
"""
import argparse
import json
import time

import torch
import torch.nn.functional as F


def conv_case(name, n, c, h, w, o, k, stride, groups):
    oh = (h + 2 * (k // 2) - k) // stride + 1
    ow = (w + 2 * (k // 2) - k) // stride + 1
    fn = lambda t: F.conv2d(t[0], t[1], t[2], stride=stride, padding=k // 2, groups=groups)
    return name, [(n, c, h, w), (o, c // groups, k, k), (o,)], fn, 2.0 * n * o * (c // groups) * k * k * oh * ow


def bn(t):
    rm = torch.zeros(64, device=t[0].device)
    rv = torch.ones(64, device=t[0].device)
    return F.batch_norm(t[0], rm, rv, t[1], t[2], training=True, momentum=0.1, eps=1e-5)


CASES = [
    conv_case("conv3x3_64-64_96x128", 8, 64, 96, 128, 64, 3, 1, 1),
    conv_case("conv7x7_32-64_96x128", 8, 32, 96, 128, 64, 7, 1, 1),
    conv_case("conv3x3_256-256_24x32", 8, 256, 24, 32, 256, 3, 1, 1),
    conv_case("conv1x1_96-576_16x20", 8, 96, 16, 20, 576, 1, 1, 1),
    conv_case("dw5x5_144_64x80", 8, 144, 64, 80, 144, 5, 1, 144),
    conv_case("dw5x5_144_64x80_s2", 8, 144, 64, 80, 144, 5, 2, 144),
    ("matmul_2048", [(2048, 2048), (2048, 2048)], lambda t: t[0] @ t[1], 2.0 * 2048 ** 3),
    ("add_8x64x96x128", [(8, 64, 96, 128)] * 2, lambda t: t[0] + t[1], 0),
    ("relu_8x64x96x128", [(8, 64, 96, 128)], lambda t: F.relu(t[0]), 0),
    ("batch_norm_train_8x64x96x128", [(8, 64, 96, 128), (64,), (64,)], bn, 0),
    ("upsample_bilinear_x2_8x64x48x64", [(8, 64, 48, 64)],
     lambda t: F.interpolate(t[0], size=(96, 128), mode="bilinear", align_corners=True), 0),
    ("grid_sample_8x64x96x128", [(8, 64, 96, 128), (8, 96, 128, 2)],
     lambda t: F.grid_sample(t[0], t[1], mode="bilinear", padding_mode="zeros", align_corners=False), 0),
]


def time_per_call(once, min_seconds):
    once()
    once()
    torch.cuda.synchronize()
    iters, t0, elapsed = 0, time.perf_counter(), 0.0
    while iters < 3 or elapsed < min_seconds:
        once()
        iters += 1
        torch.cuda.synchronize()
        elapsed = time.perf_counter() - t0
    return elapsed / iters


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--min-seconds", type=float, default=0.2)
    args = ap.parse_args()
    torch.backends.cuda.matmul.allow_tf32 = False
    torch.backends.cudnn.allow_tf32 = False
    torch.backends.cudnn.benchmark = True
    dev = torch.device("cuda")
    g = torch.Generator(device="cpu").manual_seed(7)
    for name, shapes, fn, flops in CASES:
        ins = [(0.5 * torch.randn(s, generator=g)).to(dev).requires_grad_(True) for s in shapes]

        def fwd():
            with torch.no_grad():
                fn(ins)

        f = time_per_call(fwd, args.min_seconds)
        gy = torch.randn(fn(ins).shape, generator=g).to(dev)
        fb = time_per_call(lambda: torch.autograd.grad(fn(ins), ins, gy), args.min_seconds)
        row = {"name": name, "fwd_ms": f * 1e3, "fwd_bwd_ms": fb * 1e3}
        if flops:
            row["fwd_gflops"] = flops / f * 1e-9
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
