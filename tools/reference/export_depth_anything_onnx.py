#!/usr/bin/env python3
"""ONNX exports of Depth Anything V2 (depth_anything_v2_model.py) for `cvd convert`.

Without arguments: the reduced network of the fixtures (4 blocks of width 24; seed 31) for
tests/test_convert_depth_anything.cpp:
  tests/data/onnx/depth_anything_v2_tiny.onnx            opset 17 (LayerNormalization nodes),
                                                         do_constant_folding=False (initializer
                                                         names = state names)
  tests/data/onnx/depth_anything_v2_tiny.expected.cvdw   input [1, 3, 56, 56] (normalised RGB),
                                                         output [1, 1, 56, 56] (float64 forward)

A published checkpoint (depth_anything_v2_vits.pth, Apache-2.0), for the README's recipe:
  OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/export_depth_anything_onnx.py \\
      --checkpoint depth_anything_v2_vits.pth [--encoder vits|vitb|vitl] -o da2.onnx
then  cvd convert da2.onnx --arch depth_anything_v2[_vitb|_vitl] -o da2.cvdw
(--random-seed N instead of --checkpoint exports seeded random weights of the full-size network;
--expected FILE.cvdw adds the example input and PyTorch's output on it: the optional full-size
parity test, tests/test_depth_anything_full_size.cpp, uses both.)
"""
import argparse
import copy
import io
import pathlib
import sys

import onnx
import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import depth_anything_v2_model as dav2  # noqa: E402
from cvdw_writer import write_cvdw  # noqa: E402
from export_onnx import compact  # noqa: E402
from gen_depth_anything_fixture import REDUCED, randomize_norms_and_gammas_  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "onnx"
ENCODERS = {"vits": dav2.VITS, "vitb": dav2.VITB, "vitl": dav2.VITL}


def export(model, example):
    buf = io.BytesIO()
    torch.onnx.export(copy.deepcopy(model).eval(), (example,), buf, opset_version=17,
                      do_constant_folding=False, input_names=["input"], output_names=["depth"])
    return onnx.load_from_string(buf.getvalue())


def tiny():
    OUT.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(31)
    gen = torch.Generator().manual_seed(31)
    model = dav2.DepthAnythingV2(REDUCED)
    with torch.no_grad():
        # Distinct values everywhere: torch.onnx merges initializers of equal values (all-one
        # LayerNorm weights would become one shared tensor), which trained weights never have.
        for name, p in model.named_parameters():
            if name.endswith("gamma"):
                p.copy_(0.5 + torch.rand(p.shape, generator=gen))
            elif "norm" in name:
                p.add_(0.2 * torch.randn(p.shape, generator=gen))
        model.depth_head.scratch.output_conv2[2].bias.fill_(0.5)
    # Square, with the position grid's size: the embedding is used as is (torch 1.13 cannot export
    # the bicubic resize with scale factors; the weights do not depend on the path).
    x = torch.randn(1, 3, 56, 56, generator=gen)
    proto = compact(export(model, x))
    path = OUT / "depth_anything_v2_tiny.onnx"
    onnx.save(proto, str(path))
    with torch.no_grad():
        out = copy.deepcopy(model).double()(x.double())
    write_cvdw(str(OUT / "depth_anything_v2_tiny.expected.cvdw"), "depth_anything_v2",
               {"dav2_config": REDUCED, "generator": "tools/reference/export_depth_anything_onnx.py",
                "torch": torch.__version__},
               [("input", x, ""), ("output", out, "")])
    ops = sorted({n.op_type for n in proto.graph.node})
    print(f"{path}: {path.stat().st_size} bytes, ops {', '.join(ops)}")


def main():
    if len(sys.argv) == 1:
        tiny()
        return
    ap = argparse.ArgumentParser(description="Export a Depth Anything V2 checkpoint for cvd convert")
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="depth_anything_v2_<encoder>.pth")
    src.add_argument("--random-seed", type=int,
                     help="no checkpoint: seeded random weights (to check a full-size conversion)")
    ap.add_argument("--encoder", default="vits", choices=sorted(ENCODERS))
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--expected", help="also write the example input and PyTorch's float64 output "
                                       "on it (a .cvdw: input, output) for a parity check")
    ap.add_argument("--size", type=int, nargs=2, default=[518, 518], metavar=("H", "W"),
                    help="example input size (keep 518 x 518: other sizes resize the position "
                         "embedding bicubically, which torch 1.13 cannot export)")
    a = ap.parse_args()
    if a.random_seed is not None:
        torch.manual_seed(a.random_seed)
    model = dav2.DepthAnythingV2(ENCODERS[a.encoder])
    if a.random_seed is not None:
        # Default initialisation makes every LayerScale gamma and LayerNorm weight / bias equal,
        # and the exporter then keeps one initializer for all of them (names lost): randomise
        # them as the fixtures do, so that the export looks like a trained checkpoint's.
        gen = torch.Generator().manual_seed(a.random_seed)
        randomize_norms_and_gammas_(model, gen)
        with torch.no_grad():  # so that the final ReLUs pass most pixels
            model.depth_head.scratch.output_conv2[2].bias.fill_(0.5)
    if a.checkpoint:
        state = torch.load(a.checkpoint, map_location="cpu")
        model.load_state_dict(state)  # strict: every name and shape of the published network
    x = torch.rand(1, 3, *a.size)
    onnx.save(export(model, x), a.output)
    if a.expected:
        with torch.no_grad():
            out = copy.deepcopy(model).double().eval()(x.double())
        write_cvdw(a.expected, "depth_anything_v2",
                   {"encoder": a.encoder, "generator": "tools/reference/export_depth_anything_onnx.py",
                    "torch": torch.__version__},
                   [("input", x, ""), ("output", out, "")])
    arch = "depth_anything_v2" + ("" if a.encoder == "vits" else "_" + a.encoder)
    print(f"wrote {a.output}: convert with  cvd convert {a.output} --arch {arch} "
          f"-o {arch}.cvdw")


if __name__ == "__main__":
    main()
