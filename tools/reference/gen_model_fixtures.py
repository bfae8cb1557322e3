#!/usr/bin/env python3
"""Generates tests/data/models/<arch>_fixture.cvdw: a tiny-width MiDaS v2, MiDaS v2.1 small and
Mannequin hourglass (structurally identical to the published networks, see midas_models.py and
mannequin_model.py for the width rules) with seeded random weights, run by PyTorch in float64.

Each file holds (names):
  param/<state name>       initial parameters and buffers (f32 values; the MiDaS files also hold
                           the unused scratch.refinenet4.resConfUnit1.* as the released state dicts)
  input                    RGB in [0, 1], [N, 3, H, W] (f32 values)
  R                        the loss weights: loss = sum(raw_output * R), raw output [N, 1, H, W]
  <mode>/output            raw network output [N, 1, H, W] (f64), mode = eval | train (BN mode)
  <mode>/loss              scalar (f64)
  <mode>/grad/<name>       d loss / d parameter (f64) for every parameter that the output uses
  train/state/<name>       BN buffers after the one train-mode forward (f64)
Both modes start from the same initial state. The header's config holds "pytorch_f32_error":
PyTorch's own float32 error on each reference tensor (metrics in relative_errors), which bounds
what a float32 implementation can be asked for on these ill-conditioned tiny networks. Also writes tests/data/models/full_size_state.json:
the name and shape of every tensor of the released (width 1) state dicts, in order, as checked
against the upstream code by verify_reference_models.py. MiDaS outputs use the ImageNet normalisation of
the input (as DepthNet::normalize_input); Mannequin takes the input as is.
Run offline: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/gen_model_fixtures.py
"""
import copy
import json
import pathlib
import sys

import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import mannequin_model  # noqa: E402
import midas_models  # noqa: E402
from cvdw_writer import write_cvdw  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "models"
N, H, W = 2, 64, 96

NETS = {
    # arch: (constructor, width, seed)
    "midas_v2": (lambda w: midas_models.MidasV2(w), 1 / 64, 11),
    "midas_small": (lambda w: midas_models.MidasSmall(w), 1 / 32, 12),
    "mannequin": (lambda w: mannequin_model.HourglassModel(w), 1 / 16, 13),
}


def randomize_(model, gen):
    """Default PyTorch init for convs; random BN affine parameters and running statistics so that
    every term of the BN formulas matters; the output conv's bias is raised so that the final ReLU
    of MiDaS passes most pixels."""
    with torch.no_grad():
        for name, t in model.state_dict().items():
            if name.endswith("running_mean"):
                t.copy_(torch.randn(t.shape, generator=gen) * 0.2)
            elif name.endswith("running_var"):
                t.copy_(torch.rand(t.shape, generator=gen) + 0.5)
            elif name.endswith("num_batches_tracked"):
                t.fill_(3)
        for m in model.modules():
            if isinstance(m, torch.nn.BatchNorm2d) and m.affine:
                m.weight.copy_(1 + 0.2 * torch.randn(m.weight.shape, generator=gen))
                m.bias.copy_(0.2 * torch.randn(m.bias.shape, generator=gen))


def raw_output(arch, model, rgb):
    if arch == "mannequin":
        return model(rgb)[0]
    return model(midas_models.imagenet_normalize(rgb)).unsqueeze(1)


def output_layer(arch, model):
    return model.pred_layer if arch == "mannequin" else model.scratch.output_conv[4]


def run(arch, model, rgb, R, mode, dtype=torch.float64):
    m = copy.deepcopy(model).to(dtype)
    m.train(mode == "train")
    out = raw_output(arch, m, rgb.to(dtype))
    loss = (out * R.to(dtype)).sum()
    loss.backward()
    res = [(f"{mode}/output", out.detach(), ""), (f"{mode}/loss", loss.detach(), "")]
    for name, p in m.named_parameters():
        if p.grad is not None:
            res.append((f"{mode}/grad/{name}", p.grad, ""))
    if mode == "train":
        for name, b in m.named_buffers():
            res.append((f"train/state/{name}", b, ""))
    return res, out


def relative_errors(res64, res32):
    """PyTorch's own float32 error against float64, with the metrics of tests/test_models.cpp:
    output: max error / output range; loss: relative; gradients: max error / max(max |ref|,
    1e-4 x the largest gradient of the model); buffers: max error / max(max |ref|, 1)."""
    ref = {n: t.double() for n, t, _ in res64}
    got = {n: t.double() for n, t, _ in res32}
    grad_max = max(t.abs().max().item() for n, t in ref.items() if "/grad/" in n)
    errs = {}
    for n, r in ref.items():
        e = (got[n] - r).abs().max().item()
        if n.endswith("/output"):
            errs[n] = e / (r.max() - r.min()).item()
        elif n.endswith("/loss"):
            errs[n] = e / max(abs(r.item()), 1.0)
        elif "/grad/" in n:
            errs[n] = e / max(r.abs().max().item(), 1e-4 * grad_max)
        else:
            errs[n] = e / max(r.abs().max().item(), 1.0)
    return errs


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    for arch, (make, width, seed) in NETS.items():
        torch.manual_seed(seed)
        gen = torch.Generator().manual_seed(seed)
        model = make(width)
        randomize_(model, gen)
        with torch.no_grad():
            output_layer(arch, model).bias.fill_(0.5 if arch != "mannequin" else 0.1)
        rgb = torch.rand(N, 3, H, W, generator=gen)
        R = torch.randn(N, 1, H, W, generator=gen)
        tensors = [(f"param/{n}", t, "buffer" if "running" in n or "num_batches" in n else "parameter")
                   for n, t in model.state_dict().items()]
        tensors += [("input", rgb, ""), ("R", R, "")]
        f32_errors = {}
        for mode in ("eval", "train"):
            res, out = run(arch, model, rgb, R, mode)
            tensors += res
            res32, _ = run(arch, model, rgb, R, mode, torch.float32)
            f32_errors.update(relative_errors(res, res32))
            print(f"{arch} {mode}: output range [{out.min().item():.4g}, {out.max().item():.4g}], "
                  f"{(out > 0).double().mean().item():.2f} positive, loss {res[1][1].item():.6g}")
        config = {"arch": arch, "width": width, "input_shape": [N, 3, H, W], "seed": seed,
                  "generator": "tools/reference/gen_model_fixtures.py", "torch": torch.__version__,
                  "pytorch_f32_error": f32_errors}
        path = OUT / f"{arch}_fixture.cvdw"
        write_cvdw(str(path), arch, config, tensors)
        nparams = sum(p.numel() for p in model.parameters())
        print(f"{path}: {nparams} parameters, {path.stat().st_size} bytes")


def write_full_size_shapes():
    shapes = {}
    for arch, (make, _, _) in NETS.items():
        sd = make(1.0).state_dict()
        shapes[arch] = [[n, list(t.shape)] for n, t in sd.items()]
    path = OUT / "full_size_state.json"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(shapes, separators=(",", ":")) + "\n")
    tmp.replace(path)
    print(f"{path}: {path.stat().st_size} bytes")


if __name__ == "__main__":
    main()
    write_full_size_shapes()
