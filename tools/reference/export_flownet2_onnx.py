#!/usr/bin/env python3
"""Exports the PyTorch FlowNet2 reference (flownet2_model.py) to ONNX for `cvd convert --arch
flownet2` and tests/test_convert_flownet2.cpp, with Correlation, Resample2d and ChannelNorm as
custom-domain nodes (domain "cvd.flownet2", version 1; names and attributes: README, "FlowNet2
ONNX custom ops", and flownet2_model.py).

  tests/data/onnx/flownet2_tiny.onnx
      the network of tests/data/models/flownet2_fixture.cvdw (gen_flownet2_fixture.py: width
      1/32, seed 21, predict_flow layers x4, f32 weights), traced on a 64x128 pair, opset 14,
      do_constant_folding=False (initializer names = state_dict names), intermediate values
      renamed v<i>. The weights are the fixture's bit for bit (checked here), so the fixture's
      PyTorch float64 outputs are the reference outputs of this file too.
The refusal tests edit the attributes of this graph in memory (no second file).

Run offline: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/export_flownet2_onnx.py

Published weights (FlowNet2_checkpoint.pth.tar of NVIDIA/flownet2-pytorch):
  OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/export_flownet2_onnx.py \
      --checkpoint FlowNet2_checkpoint.pth.tar -o flownet2.onnx
"""
import argparse
import pathlib
import sys
import tempfile

import onnx
import torch
import onnx.numpy_helper

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import flownet2_model  # noqa: E402
import gen_flownet2_fixture as fixture  # noqa: E402
from export_onnx import compact  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "onnx"


def fixture_network():
    """The network of gen_flownet2_fixture.py, built by the same recipe (seeded default init,
    predict_flow layers scaled, f32 values)."""
    torch.manual_seed(fixture.SEED)
    net = flownet2_model.FlowNet2(fixture.WIDTH)
    with torch.no_grad():
        for name, p in net.named_parameters():
            if ".predict_flow" in name:
                p.mul_(fixture.PREDICT_SCALE)
            p.copy_(p.float())
    return net.eval()


def export(net, height, width):
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "flownet2.onnx"
        flownet2_model.export_onnx(net, path, height, width)
        return onnx.load(str(path))


def check_fixture_weights(proto, net):
    """Every initializer named after a state_dict entry holds exactly that tensor."""
    state = net.state_dict()
    inits = {t.name: onnx.numpy_helper.to_array(t) for t in proto.graph.initializer}
    missing = [k for k in state if k not in inits]
    assert not missing, f"state tensors not exported as initializers: {missing[:5]}"
    for k, v in state.items():
        assert (torch.from_numpy(inits[k].copy()) == v.float()).all(), k


def export_checkpoint(checkpoint, out, height, width, net_width=1.0):
    net = flownet2_model.FlowNet2(net_width)
    state = torch.load(checkpoint, map_location="cpu")
    if isinstance(state, dict) and "state_dict" in state:
        state = state["state_dict"]
    state = {k[len("module."):] if k.startswith("module.") else k: v for k, v in state.items()}
    net.load_state_dict(state)  # strict: every name and shape of the published network
    onnx.save(export(net.eval(), height, width), out)
    wflag = "" if net_width == 1.0 else f" --width {net_width}"
    print(f"wrote {out}: convert with  cvd convert {out} --arch flownet2{wflag} -o flownet2.cvdw")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", help="a published FlowNet2 checkpoint (.pth.tar)")
    ap.add_argument("-o", "--output", help="ONNX file to write (with --checkpoint)")
    ap.add_argument("--size", type=int, nargs=2, default=[384, 512], metavar=("H", "W"),
                    help="example input size (multiples of 64; the weights do not depend on it)")
    ap.add_argument("--width", type=float, default=1.0, help="channel width of the checkpoint's network")
    a = ap.parse_args()
    if a.checkpoint:
        export_checkpoint(a.checkpoint, a.output or "flownet2.onnx", *a.size, net_width=a.width)
        return
    net = fixture_network()
    proto = compact(export(net, fixture.H, fixture.W))
    check_fixture_weights(proto, net)
    onnx.checker.check_model(proto)
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / "flownet2_tiny.onnx"
    onnx.save(proto, str(path))
    ops = sorted({(n.domain + "::" if n.domain else "") + n.op_type for n in proto.graph.node})
    nparams = sum(p.numel() for p in net.parameters())
    print(f"{path.name}: {nparams} parameters, {path.stat().st_size} bytes, ops {ops}")


if __name__ == "__main__":
    main()
