#!/usr/bin/env python3
"""PyTorch side of bench/compare_models.sh: the same configurations as bench/bench_models.cpp
(inference, or one training step = forward in BN train mode + backward + Adam) with the reference
definitions of midas_models.py / mannequin_model.py at full width, optionally with the weights
that bench_models wrote (--weights). Prints one JSON line (seconds per iteration, peak RSS, forward
GMAC per image counted with conv hooks, GFLOP/s and MFU against --peak-gflops). The training
step's loss is by default the CVD geometric loss on 4 pairs with the synthetic cameras and flow
of bench_models.cpp's bench_pairs (--loss surrogate: mean(output * R)).
Run: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/bench_models_torch.py --arch midas_v2 --mode train
"""
import argparse
import json
import math
import pathlib
import resource
import sys
import time

import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import depth_anything_v2_model  # noqa: E402
import mannequin_model  # noqa: E402
import midas_models  # noqa: E402
from cvdw_writer import read_cvdw  # noqa: E402


def build(arch):
    if arch == "depth_anything_v2":
        return depth_anything_v2_model.DepthAnythingV2(depth_anything_v2_model.VITS)
    if arch == "midas_v2":
        return midas_models.MidasV2(1.0)
    if arch == "midas_small":
        return midas_models.MidasSmall(1.0)
    return mannequin_model.HourglassModel(1.0)


def raw_output(arch, model, rgb):
    if arch == "mannequin":
        return model(rgb)[0]
    if arch == "depth_anything_v2":
        return model(midas_models.imagenet_normalize(rgb))
    return model(midas_models.imagenet_normalize(rgb)).unsqueeze(1)


def depth_from_raw(arch, raw):
    """models/depth_net.cpp: MiDaS predicts inverse depth (clamped at 1e-4), Mannequin log depth."""
    if arch == "mannequin":
        return torch.exp(raw)
    return 1.0 / torch.clamp(raw, min=1e-4)


def rot_zyx(ax, ay, az):
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = torch.tensor([[1, 0, 0], [0, cx, -sx], [0, sx, cx]], dtype=torch.float64)
    ry = torch.tensor([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]], dtype=torch.float64)
    rz = torch.tensor([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]], dtype=torch.float64)
    return rz @ ry @ rx


def bench_pairs(batch, h, w):
    """The same pairs as bench_models.cpp's bench_pairs: (2k, 2k+1) with camera i at the origin,
    camera j rotated and moved, analytic flow i -> j, its negative j -> i, one mask."""
    K = torch.tensor([[0.8 * w, 0, 0.5 * (w - 1)], [0, 0.8 * w, 0.5 * (h - 1)], [0, 0, 1]], dtype=torch.float64)
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    flow = torch.stack([2 + 0.01 * xs + torch.sin(0.05 * ys), -1 + 0.01 * ys + torch.cos(0.07 * xs)], -1).float()
    mask = (((xs + 2 * ys) % 7) != 0).float()
    pairs = []
    for k in range(batch // 2):
        R_i, t_i = torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64)
        R_j = rot_zyx(0.02, -0.03 + 0.01 * k, 0.01)
        t_j = torch.tensor([0.1 + 0.05 * k, 0.02, -0.01], dtype=torch.float64)
        pairs.append((2 * k, 2 * k + 1, (R_i, t_i, R_j, t_j, K, flow, mask), (R_j, t_j, R_i, t_i, K, -flow, mask)))
    return pairs


def loss_direction(d_i, d_j, cam, lam):
    """pipeline/training/geometric_loss.h, one direction: mean reprojection distance to the flow target +
    lambda * mean focal-weighted disparity difference (D_j sampled bilinearly, border), masked."""
    R_i, t_i, R_j, t_j, K, flow, mask = cam
    h, w = d_i.shape
    A = (R_j.T @ R_i).float()
    b = (R_j.T @ (t_i - t_j)).float().reshape(3, 1)
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    rays = torch.stack([(xs - K[0, 2]) / K[0, 0], (ys - K[1, 2]) / K[1, 1], torch.ones_like(xs)], 0).reshape(3, -1).float()
    c = A @ (rays * d_i.reshape(1, -1)) + b
    z = torch.clamp(c[2], min=1e-3)
    pu = float(K[0, 0]) * c[0] / z + float(K[0, 2])
    pv = float(K[1, 1]) * c[1] / z + float(K[1, 2])
    tu = xs.reshape(-1) + flow[..., 0].reshape(-1)
    tv = ys.reshape(-1) + flow[..., 1].reshape(-1)
    dist = torch.sqrt((pu - tu) ** 2 + (pv - tv) ** 2 + 1e-12)
    grid = torch.stack([tu / (w - 1) * 2 - 1, tv / (h - 1) * 2 - 1], -1).reshape(1, h, w, 2)
    dj = torch.nn.functional.grid_sample(d_j.reshape(1, 1, h, w), grid, mode="bilinear", padding_mode="border",
                                         align_corners=True).reshape(-1)
    disp = float(0.5 * (K[0, 0] + K[1, 1])) * torch.abs(1 / z - 1 / torch.clamp(dj, min=1e-3))
    m = mask.reshape(-1)
    cnt = torch.clamp(m.sum(), min=1.0)
    return (dist * m).sum() / cnt + lam * (disp * m).sum() / cnt


def geometric_loss(arch, depth, pairs):
    lam = 0.1 if arch == "mannequin" else 1e-4  # depth_anything_v2: MiDaS's (provisional)
    total = 0
    for i, j, ij, ji in pairs:
        d_i, d_j = depth[i, 0], depth[j, 0]
        total = total + 0.5 * (loss_direction(d_i, d_j, ij, lam) + loss_direction(d_j, d_i, ji, lam))
    return total / len(pairs)


def forward_gmac(arch, model, h, w):
    """Multiply-accumulates of convolutions (and of the ViT's linear layers and attention
    products) of one forward per image (what docs/models.md section 8 counts)."""
    macs = [0]

    def hook(m, inp, out):
        if isinstance(m, torch.nn.Linear):
            macs[0] += out.numel() * m.in_features
        elif isinstance(m, torch.nn.ConvTranspose2d):
            macs[0] += inp[0].numel() * m.weight.shape[1] * m.weight.shape[2] * m.weight.shape[3]
        elif isinstance(m, depth_anything_v2_model.Attention):
            b, n, c = inp[0].shape
            macs[0] += 2 * b * n * n * c  # q k^T and attn v
        else:
            k = m.weight.shape[1] * m.weight.shape[2] * m.weight.shape[3]
            macs[0] += out.numel() * k

    kinds = (torch.nn.Conv2d, torch.nn.Linear, torch.nn.ConvTranspose2d, depth_anything_v2_model.Attention)
    hs = [m.register_forward_hook(hook) for m in model.modules() if isinstance(m, kinds)]
    model.eval()
    with torch.no_grad():
        raw_output(arch, model, torch.rand(1, 3, h, w))
    for x in hs:
        x.remove()
    return macs[0] / 1e9


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--arch", default="midas_v2")
    p.add_argument("--mode", default="infer", choices=["infer", "train"])
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--height", type=int, default=224)
    p.add_argument("--width", type=int, default=384)
    p.add_argument("--iters", type=int, default=1)
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--weights", default="")
    p.add_argument("--peak-gflops", type=float, default=256.0)
    p.add_argument("--gmac-only", action="store_true")
    p.add_argument("--loss", default="geometric", choices=["geometric", "surrogate"])
    p.add_argument("--precision", default="f32", choices=["f32"])
    a = p.parse_args()
    torch.manual_seed(0)
    model = build(a.arch)
    if a.weights:
        _, tensors = read_cvdw(a.weights)
        state = {k: torch.from_numpy(v) for k, v in tensors.items()}
        missing, unexpected = model.load_state_dict(state, strict=False)
        assert not unexpected, unexpected
        assert all("refinenet4.resConfUnit1" in k for k in missing), missing
    gmac = forward_gmac(a.arch, model, a.height, a.width)
    if a.gmac_only:
        print(f"{gmac:.6f}")
        return
    g = torch.Generator().manual_seed(7)
    rgb = torch.rand(a.batch, 3, a.height, a.width, generator=g)
    R = torch.randn(a.batch, 1, a.height, a.width, generator=g)
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    pairs = bench_pairs(a.batch, a.height, a.width)

    def step():
        if a.mode == "infer":
            model.eval()
            with torch.no_grad():
                return raw_output(a.arch, model, rgb).sum().item()
        model.train()
        opt.zero_grad(set_to_none=True)
        out = raw_output(a.arch, model, rgb)
        if a.loss == "surrogate":
            loss = (out * R).mean()
        else:
            loss = geometric_loss(a.arch, depth_from_raw(a.arch, out), pairs)
        loss.backward()
        opt.step()
        return loss.item()

    for _ in range(a.warmup):
        step()
    t0 = time.perf_counter()
    check = sum(step() for _ in range(a.iters))
    sec = (time.perf_counter() - t0) / a.iters
    gflop = 2 * gmac * a.batch * (3 if a.mode == "train" else 1)
    print(json.dumps({"impl": "pytorch " + torch.__version__, "arch": a.arch, "mode": a.mode, "batch": a.batch,
                      "loss": a.loss if a.mode == "train" else "none",
                      "size": f"{a.width}x{a.height}", "seconds": sec, "gflop": gflop, "gflops": gflop / sec,
                      "mfu": gflop / sec / a.peak_gflops,
                      "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                      "threads": torch.get_num_threads(), "check": check}))


if __name__ == "__main__":
    main()
