#!/usr/bin/env python3
"""Checks the width-multiplied reference definitions (midas_models.py, mannequin_model.py) at
width 1 against the upstream source code: identical state-dict names and shapes, identical
outputs for the same random weights in train and eval mode, and the published parameter counts.

Upstream sources are not part of this repository. Give a directory that holds
  midas/            (isl-org/MiDaS at 9983656: blocks.py, midas_net.py, midas_net_custom.py, ...)
  geffnet/          (rwightman/gen-efficientnet-pytorch)
  hourglass.py      (google/mannequinchallenge models/hourglass.py)
Run offline: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/verify_reference_models.py DIR
"""
import pathlib
import sys

import torch
import torchvision

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import mannequin_model  # noqa: E402
import midas_models  # noqa: E402


def randomize_(model, seed):
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, t in model.state_dict().items():
            if t.dtype.is_floating_point:
                if name.endswith("running_var"):
                    t.copy_(torch.rand(t.shape, generator=g) + 0.5)
                else:
                    t.copy_(torch.randn(t.shape, generator=g) * (0.05 if "weight" in name and t.dim() == 4 else 0.1))


def compare(name, ours, theirs, inputs, out_index=None, skip_prefix=None):
    ours_sd, theirs_sd = ours.state_dict(), theirs.state_dict()
    ours_shapes = {k: tuple(v.shape) for k, v in ours_sd.items()}
    theirs_shapes = {k: tuple(v.shape) for k, v in theirs_sd.items()}
    if ours_shapes != theirs_shapes:
        only_o = sorted(set(ours_shapes) - set(theirs_shapes))[:10]
        only_t = sorted(set(theirs_shapes) - set(ours_shapes))[:10]
        diff = [k for k in ours_shapes if k in theirs_shapes and ours_shapes[k] != theirs_shapes[k]][:10]
        raise SystemExit(f"{name}: state dicts differ: only ours {only_o}, only theirs {only_t}, shapes {diff}")
    randomize_(theirs, 1)
    ours.load_state_dict(theirs.state_dict())
    for mode in ("eval", "train"):
        ours.train(mode == "train")
        theirs.train(mode == "train")
        ours.load_state_dict(theirs.state_dict())
        with torch.no_grad():
            a = ours(inputs.clone())
            b = theirs(inputs.clone())
        if out_index is not None:
            a, b = a[out_index], b[out_index]
        err = (a - b).abs().max().item()
        scale = b.abs().max().item()
        print(f"{name} {mode}: max |ours - upstream| = {err:.3g} (output max {scale:.3g})")
        if not err <= 1e-5 * max(scale, 1.0):
            raise SystemExit(f"{name} {mode}: outputs differ")
    n = sum(p.numel() for k, p in ours.named_parameters() if not (skip_prefix and k.startswith(skip_prefix)))
    print(f"{name}: {n} used parameters")
    return n


def main():
    src = pathlib.Path(sys.argv[1]).resolve()
    sys.path.insert(0, str(src))
    torch.manual_seed(0)
    x = torch.rand(2, 3, 64, 96)

    import hourglass  # upstream
    n = compare("mannequin", mannequin_model.HourglassModel(1.0), hourglass.HourglassModel(3), x, out_index=0)
    assert n == 5357730, n

    import geffnet  # upstream
    import midas.blocks as blocks  # upstream

    blocks._make_pretrained_resnext101_wsl = lambda use_pretrained: blocks._make_resnet_backbone(
        torchvision.models.resnext101_32x8d())

    def hub_load(repo, model, pretrained=False, exportable=True):
        assert model == "tf_efficientnet_lite3"
        return geffnet.tf_efficientnet_lite3(pretrained=False, exportable=exportable)

    torch.hub.load = hub_load
    from midas.midas_net import MidasNet
    from midas.midas_net_custom import MidasNet_small

    n = compare("midas_v2", midas_models.MidasV2(1.0), MidasNet(None, features=256, non_negative=True), x,
                skip_prefix="scratch.refinenet4.resConfUnit1")
    assert n == 104182785, n
    upstream_small = MidasNet_small(None, features=64, backbone="efficientnet_lite3", exportable=True,
                                    non_negative=True, blocks={"expand": True})
    n = compare("midas_small", midas_models.MidasSmall(1.0), upstream_small, x,
                skip_prefix="scratch.refinenet4.resConfUnit1")
    assert n == 16600929, n
    print("all reference definitions match upstream")


if __name__ == "__main__":
    main()
