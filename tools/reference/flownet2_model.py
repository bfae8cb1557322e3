"""FlowNet2 (Ilg et al. 2017) as in NVIDIA/flownet2-pytorch (models.FlowNet2, batchNorm=False,
div_flow 20, rgb_max 255), written from the facts of docs/models.md section 5 in pure PyTorch: the CUDA
Correlation, Resample2d and ChannelNorm packages are replaced by the equivalent torch code below.
Module and parameter names follow the upstream state_dict ("flownetc.conv1.0.weight", ...).

ONNX export (export_onnx below) writes the three flownet2-specific layers as custom-domain ops,
domain "cvd.flownet2" (opset version 1), so that the graph stays small and a converter maps them
1:1:
  Correlation(a, b) -> y    ints pad_size, kernel_size, max_displacement, stride1, stride2,
                            corr_multiply (FlowNetC: 20, 1, 20, 1, 2, 1); semantics of
                            engine/kernel_params.h CorrelationParams (divided by k^2 C)
  Resample2d(img, flow) -> warped   int kernel_size (1); bilinear sample at (x + u, y + v) with
                            clamped indices = grid_sample(bilinear, border, align_corners=True)
  ChannelNorm(x) -> y       int norm_deg (2); sqrt(sum_c x^2), [N, C, H, W] -> [N, 1, H, W]

`width` scales every internal channel count c to max(1, floor(c * width + 0.5)); the image
inputs (3 / 6 / 11 / 12 channels), the flows (2) and the 441 correlation channels are fixed, so
a tiny width is structurally identical to the published network (width 1: 162,518,834
parameters).
"""
import math

import torch
import torch.nn as nn
import torch.nn.functional as F

DIV_FLOW = 20.0
RGB_MAX = 255.0


def scaled(c, width):
    return max(1, int(math.floor(c * width + 0.5)))


def conv(cin, cout, k=3, s=1):
    return nn.Sequential(nn.Conv2d(cin, cout, k, s, (k - 1) // 2, bias=True), nn.LeakyReLU(0.1))


def i_conv(cin, cout):
    return nn.Sequential(nn.Conv2d(cin, cout, 3, 1, 1, bias=True))


def predict_flow(cin):
    return nn.Conv2d(cin, 2, 3, 1, 1, bias=True)


def deconv(cin, cout):
    return nn.Sequential(nn.ConvTranspose2d(cin, cout, 4, 2, 1, bias=True), nn.LeakyReLU(0.1))


CUSTOM_DOMAIN = "cvd.flownet2"
_EXPORTING = [False]  # set by export_onnx: route the three layers through the custom ops


class _CorrelationOp(torch.autograd.Function):
    # Non-tensor arguments break torch 1.13's export of a custom Function; FlowNet2 uses one
    # parameter set, kept here while exporting.
    params = (20, 1, 20, 1, 2)

    @staticmethod
    def forward(ctx, a, b):
        # The values are computed outside the ONNX tracer (which otherwise records the loop's
        # ops inside the custom op and fails) and handed over as a constant.
        state = torch._C._get_tracing_state()
        torch._C._set_tracing_state(None)
        try:
            with torch.no_grad():
                values = _correlation(a, b, *_CorrelationOp.params).detach()
        finally:
            torch._C._set_tracing_state(state)
        return a.new_zeros(values.shape) + values

    @staticmethod
    def symbolic(g, a, b):
        pad, k, md, s1, s2 = _CorrelationOp.params
        return g.op(CUSTOM_DOMAIN + "::Correlation", a, b, pad_size_i=pad, kernel_size_i=k, max_displacement_i=md,
                    stride1_i=s1, stride2_i=s2, corr_multiply_i=1)


class _Resample2dOp(torch.autograd.Function):
    @staticmethod
    def forward(ctx, img, flow):
        return _resample2d(img, flow)

    @staticmethod
    def symbolic(g, img, flow):
        return g.op(CUSTOM_DOMAIN + "::Resample2d", img, flow, kernel_size_i=1)


class _ChannelNormOp(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x):
        return _channel_norm(x)

    @staticmethod
    def symbolic(g, x):
        return g.op(CUSTOM_DOMAIN + "::ChannelNorm", x, norm_deg_i=2)


def correlation(a, b, pad, kernel_size, max_displacement, stride1, stride2):
    if _EXPORTING[0]:
        _CorrelationOp.params = (pad, kernel_size, max_displacement, stride1, stride2)
        return _CorrelationOp.apply(a, b)
    return _correlation(a, b, pad, kernel_size, max_displacement, stride1, stride2)


def resample2d(img, flow):
    return _Resample2dOp.apply(img, flow) if _EXPORTING[0] else _resample2d(img, flow)


def channel_norm(x):
    return _ChannelNormOp.apply(x) if _EXPORTING[0] else _channel_norm(x)


def export_onnx(net, path, height=384, width=512, opset=14):
    """Exports FlowNet2 (inputs img0, img1: RGB [1, 3, H, W] in [0, 255]; output flow) with the
    custom-domain ops and the initializers under the state_dict names."""
    _EXPORTING[0] = True
    try:
        img = torch.zeros(1, 3, height, width)
        torch.onnx.export(net, (img, img), str(path), input_names=["img0", "img1"], output_names=["flow"],
                          opset_version=opset, do_constant_folding=False,
                          custom_opsets={CUSTOM_DOMAIN: 1}, keep_initializers_as_inputs=False)
    finally:
        _EXPORTING[0] = False


def _correlation(a, b, pad, kernel_size, max_displacement, stride1, stride2):
    """FlowNetC correlation (see engine/kernel_params.h, CorrelationParams): for each
    displacement (tj, ti) in [-r, r]^2, r = max_displacement // stride2, the channel mean of
    a * shifted b over the k x k patch, zero padding `pad`."""
    n, c, h, w = a.shape
    kr = (kernel_size - 1) // 2
    r = max_displacement // stride2
    border = max_displacement + kr
    oh = math.ceil((h + 2 * pad - 2 * border) / stride1)
    ow = math.ceil((w + 2 * pad - 2 * border) / stride1)
    ap = F.pad(a, (pad, pad, pad, pad))
    bp = F.pad(b, (pad, pad, pad, pad))

    def window(t, y0, x0):
        return t[:, :, y0:y0 + (oh - 1) * stride1 + 1:stride1, x0:x0 + (ow - 1) * stride1 + 1:stride1]

    outs = []
    for tj in range(-r, r + 1):
        for ti in range(-r, r + 1):
            acc = 0
            for dj in range(-kr, kr + 1):
                for di in range(-kr, kr + 1):
                    ya, xa = border + dj, border + di
                    acc = acc + (window(ap, ya, xa) * window(bp, ya + tj * stride2, xa + ti * stride2)).sum(1)
            outs.append(acc / (kernel_size * kernel_size * c))
    return torch.stack(outs, 1)


def _resample2d(img, flow):
    """flownet2 Resample2d: bilinear sample of img at (x + u, y + v) with clamped (border)
    indices = grid_sample(bilinear, border, align_corners=True)."""
    n, _, h, w = img.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=img.dtype), torch.arange(w, dtype=img.dtype), indexing="ij")
    x = xs + flow[:, 0]
    y = ys + flow[:, 1]
    grid = torch.stack((2 * x / max(w - 1, 1) - 1, 2 * y / max(h - 1, 1) - 1), dim=-1)
    return F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=True)


def _channel_norm(x):
    return x.pow(2).sum(1, keepdim=True).sqrt()


class FlowNetS(nn.Module):
    def __init__(self, width=1.0, input_channels=12):
        super().__init__()
        s = lambda c: scaled(c, width)  # noqa: E731
        self.conv1 = conv(input_channels, s(64), 7, 2)
        self.conv2 = conv(s(64), s(128), 5, 2)
        self.conv3 = conv(s(128), s(256), 5, 2)
        self.conv3_1 = conv(s(256), s(256))
        self.conv4 = conv(s(256), s(512), 3, 2)
        self.conv4_1 = conv(s(512), s(512))
        self.conv5 = conv(s(512), s(512), 3, 2)
        self.conv5_1 = conv(s(512), s(512))
        self.conv6 = conv(s(512), s(1024), 3, 2)
        self.conv6_1 = conv(s(1024), s(1024))
        self.deconv5 = deconv(s(1024), s(512))
        self.deconv4 = deconv(2 * s(512) + 2, s(256))
        self.deconv3 = deconv(s(512) + s(256) + 2, s(128))
        self.deconv2 = deconv(s(256) + s(128) + 2, s(64))
        self.predict_flow6 = predict_flow(s(1024))
        self.predict_flow5 = predict_flow(2 * s(512) + 2)
        self.predict_flow4 = predict_flow(s(512) + s(256) + 2)
        self.predict_flow3 = predict_flow(s(256) + s(128) + 2)
        self.predict_flow2 = predict_flow(s(128) + s(64) + 2)
        for name in ("6_to_5", "5_to_4", "4_to_3", "3_to_2"):
            setattr(self, "upsampled_flow" + name, nn.ConvTranspose2d(2, 2, 4, 2, 1, bias=False))

    def forward(self, x):
        c2 = self.conv2(self.conv1(x))
        c3 = self.conv3_1(self.conv3(c2))
        return decoder(self, c2, c3, x)


def decoder(m, c2, c3, _x):
    c4 = m.conv4_1(m.conv4(c3))
    c5 = m.conv5_1(m.conv5(c4))
    c6 = m.conv6_1(m.conv6(c5))
    flow6 = m.predict_flow6(c6)
    cat5 = torch.cat((c5, m.deconv5(c6), m.upsampled_flow6_to_5(flow6)), 1)
    flow5 = m.predict_flow5(cat5)
    cat4 = torch.cat((c4, m.deconv4(cat5), m.upsampled_flow5_to_4(flow5)), 1)
    flow4 = m.predict_flow4(cat4)
    cat3 = torch.cat((c3, m.deconv3(cat4), m.upsampled_flow4_to_3(flow4)), 1)
    flow3 = m.predict_flow3(cat3)
    cat2 = torch.cat((c2, m.deconv2(cat3), m.upsampled_flow3_to_2(flow3)), 1)
    return m.predict_flow2(cat2)


class FlowNetC(FlowNetS):
    def __init__(self, width=1.0):
        super().__init__(width, input_channels=3)
        s = lambda c: scaled(c, width)  # noqa: E731
        del self.conv3_1
        self.conv_redir = conv(s(256), s(32), 1, 1)
        self.conv3_1 = conv(s(32) + 441, s(256))
        for name in ("6_to_5", "5_to_4", "4_to_3", "3_to_2"):
            setattr(self, "upsampled_flow" + name, nn.ConvTranspose2d(2, 2, 4, 2, 1, bias=True))
        # upstream registration order: conv1, conv2, conv3, conv_redir, conv3_1, conv4 ...
        order = ["conv1", "conv2", "conv3", "conv_redir", "conv3_1", "conv4", "conv4_1", "conv5", "conv5_1", "conv6",
                 "conv6_1", "deconv5", "deconv4", "deconv3", "deconv2", "predict_flow6", "predict_flow5",
                 "predict_flow4", "predict_flow3", "predict_flow2", "upsampled_flow6_to_5", "upsampled_flow5_to_4",
                 "upsampled_flow4_to_3", "upsampled_flow3_to_2"]
        self._modules = type(self._modules)((k, self._modules[k]) for k in order)

    def forward(self, x):
        def tower(img):
            c2 = self.conv2(self.conv1(img))
            return c2, self.conv3(c2)

        c2a, c3a = tower(x[:, :3])
        _, c3b = tower(x[:, 3:])
        corr = F.leaky_relu(correlation(c3a, c3b, 20, 1, 20, 1, 2), 0.1)
        c3 = self.conv3_1(torch.cat((self.conv_redir(c3a), corr), 1))
        return decoder(self, c2a, c3, x)


class FlowNetSD(nn.Module):
    def __init__(self, width=1.0):
        super().__init__()
        s = lambda c: scaled(c, width)  # noqa: E731
        self.conv0 = conv(6, s(64))
        self.conv1 = conv(s(64), s(64), 3, 2)
        self.conv1_1 = conv(s(64), s(128))
        self.conv2 = conv(s(128), s(128), 3, 2)
        self.conv2_1 = conv(s(128), s(128))
        self.conv3 = conv(s(128), s(256), 3, 2)
        self.conv3_1 = conv(s(256), s(256))
        self.conv4 = conv(s(256), s(512), 3, 2)
        self.conv4_1 = conv(s(512), s(512))
        self.conv5 = conv(s(512), s(512), 3, 2)
        self.conv5_1 = conv(s(512), s(512))
        self.conv6 = conv(s(512), s(1024), 3, 2)
        self.conv6_1 = conv(s(1024), s(1024))
        self.deconv5 = deconv(s(1024), s(512))
        self.deconv4 = deconv(2 * s(512) + 2, s(256))
        self.deconv3 = deconv(s(512) + s(256) + 2, s(128))
        self.deconv2 = deconv(s(256) + s(128) + 2, s(64))
        self.inter_conv5 = i_conv(2 * s(512) + 2, s(512))
        self.inter_conv4 = i_conv(s(512) + s(256) + 2, s(256))
        self.inter_conv3 = i_conv(s(256) + s(128) + 2, s(128))
        self.inter_conv2 = i_conv(s(128) + s(64) + 2, s(64))
        self.predict_flow6 = predict_flow(s(1024))
        self.predict_flow5 = predict_flow(s(512))
        self.predict_flow4 = predict_flow(s(256))
        self.predict_flow3 = predict_flow(s(128))
        self.predict_flow2 = predict_flow(s(64))
        for name in ("6_to_5", "5_to_4", "4_to_3", "3_to_2"):
            setattr(self, "upsampled_flow" + name, nn.ConvTranspose2d(2, 2, 4, 2, 1, bias=True))

    def forward(self, x):
        c1 = self.conv1_1(self.conv1(self.conv0(x)))
        c2 = self.conv2_1(self.conv2(c1))
        c3 = self.conv3_1(self.conv3(c2))
        c4 = self.conv4_1(self.conv4(c3))
        c5 = self.conv5_1(self.conv5(c4))
        c6 = self.conv6_1(self.conv6(c5))
        flow6 = self.predict_flow6(c6)
        cat5 = torch.cat((c5, self.deconv5(c6), self.upsampled_flow6_to_5(flow6)), 1)
        flow5 = self.predict_flow5(self.inter_conv5(cat5))
        cat4 = torch.cat((c4, self.deconv4(cat5), self.upsampled_flow5_to_4(flow5)), 1)
        flow4 = self.predict_flow4(self.inter_conv4(cat4))
        cat3 = torch.cat((c3, self.deconv3(cat4), self.upsampled_flow4_to_3(flow4)), 1)
        flow3 = self.predict_flow3(self.inter_conv3(cat3))
        cat2 = torch.cat((c2, self.deconv2(cat3), self.upsampled_flow3_to_2(flow3)), 1)
        return self.predict_flow2(self.inter_conv2(cat2))


class FlowNetFusion(nn.Module):
    def __init__(self, width=1.0):
        super().__init__()
        s = lambda c: scaled(c, width)  # noqa: E731
        self.conv0 = conv(11, s(64))
        self.conv1 = conv(s(64), s(64), 3, 2)
        self.conv1_1 = conv(s(64), s(128))
        self.conv2 = conv(s(128), s(128), 3, 2)
        self.conv2_1 = conv(s(128), s(128))
        self.deconv1 = deconv(s(128), s(32))
        self.deconv0 = deconv(s(128) + s(32) + 2, s(16))
        self.inter_conv1 = i_conv(s(128) + s(32) + 2, s(32))
        self.inter_conv0 = i_conv(s(64) + s(16) + 2, s(16))
        self.predict_flow2 = predict_flow(s(128))
        self.predict_flow1 = predict_flow(s(32))
        self.predict_flow0 = predict_flow(s(16))
        self.upsampled_flow2_to_1 = nn.ConvTranspose2d(2, 2, 4, 2, 1, bias=True)
        self.upsampled_flow1_to_0 = nn.ConvTranspose2d(2, 2, 4, 2, 1, bias=True)

    def forward(self, x):
        c0 = self.conv0(x)
        c1 = self.conv1_1(self.conv1(c0))
        c2 = self.conv2_1(self.conv2(c1))
        flow2 = self.predict_flow2(c2)
        cat1 = torch.cat((c1, self.deconv1(c2), self.upsampled_flow2_to_1(flow2)), 1)
        flow1 = self.predict_flow1(self.inter_conv1(cat1))
        cat0 = torch.cat((c0, self.deconv0(cat1), self.upsampled_flow1_to_0(flow1)), 1)
        return self.predict_flow0(self.inter_conv0(cat0))


class FlowNet2(nn.Module):
    def __init__(self, width=1.0):
        super().__init__()
        self.flownetc = FlowNetC(width)
        self.flownets_1 = FlowNetS(width)
        self.flownets_2 = FlowNetS(width)
        self.flownets_d = FlowNetSD(width)
        self.flownetfusion = FlowNetFusion(width)

    @staticmethod
    def normalize(img0, img1):
        """img0, img1 [N, 3, H, W] RGB in [0, 255] -> x [N, 6, H, W]: minus the per-image-pair,
        per-channel mean over both frames, / rgb_max."""
        both = torch.stack((img0, img1), 2)  # [N, 3, 2, H, W] as upstream
        mean = both.reshape(both.shape[0], both.shape[1], -1).mean(-1).view(both.shape[0], 3, 1, 1, 1)
        x = (both - mean) / RGB_MAX
        return torch.cat((x[:, :, 0], x[:, :, 1]), 1)

    def forward(self, img0, img1, trace=None):
        x = self.normalize(img0, img1)
        up = lambda f: F.interpolate(f, scale_factor=4, mode="bilinear", align_corners=False)  # noqa: E731
        near = lambda f: F.interpolate(f, scale_factor=4, mode="nearest")  # noqa: E731

        def refine_input(flow):
            warped = resample2d(x[:, 3:], flow)
            return torch.cat((x, warped, flow / DIV_FLOW, channel_norm(x[:, :3] - warped)), 1)

        c_flow2 = self.flownetc(x)
        cat1 = refine_input(up(c_flow2 * DIV_FLOW))
        s1_flow2 = self.flownets_1(cat1)
        cat2 = refine_input(up(s1_flow2 * DIV_FLOW))
        s2_flow2 = self.flownets_2(cat2)
        s2_flow = near(s2_flow2 * DIV_FLOW)
        sd_flow2 = self.flownets_d(x)
        sd_flow = near(sd_flow2 / DIV_FLOW)
        cat3 = torch.cat((x[:, :3], sd_flow, s2_flow, channel_norm(sd_flow), channel_norm(s2_flow),
                          channel_norm(x[:, :3] - resample2d(x[:, 3:], sd_flow)),
                          channel_norm(x[:, :3] - resample2d(x[:, 3:], s2_flow))), 1)
        out = self.flownetfusion(cat3)
        if trace is not None:
            trace.update(x=x, flownetc=c_flow2, cat1=cat1, flownets_1=s1_flow2, cat2=cat2, flownets_2=s2_flow2,
                         flownets_d=sd_flow2, cat3=cat3, flownetfusion=out)
        return out
