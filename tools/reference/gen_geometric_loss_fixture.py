#!/usr/bin/env python3
"""Generates tests/data/geometric_loss_fixture.json: the CVD geometric loss (docs/design.md 5.6) on
random inputs computed by PyTorch (float64), with gradients w.r.t. both depth maps. An
independent implementation in torch of the paper's / reference implementation's loss:
spatial ||p_ij - f_ij||_2 and focal * |1/z_ij - 1/z_j(f_ij)|, mask-normalised means, both
directions averaged. Run offline: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/gen_geometric_loss_fixture.py
"""
import json
import math
import pathlib

import torch
import torch.nn.functional as F

torch.manual_seed(7)
torch.set_default_dtype(torch.float64)
H, W = 6, 8
LAMBDA = 0.1


def rot(ax, ay, az):
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = torch.tensor([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = torch.tensor([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = torch.tensor([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def direction(d_i, d_j, R_i, t_i, R_j, t_j, K_i, K_j, flow, mask):
    ys, xs = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64), indexing="ij")
    pix = torch.stack([xs, ys, torch.ones_like(xs)], 0).reshape(3, -1)
    c_i = torch.linalg.inv(K_i) @ pix * d_i.reshape(1, -1)
    c_ij = R_j.T @ (R_i @ c_i + (t_i - t_j).reshape(3, 1))
    z = torch.clamp(c_ij[2], min=1e-3)
    pu = K_j[0, 0] * c_ij[0] / z + K_j[0, 2]
    pv = K_j[1, 1] * c_ij[1] / z + K_j[1, 2]
    tu = xs.reshape(-1) + flow[..., 0].reshape(-1)
    tv = ys.reshape(-1) + flow[..., 1].reshape(-1)
    dist = torch.sqrt((pu - tu) ** 2 + (pv - tv) ** 2 + 1e-12)
    grid = torch.stack([tu / (W - 1) * 2 - 1, tv / (H - 1) * 2 - 1], -1).reshape(1, H, W, 2)
    dj = F.grid_sample(d_j.reshape(1, 1, H, W), grid, mode="bilinear", padding_mode="border", align_corners=True).reshape(-1)
    zj = torch.clamp(dj, min=1e-3)
    focal = 0.5 * (K_i[0, 0] + K_i[1, 1])
    disp = focal * torch.abs(1 / z - 1 / zj)
    m = mask.reshape(-1)
    cnt = torch.clamp(m.sum(), min=1.0)
    spatial = (dist * m).sum() / cnt
    disparity = (disp * m).sum() / cnt
    return spatial, disparity


def main():
    K = torch.tensor([[7.0, 0, 3.6], [0, 6.5, 2.4], [0, 0, 1]])
    R_i, R_j = rot(0.02, -0.05, 0.01), rot(-0.03, 0.04, -0.02)
    t_i, t_j = torch.tensor([0.0, 0.0, 0.0]), torch.tensor([0.3, -0.1, 0.05])
    d_i = (2.0 + torch.rand(H, W)).requires_grad_()
    d_j = (2.0 + torch.rand(H, W)).requires_grad_()
    flow_ij = torch.randn(H, W, 2) * 0.8 + torch.tensor([-0.7, 0.3])
    flow_ji = torch.randn(H, W, 2) * 0.8 + torch.tensor([0.7, -0.3])
    mask_ij = (torch.rand(H, W) > 0.25).double()
    mask_ji = (torch.rand(H, W) > 0.25).double()
    s1, p1 = direction(d_i, d_j, R_i, t_i, R_j, t_j, K, K, flow_ij, mask_ij)
    s2, p2 = direction(d_j, d_i, R_j, t_j, R_i, t_i, K, K, flow_ji, mask_ji)
    spatial = 0.5 * (s1 + s2)
    disparity = 0.5 * (p1 + p2)
    total = spatial + LAMBDA * disparity
    total.backward()
    flat = lambda t: [float(x) for x in t.detach().reshape(-1)]
    out = {
        "H": H, "W": W, "lambda": LAMBDA,
        "K": flat(K), "R_i": flat(R_i), "t_i": flat(t_i), "R_j": flat(R_j), "t_j": flat(t_j),
        "depth_i": flat(d_i), "depth_j": flat(d_j),
        "flow_ij": flat(flow_ij), "flow_ji": flat(flow_ji), "mask_ij": flat(mask_ij), "mask_ji": flat(mask_ji),
        "spatial": float(spatial), "disparity": float(disparity), "total": float(total),
        "grad_depth_i": flat(d_i.grad), "grad_depth_j": flat(d_j.grad),
    }
    path = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "geometric_loss_fixture.json"
    path.write_text(json.dumps(out))
    print(f"wrote {path} (total {float(total):.6f})")


if __name__ == "__main__":
    main()
