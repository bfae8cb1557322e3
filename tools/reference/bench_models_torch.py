#!/usr/bin/env python3
"""PyTorch side of bench/compare_models.sh: the same configurations as bench/bench_models.cpp
(inference, or one training step = forward in BN train mode + backward + Adam) with the reference
definitions of midas_models.py / mannequin_model.py at full width, optionally with the weights
that bench_models wrote (--weights). Prints one JSON line (seconds per iteration, peak RSS, forward
GMAC per image counted with conv hooks, GFLOP/s and MFU against --peak-gflops).
Run: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/bench_models_torch.py --arch midas_v2 --mode train
"""
import argparse
import json
import pathlib
import resource
import sys
import time

import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import mannequin_model  # noqa: E402
import midas_models  # noqa: E402
from cvdw_writer import read_cvdw  # noqa: E402


def build(arch):
    if arch == "midas_v2":
        return midas_models.MidasV2(1.0)
    if arch == "midas_small":
        return midas_models.MidasSmall(1.0)
    return mannequin_model.HourglassModel(1.0)


def raw_output(arch, model, rgb):
    if arch == "mannequin":
        return model(rgb)[0]
    return model(midas_models.imagenet_normalize(rgb)).unsqueeze(1)


def forward_gmac(arch, model, h, w):
    """Multiply-accumulates of convolutions of one forward per image (what MODELS.md counts)."""
    macs = [0]

    def hook(m, inp, out):
        k = m.weight.shape[1] * m.weight.shape[2] * m.weight.shape[3]
        macs[0] += out.numel() * k

    hs = [m.register_forward_hook(hook) for m in model.modules() if isinstance(m, torch.nn.Conv2d)]
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

    def step():
        if a.mode == "infer":
            model.eval()
            with torch.no_grad():
                return raw_output(a.arch, model, rgb).sum().item()
        model.train()
        opt.zero_grad(set_to_none=True)
        loss = (raw_output(a.arch, model, rgb) * R).mean()
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
                      "size": f"{a.width}x{a.height}", "seconds": sec, "gflop": gflop, "gflops": gflop / sec,
                      "mfu": gflop / sec / a.peak_gflops,
                      "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                      "threads": torch.get_num_threads(), "check": check}))


if __name__ == "__main__":
    main()
