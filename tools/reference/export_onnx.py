#!/usr/bin/env python3
"""Exports the PyTorch reference networks (midas_models.py, mannequin_model.py) at tiny width to
ONNX for tests/test_convert.cpp, with the outputs PyTorch computes for the same weights:

  tests/data/onnx/<arch>_tiny.onnx       opset 14, training=TrainingMode.TRAINING,
                                         do_constant_folding=False (BatchNormalization kept with
                                         gamma / beta / running statistics; initializer names =
                                         state_dict names)
  tests/data/onnx/<arch>_tiny.expected.cvdw
      input               RGB in [0, 1], [1, 3, H, W]
      eval/output         raw output [1, 1, H, W], BN with running statistics (float64 forward)
      train/output        raw output, BN with batch statistics (float64 forward)
  tests/data/onnx/unsupported_ops.onnx   a graph with two FancyOp (custom domain), one LSTM and
                                         a Conv, for the refusal test
  tests/data/onnx/external_data.onnx     a Conv whose weight is external data (refused)
  tests/data/onnx/bad_tensors/*.onnx     well-formed protobuf whose one tensor is impossible
                                         (shapes that overflow, data that does not fit the
                                         shape; the fuzzer's findings as valid ModelProtos);
                                         `--bad-tensors` writes only these

The raw output is what DepthNet::forward_raw returns: MiDaS's network output on the ImageNet-
normalised input (unsqueezed to [N, 1, H, W]), Mannequin's log-depth prediction on the input as is.
Run offline: OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/export_onnx.py [ARCH ...]

Published weights (README, "Converting published weights"):
  OMP_NUM_THREADS=2 /usr/bin/python3 tools/reference/export_onnx.py --checkpoint FILE.pt \
      --arch midas_v2|midas_small|mannequin -o OUT.onnx
"""
import copy
import io
import pathlib
import sys

import onnx
import torch
from onnx import TensorProto, helper

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import mannequin_model  # noqa: E402
import midas_models  # noqa: E402
from cvdw_writer import write_cvdw  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "onnx"

NETS = {
    # arch: (constructor, width, seed, input H, W)
    "midas_v2": (lambda w: midas_models.MidasV2(w), 1 / 64, 21, 32, 64),
    "midas_small": (lambda w: midas_models.MidasSmall(w), 1 / 32, 22, 32, 64),
    "mannequin": (lambda w: mannequin_model.HourglassModel(w), 1 / 16, 23, 32, 48),
}


def randomize_(model, gen):
    """Random BN affine parameters and running statistics, so that every BN term matters."""
    with torch.no_grad():
        for name, t in model.state_dict().items():
            if name.endswith("running_mean"):
                t.copy_(torch.randn(t.shape, generator=gen) * 0.2)
            elif name.endswith("running_var"):
                t.copy_(torch.rand(t.shape, generator=gen) + 0.5)
        for m in model.modules():
            if isinstance(m, torch.nn.BatchNorm2d) and m.affine:
                m.weight.copy_(1 + 0.2 * torch.randn(m.weight.shape, generator=gen))
                m.bias.copy_(0.2 * torch.randn(m.bias.shape, generator=gen))


def calibrate_midas_head_(model, x, gen):
    """At tiny width the signal fades through the decoder and the head's ReLUs zero it: shift the
    head's middle conv bias so that most of its outputs are positive, and scale the last conv so
    that the output varies (std ~0.1 around 0.5) and the final ReLU passes most pixels."""
    head = model.scratch.output_conv
    model.eval()

    def output_of(layer):
        seen = {}
        hook = layer.register_forward_hook(lambda m, i, o: seen.__setitem__("o", o))
        model(x)
        hook.remove()
        return seen["o"]

    with torch.no_grad():
        pre = output_of(head[2])
        mean, std = pre.mean(dim=(0, 2, 3)), pre.std(dim=(0, 2, 3)).clamp_min(1e-4)
        head[2].bias.add_(-mean + 0.5 * std)
        std = output_of(head[3]).std(dim=(0, 2, 3)).clamp_min(1e-4)
        w = torch.randn(head[4].weight.shape, generator=gen) * 0.1 / std.view(1, -1, 1, 1)
        head[4].weight.copy_(w / w.shape[1] ** 0.5)
        head[4].bias.fill_(0.5)


def raw_output(arch, model, rgb):
    if arch == "mannequin":
        return model(rgb)[0]
    return model(midas_models.imagenet_normalize(rgb)).unsqueeze(1)


def export_for_cvd(model, example, output_names):
    """The export cvd converts: opset 14, training=TrainingMode.TRAINING and
    do_constant_folding=False keep every BatchNormalization with gamma, beta and the running
    statistics (an eval-mode export folds them into the convolutions), and initializer names
    equal the state_dict names. A training-mode export runs one forward in train mode, which would
    update the running statistics before they are saved: BN momentum is set to 0 on a copy so that
    the saved statistics are the model's."""
    m = copy.deepcopy(model)
    for mod in m.modules():
        if isinstance(mod, torch.nn.modules.batchnorm._BatchNorm):
            mod.momentum = 0.0
    buf = io.BytesIO()
    torch.onnx.export(m, (example,), buf, opset_version=14, training=torch.onnx.TrainingMode.TRAINING,
                      do_constant_folding=False, input_names=["input"], output_names=output_names)
    return onnx.load_from_string(buf.getvalue())


def output_names(arch):
    return ["pred", "confidence"] if arch == "mannequin" else ["depth"]


def compact(model_proto):
    """Shortens the file without changing the graph: intermediate values renamed v<i>, node names
    and doc strings dropped (initializer, input and output names are kept)."""
    g = model_proto.graph
    keep = {t.name for t in g.initializer} | {i.name for i in g.input} | {o.name for o in g.output}
    rename = {}
    for n in g.node:
        n.name = ""
        n.doc_string = ""
        for i, name in enumerate(n.output):
            if name and name not in keep:
                rename.setdefault(name, f"v{len(rename)}")
                n.output[i] = rename[name]
        for i, name in enumerate(n.input):
            n.input[i] = rename.get(name, name)
    del g.value_info[:]
    g.doc_string = ""
    return model_proto


def unsupported_model():
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 2, 4, 4])
    # LSTM's Y: [seq_length 1, num_directions 1, batch 2, hidden_size 2]; a declared shape keeps
    # the model valid for onnx.checker, which cvd convert runs after its own checks.
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 1, 2, 2])
    w = helper.make_tensor("conv.weight", TensorProto.FLOAT, [2, 2, 1, 1], [1.0, 0.0, 0.0, 1.0])
    nodes = [
        helper.make_node("Conv", ["x", "conv.weight"], ["a"]),
        helper.make_node("FancyOp", ["a"], ["b"], domain="com.example"),
        helper.make_node("FancyOp", ["b"], ["c"], domain="com.example"),
        helper.make_node("Reshape", ["c", "shape"], ["d"]),
        helper.make_node("LSTM", ["d", "lstm_w", "lstm_r"], ["y"], hidden_size=2),
    ]
    inits = [w, helper.make_tensor("shape", TensorProto.INT64, [3], [1, 2, 16]),
             helper.make_tensor("lstm_w", TensorProto.FLOAT, [1, 8, 16], [0.0] * 128),
             helper.make_tensor("lstm_r", TensorProto.FLOAT, [1, 8, 2], [0.0] * 16)]
    graph = helper.make_graph(nodes, "unsupported", [x], [y], inits)
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 14),
                                                   helper.make_opsetid("com.example", 1)])


def external_data_model():
    """A Conv whose weight is stored outside the file (the .bin is deliberately not written)."""
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 1, 2, 2])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, None)
    w = TensorProto(name="conv.weight", data_type=TensorProto.FLOAT, dims=[1, 1, 1, 1],
                    data_location=TensorProto.EXTERNAL)
    w.external_data.add(key="location", value="weights.bin")
    graph = helper.make_graph([helper.make_node("Conv", ["x", "conv.weight"], ["y"])], "external", [x], [y], [w])
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 14)])


def bad_tensor_models():
    """One model per impossible initializer: name -> ModelProto (each a Conv on that weight)."""
    big = 1 << 40
    cases = {
        "impossibly_large_shape": TensorProto(name="w", data_type=TensorProto.FLOAT,
                                              dims=[big, big, big]),
        "zero_dim_with_huge_strides": TensorProto(name="w", data_type=TensorProto.FLOAT,
                                                  dims=[0, 1 << 62, 1 << 62]),
        "negative_dimension": TensorProto(name="w", data_type=TensorProto.FLOAT, dims=[-1, 2]),
        "float_data_shorter_than_shape": TensorProto(name="w", data_type=TensorProto.FLOAT,
                                                     dims=[1, 1, 1, 3], float_data=[1.0]),
        "raw_data_shorter_than_shape": TensorProto(name="w", data_type=TensorProto.FLOAT,
                                                   dims=[1, 1, 1, 3], raw_data=b"\0" * 10),
        "int64_raw_data_of_odd_length": TensorProto(name="w", data_type=TensorProto.INT64,
                                                    dims=[2], raw_data=b"\0" * 15),
    }
    models = {}
    for name, w in cases.items():
        x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 1, 2, 2])
        y = helper.make_tensor_value_info("y", TensorProto.FLOAT, None)
        graph = helper.make_graph([helper.make_node("Conv", ["x", "w"], ["y"])], name, [x], [y],
                                  [w])
        models[name] = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 14)])
    return models


def write_bad_tensor_models():
    (OUT / "bad_tensors").mkdir(parents=True, exist_ok=True)
    for name, m in bad_tensor_models().items():
        with open(OUT / "bad_tensors" / f"{name}.onnx", "wb") as f:
            f.write(m.SerializeToString())


CONSTRUCTORS = {
    "midas_v2": midas_models.MidasV2,
    "midas_small": midas_models.MidasSmall,
    "mannequin": mannequin_model.HourglassModel,
}


def export_checkpoint(arch, checkpoint, out, height, width):
    """Exports a published PyTorch checkpoint (full width) for `cvd convert`."""
    model = CONSTRUCTORS[arch](1.0)
    state = torch.load(checkpoint, map_location="cpu")
    if isinstance(state, dict) and "state_dict" in state:
        state = state["state_dict"]
    if isinstance(state, dict) and "model" in state and isinstance(state["model"], dict):
        state = state["model"]
    state = {k[len("module."):] if k.startswith("module.") else k: v for k, v in state.items()}
    model.load_state_dict(state)  # strict: every name and shape of the published network
    model.eval()
    example = torch.rand(1, 3, height, width)
    if arch != "mannequin":
        example = midas_models.imagenet_normalize(example)
    onnx.save(export_for_cvd(model, example, output_names(arch)), out)
    print(f"wrote {out}: convert with  cvd convert {out} --arch {arch} -o {arch}.cvdw")


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--checkpoint":
        import argparse
        ap = argparse.ArgumentParser(description="Export a published checkpoint for cvd convert")
        ap.add_argument("--checkpoint", required=True, help="the published .pt / .pth file")
        ap.add_argument("--arch", required=True, choices=sorted(CONSTRUCTORS))
        ap.add_argument("-o", "--output", required=True, help="ONNX file to write")
        ap.add_argument("--size", type=int, nargs=2, default=[384, 384], metavar=("H", "W"),
                        help="example input size (multiples of 32; the weights do not depend on it)")
        a = ap.parse_args()
        export_checkpoint(a.arch, a.checkpoint, a.output, *a.size)
        return
    OUT.mkdir(parents=True, exist_ok=True)
    if sys.argv[1:] == ["--bad-tensors"]:
        write_bad_tensor_models()
        return
    only = sys.argv[1:]
    for arch, (make, width, seed, h, w) in NETS.items():
        if only and arch not in only:
            continue
        torch.manual_seed(seed)
        gen = torch.Generator().manual_seed(seed)
        model = make(width)
        randomize_(model, gen)
        rgb = torch.rand(1, 3, h, w, generator=gen)
        example = rgb if arch == "mannequin" else midas_models.imagenet_normalize(rgb)
        if arch != "mannequin":
            calibrate_midas_head_(model, example, gen)
        model.eval()
        proto = compact(export_for_cvd(model, example, output_names(arch)))
        onnx.checker.check_model(proto)
        path = OUT / f"{arch}_tiny.onnx"
        onnx.save(proto, str(path))
        tensors = [("input", rgb, "")]
        for mode in ("eval", "train"):
            m = copy.deepcopy(model).double()
            m.train(mode == "train")
            with torch.no_grad():
                out = raw_output(arch, m, rgb.double())
            tensors.append((f"{mode}/output", out, ""))
            print(f"{arch} {mode}: output range [{out.min().item():.4g}, {out.max().item():.4g}]")
        config = {"arch": arch, "width": width, "seed": seed, "opset": 14,
                  "generator": "tools/reference/export_onnx.py", "torch": torch.__version__}
        write_cvdw(str(OUT / f"{arch}_tiny.expected.cvdw"), arch, config, tensors)
        nparams = sum(p.numel() for p in model.parameters())
        ops = sorted({n.op_type for n in proto.graph.node})
        print(f"{path.name}: {nparams} parameters, {path.stat().st_size} bytes, ops {ops}")
    if not only:
        onnx.save(unsupported_model(), str(OUT / "unsupported_ops.onnx"))
        with open(OUT / "external_data.onnx", "wb") as f:
            f.write(external_data_model().SerializeToString())
        write_bad_tensor_models()


if __name__ == "__main__":
    main()
