#!/usr/bin/env python3
"""Generates tests/data/models/depth_anything_v2_fixture.cvdw: a reduced Depth Anything V2
(depth_anything_v2_model.py: 4 blocks of width 12, 2 heads, MLP ratio 2, a 4 x 4 position grid,
features 4) with seeded random weights, run by PyTorch in float64 on a 56 x 42 input (4 x 3
patches: the position embedding is resized bicubically with DINOv2's scale factors) and on a
56 x 56 input (4 x 4 patches: used as is). The network has no batch norm or dropout, so train and
eval mode compute the same; the file holds one set.

Names:
  param/<state name>   initial parameters (f32 values)
  input, R             RGB in [0, 1] [2, 3, 56, 42] and loss weights [2, 1, 56, 42]; loss =
                       sum(raw_output * R), the raw output on the ImageNet-normalised input
  eval/output, eval/loss   raw output [2, 1, 56, 42] and loss (f64)
  eval/grad/<name>     d loss / d parameter (f64) of every parameter the output uses
  square/input, square/output   the 56 x 56 case (forward only)
Header config: "dav2_config" (the reduced configuration) and "pytorch_f32_error" (PyTorch's own
float32 error per reference tensor, metrics as tests/test_models.cpp). Also writes
tests/data/models/depth_anything_v2_{vits,vitb,vitl}_state.json: the name and shape of every
tensor of the three published networks, in order, and their parameter counts (`--states-only`
writes only these).
Run offline: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/gen_depth_anything_fixture.py
"""
import copy
import json
import pathlib
import sys

import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import depth_anything_v2_model as dav2  # noqa: E402
from cvdw_writer import write_cvdw  # noqa: E402
from gen_model_fixtures import relative_errors  # noqa: E402
from midas_models import imagenet_normalize  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "models"
REDUCED = dict(embed_dim=12, depth=4, heads=2, mlp_ratio=2, patch=14, pos_grid=4, features=4,
               out_channels=(4, 8, 12, 12), layers=(0, 1, 2, 3))
SEED = 21


def randomize_norms_and_gammas_(model, gen):
    """Random (not unit) LayerScale and LayerNorm affine parameters and class token, so that every
    term matters (and no two initializers of an ONNX export are equal)."""
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name.endswith("ls1.gamma") or name.endswith("ls2.gamma"):
                p.copy_(0.5 + torch.rand(p.shape, generator=gen))
            elif "norm" in name and name.endswith("weight"):
                p.copy_(1 + 0.2 * torch.randn(p.shape, generator=gen))
            elif "norm" in name and name.endswith("bias"):
                p.copy_(0.2 * torch.randn(p.shape, generator=gen))
        model.pretrained.cls_token.copy_(torch.randn(model.pretrained.cls_token.shape, generator=gen))


def run(model, rgb, R, dtype):
    m = copy.deepcopy(model).to(dtype)
    out = m(imagenet_normalize(rgb.to(dtype)))
    loss = (out * R.to(dtype)).sum()
    loss.backward()
    res = [("eval/output", out.detach(), ""), ("eval/loss", loss.detach(), "")]
    for name, p in m.named_parameters():
        if p.grad is not None:
            res.append((f"eval/grad/{name}", p.grad, ""))
    return res, out


def write_published_states():
    """The published configurations' parameter counts and state names / shapes (no weights)."""
    for encoder, config in (("vits", dav2.VITS), ("vitb", dav2.VITB), ("vitl", dav2.VITL)):
        full = dav2.DepthAnythingV2(config)
        shapes = {"parameters": sum(p.numel() for p in full.parameters()),
                  "state": [[n, list(t.shape)] for n, t in full.state_dict().items()]}
        del full
        state_path = OUT / f"depth_anything_v2_{encoder}_state.json"
        state_path.write_text(json.dumps(shapes, indent=0) + "\n")
        print(f"{state_path}: {shapes['parameters']} parameters, {len(shapes['state'])} tensors")


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    if "--states-only" in sys.argv:
        write_published_states()
        return
    torch.manual_seed(SEED)
    gen = torch.Generator().manual_seed(SEED)
    model = dav2.DepthAnythingV2(REDUCED)
    randomize_norms_and_gammas_(model, gen)
    with torch.no_grad():
        # A raised output bias so that the final ReLUs pass most pixels.
        model.depth_head.scratch.output_conv2[2].bias.fill_(0.5)
    rgb = torch.rand(2, 3, 56, 42, generator=gen)
    R = torch.randn(2, 1, 56, 42, generator=gen)
    square = torch.rand(1, 3, 56, 56, generator=gen)
    tensors = [(f"param/{n}", t, "parameter") for n, t in model.state_dict().items()]
    tensors += [("input", rgb, ""), ("R", R, ""), ("square/input", square, "")]
    res, out = run(model, rgb, R, torch.float64)
    res32, _ = run(model, rgb, R, torch.float32)
    tensors += res
    with torch.no_grad():
        sq = copy.deepcopy(model).double()(imagenet_normalize(square.double()))
    tensors.append(("square/output", sq, ""))
    print(f"output range [{out.min().item():.4g}, {out.max().item():.4g}], "
          f"{(out > 0).double().mean().item():.2f} positive, loss {res[1][1].item():.6g}")
    config = {"arch": "depth_anything_v2", "dav2_config": REDUCED, "seed": SEED,
              "generator": "tools/reference/gen_depth_anything_fixture.py",
              "torch": torch.__version__, "pytorch_f32_error": relative_errors(res, res32)}
    path = OUT / "depth_anything_v2_fixture.cvdw"
    write_cvdw(str(path), "depth_anything_v2", config, tensors)
    print(f"{path}: {sum(p.numel() for p in model.parameters())} parameters, "
          f"{path.stat().st_size} bytes")

    write_published_states()


if __name__ == "__main__":
    main()
