#!/usr/bin/env python3
"""Generates tests/data/models/flownet2_fixture.cvdw: a tiny-width FlowNet2 (flownet2_model.py,
structurally identical to NVIDIA/flownet2-pytorch's FlowNet2) with seeded random weights, run by
PyTorch in float64 on a small image pair.

Tensors (names):
  param/<state name>   the weights (f32 values, PyTorch's default init, the predict_flow layers
                       scaled by PREDICT_SCALE so that the flows are a few pixels: the warps
                       then interpolate inside the image rather than only near 0)
  input/img0, input/img1   RGB in [0, 255] (integers), [N, 3, H, W] (f32)
  flownetc, flownets_1, flownets_2, flownets_d   each sub-network's raw flow2 output inside the
                       chain, [N, 2, H/4, W/4] (f64)
  output               FlowNet2's output flow in pixels, [N, 2, H, W] (f64)
Config: {"arch": "flownet2", "width": W}.
Run offline: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/gen_flownet2_fixture.py
"""
import pathlib
import sys

import torch
import torch.nn.functional as F

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import flownet2_model  # noqa: E402
from cvdw_writer import write_cvdw  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "models" / "flownet2_fixture.cvdw"
N, H, W = 2, 64, 128
WIDTH = 1 / 32
SEED = 21
PREDICT_SCALE = 4.0


def image_pair(gen):
    """A smooth random texture and a copy shifted by (3, -2) px with a little noise, 0..255."""
    base = torch.rand((N, 3, H // 8 + 2, W // 8 + 2), generator=gen, dtype=torch.float64)
    big = F.interpolate(base, size=(H + 16, W + 16), mode="bicubic", align_corners=False)
    big = (big - big.amin()) / (big.amax() - big.amin()) * 255
    img0 = big[:, :, 8:8 + H, 8:8 + W]
    img1 = big[:, :, 10:10 + H, 5:5 + W] + 4 * torch.randn((N, 3, H, W), generator=gen, dtype=torch.float64)
    return img0.clamp(0, 255).round(), img1.clamp(0, 255).round()


def main():
    gen = torch.Generator().manual_seed(SEED)
    torch.manual_seed(SEED)
    net = flownet2_model.FlowNet2(WIDTH)
    with torch.no_grad():
        for name, p in net.named_parameters():
            if ".predict_flow" in name:
                p.mul_(PREDICT_SCALE)
            p.copy_(p.float())  # f32 values, exactly representable in the fixture
    net = net.double().eval()
    img0, img1 = image_pair(gen)
    trace = {}
    with torch.no_grad():
        out = net(img0, img1, trace)
    print("output flow range", out.amin().item(), out.amax().item())
    for k in ("flownetc", "flownets_1", "flownets_2", "flownets_d"):
        print(k, "x20 range", (trace[k] * 20).amin().item(), (trace[k] * 20).amax().item())
    tensors = [("param/" + k, v.float(), "parameter") for k, v in net.state_dict().items()]
    tensors += [("input/img0", img0.float(), ""), ("input/img1", img1.float(), "")]
    tensors += [(k, trace[k], "") for k in ("flownetc", "flownets_1", "flownets_2", "flownets_d")]
    tensors.append(("output", out, ""))
    write_cvdw(OUT, "flownet2_fixture", {"arch": "flownet2", "width": WIDTH}, tensors)
    print("wrote", OUT, sum(p.numel() for p in net.parameters()), "parameters")


if __name__ == "__main__":
    main()
