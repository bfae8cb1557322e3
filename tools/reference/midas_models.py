"""PyTorch definitions of MiDaS v2 (MidasNet, ResNeXt-101 32x8d encoder) and MiDaS v2.1 small
(MidasNet_small, EfficientNet-Lite3 encoder) with a width multiplier, written from the facts in
docs/models.md sections 2-3 (read from isl-org/MiDaS 5d208c5 / 9983656 and rwightman/gen-efficientnet-pytorch).
Parameter / buffer names equal the released state dicts at every width.

Width multiplier (shared with models/midas_v2.cpp and models/midas_small.cpp): `width` must be a
power of two in (0, 1]; every channel count c becomes ceil(c * width) (at least 1). ResNeXt
cardinality is min(32, ceil(256 * width)) so that it divides every bottleneck width.
EfficientNet expanded widths are 6 * (scaled input width); residual connections are those of
the full-size network (every block of a stage but the first).
"""
import math

import torch
import torch.nn as nn
import torch.nn.functional as F


def check_width(width):
    k = round(-math.log2(width))
    if not (0 < width <= 1 and abs(2.0 ** -k - width) < 1e-12):
        raise ValueError(f"width {width} must be a power of two in (0, 1]")


def scaled(c, width):
    return max(1, math.ceil(c * width - 1e-9))


# ---- MiDaS v2 --------------------------------------------------------------------------------

class Bottleneck(nn.Module):
    """torchvision ResNeXt Bottleneck (v1.5: stride in the 3x3 conv)."""

    def __init__(self, inplanes, width, out, stride, groups, downsample):
        super().__init__()
        self.conv1 = nn.Conv2d(inplanes, width, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(width)
        self.conv2 = nn.Conv2d(width, width, 3, stride=stride, padding=1, groups=groups, bias=False)
        self.bn2 = nn.BatchNorm2d(width)
        self.conv3 = nn.Conv2d(width, out, 1, bias=False)
        self.bn3 = nn.BatchNorm2d(out)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = downsample

    def forward(self, x):
        identity = x
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.relu(self.bn2(self.conv2(out)))
        out = self.bn3(self.conv3(out))
        if self.downsample is not None:
            identity = self.downsample(x)
        out += identity
        return self.relu(out)


def resnext_layer(inplanes, planes, blocks, stride, width, groups):
    w = scaled(planes * 4, width)  # planes * (8 / 64) * 32
    out = scaled(planes * 4, width)
    downsample = None
    if stride != 1 or inplanes != out:
        downsample = nn.Sequential(nn.Conv2d(inplanes, out, 1, stride=stride, bias=False), nn.BatchNorm2d(out))
    layers = [Bottleneck(inplanes, w, out, stride, groups, downsample)]
    for _ in range(1, blocks):
        layers.append(Bottleneck(out, w, out, 1, groups, None))
    return nn.Sequential(*layers), out


class ResidualConvUnit(nn.Module):
    """MiDaS v2 RCU: its ReLU is in place, so the skip adds relu(x), not x."""

    def __init__(self, features):
        super().__init__()
        self.conv1 = nn.Conv2d(features, features, 3, padding=1, bias=True)
        self.conv2 = nn.Conv2d(features, features, 3, padding=1, bias=True)
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x):
        out = self.relu(x)
        out = self.conv1(out)
        out = self.relu(out)
        out = self.conv2(out)
        return out + x


class FeatureFusionBlock(nn.Module):
    def __init__(self, features):
        super().__init__()
        self.resConfUnit1 = ResidualConvUnit(features)
        self.resConfUnit2 = ResidualConvUnit(features)

    def forward(self, *xs):
        output = xs[0]
        if len(xs) == 2:
            output += self.resConfUnit1(xs[1])
        output = self.resConfUnit2(output)
        return F.interpolate(output, scale_factor=2, mode="bilinear", align_corners=True)


class Interpolate(nn.Module):
    def __init__(self, scale_factor, mode):
        super().__init__()
        self.scale_factor, self.mode = scale_factor, mode

    def forward(self, x):
        return F.interpolate(x, scale_factor=self.scale_factor, mode=self.mode, align_corners=False)


class MidasV2(nn.Module):
    def __init__(self, width=1.0, non_negative=True):
        super().__init__()
        check_width(width)
        groups = min(32, scaled(256, width))
        stem = scaled(64, width)
        features = scaled(256, width)
        self.pretrained = nn.Module()
        layer1, c1 = resnext_layer(stem, 64, 3, 1, width, groups)
        self.pretrained.layer1 = nn.Sequential(
            nn.Conv2d(3, stem, 7, stride=2, padding=3, bias=False), nn.BatchNorm2d(stem), nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2, 1), layer1)
        self.pretrained.layer2, c2 = resnext_layer(c1, 128, 4, 2, width, groups)
        self.pretrained.layer3, c3 = resnext_layer(c2, 256, 23, 2, width, groups)
        self.pretrained.layer4, c4 = resnext_layer(c3, 512, 3, 2, width, groups)
        self.scratch = nn.Module()
        for i, c in enumerate([c1, c2, c3, c4], 1):
            setattr(self.scratch, f"layer{i}_rn", nn.Conv2d(c, features, 3, padding=1, bias=False))
        self.scratch.refinenet4 = FeatureFusionBlock(features)
        self.scratch.refinenet3 = FeatureFusionBlock(features)
        self.scratch.refinenet2 = FeatureFusionBlock(features)
        self.scratch.refinenet1 = FeatureFusionBlock(features)
        h128, h32 = scaled(128, width), scaled(32, width)
        self.scratch.output_conv = nn.Sequential(
            nn.Conv2d(features, h128, 3, padding=1), Interpolate(2, "bilinear"),
            nn.Conv2d(h128, h32, 3, padding=1), nn.ReLU(True), nn.Conv2d(h32, 1, 1),
            nn.ReLU(True) if non_negative else nn.Identity())

    def forward(self, x):
        l1 = self.pretrained.layer1(x)
        l2 = self.pretrained.layer2(l1)
        l3 = self.pretrained.layer3(l2)
        l4 = self.pretrained.layer4(l3)
        s = self.scratch
        p4 = s.refinenet4(s.layer4_rn(l4))
        p3 = s.refinenet3(p4, s.layer3_rn(l3))
        p2 = s.refinenet2(p3, s.layer2_rn(l2))
        p1 = s.refinenet1(p2, s.layer1_rn(l1))
        return torch.squeeze(s.output_conv(p1), dim=1)


# ---- MiDaS v2.1 small ------------------------------------------------------------------------

def same_pad(k, s):
    """TF 'SAME' padding (left, right, top, bottom) for an input whose size divides by s."""
    total = max(k - s, 0)
    return (total // 2, total - total // 2, total // 2, total - total // 2)


class SameConv(nn.Conv2d):
    """Conv2d with TF 'SAME' padding; parameter names as nn.Conv2d."""

    def __init__(self, cin, cout, k, stride=1, groups=1):
        super().__init__(cin, cout, k, stride=stride, padding=0, groups=groups, bias=False)
        self.pads = same_pad(k, stride)

    def forward(self, x):
        return super().forward(F.pad(x, self.pads))


def bn_tf(c):
    return nn.BatchNorm2d(c, eps=1e-3)


class DepthwiseSeparable(nn.Module):
    def __init__(self, cin, cout, k, residual):
        super().__init__()
        self.conv_dw = SameConv(cin, cin, k, 1, groups=cin)
        self.bn1 = bn_tf(cin)
        self.act1 = nn.ReLU6(inplace=True)
        self.conv_pw = SameConv(cin, cout, 1)
        self.bn2 = bn_tf(cout)
        self.residual = residual

    def forward(self, x):
        y = self.bn2(self.conv_pw(self.act1(self.bn1(self.conv_dw(x)))))
        return y + x if self.residual else y


class InvertedResidual(nn.Module):
    def __init__(self, cin, cout, k, stride, residual):
        super().__init__()
        mid = 6 * cin
        self.conv_pw = SameConv(cin, mid, 1)
        self.bn1 = bn_tf(mid)
        self.act1 = nn.ReLU6(inplace=True)
        self.conv_dw = SameConv(mid, mid, k, stride, groups=mid)
        self.bn2 = bn_tf(mid)
        self.act2 = nn.ReLU6(inplace=True)
        self.conv_pwl = SameConv(mid, cout, 1)
        self.bn3 = bn_tf(cout)
        self.residual = residual

    def forward(self, x):
        y = self.act1(self.bn1(self.conv_pw(x)))
        y = self.act2(self.bn2(self.conv_dw(y)))
        y = self.bn3(self.conv_pwl(y))
        return y + x if self.residual else y


# tf_efficientnet_lite3 stages after channel x1.2 (divisor 8) and depth x1.4 (ceil; first and
# last stage fixed): (repeats, kernel, stride, out channels).
LITE3_STAGES = [(3, 3, 2, 32), (3, 5, 2, 48), (5, 3, 2, 96), (5, 5, 1, 136), (6, 5, 2, 232), (1, 3, 1, 384)]


def efficientnet_stage(cin, stage, width):
    reps, k, s, cout = stage
    cout = scaled(cout, width)
    blocks = []
    for i in range(reps):
        blocks.append(InvertedResidual(cin if i == 0 else cout, cout, k, s if i == 0 else 1, residual=i > 0))
    return nn.Sequential(*blocks), cout


class ResidualConvUnitCustom(nn.Module):
    """MiDaS v2.1 custom RCU (bn=False): x + conv2(relu(conv1(relu(x)))), ReLU not in place."""

    def __init__(self, features):
        super().__init__()
        self.conv1 = nn.Conv2d(features, features, 3, padding=1, bias=True)
        self.conv2 = nn.Conv2d(features, features, 3, padding=1, bias=True)
        self.activation = nn.ReLU(False)

    def forward(self, x):
        out = self.conv2(self.activation(self.conv1(self.activation(x))))
        return out + x


class FeatureFusionBlockCustom(nn.Module):
    def __init__(self, features, expand):
        super().__init__()
        out = features // 2 if expand else features
        self.out_conv = nn.Conv2d(features, out, 1, bias=True)
        self.resConfUnit1 = ResidualConvUnitCustom(features)
        self.resConfUnit2 = ResidualConvUnitCustom(features)

    def forward(self, *xs):
        output = xs[0]
        if len(xs) == 2:
            output = output + self.resConfUnit1(xs[1])
        output = self.resConfUnit2(output)
        output = F.interpolate(output, scale_factor=2, mode="bilinear", align_corners=True)
        return self.out_conv(output)


class MidasSmall(nn.Module):
    def __init__(self, width=1.0, non_negative=True):
        super().__init__()
        check_width(width)
        stem = scaled(32, width)
        c0 = scaled(24, width)
        self.pretrained = nn.Module()
        s1, c1 = efficientnet_stage(c0, LITE3_STAGES[0], width)
        self.pretrained.layer1 = nn.Sequential(
            SameConv(3, stem, 3, 2), bn_tf(stem), nn.ReLU6(inplace=True),
            nn.Sequential(DepthwiseSeparable(stem, c0, 3, residual=False)), s1)
        s2, c2 = efficientnet_stage(c1, LITE3_STAGES[1], width)
        self.pretrained.layer2 = nn.Sequential(s2)
        s3, c3a = efficientnet_stage(c2, LITE3_STAGES[2], width)
        s4, c3 = efficientnet_stage(c3a, LITE3_STAGES[3], width)
        self.pretrained.layer3 = nn.Sequential(s3, s4)
        s5, c4a = efficientnet_stage(c3, LITE3_STAGES[4], width)
        s6, c4 = efficientnet_stage(c4a, LITE3_STAGES[5], width)
        self.pretrained.layer4 = nn.Sequential(s5, s6)
        f = scaled(64, width)
        self.scratch = nn.Module()
        for i, (cin, cout) in enumerate([(c1, f), (c2, 2 * f), (c3, 4 * f), (c4, 8 * f)], 1):
            setattr(self.scratch, f"layer{i}_rn", nn.Conv2d(cin, cout, 3, padding=1, bias=False))
        self.scratch.refinenet4 = FeatureFusionBlockCustom(8 * f, True)
        self.scratch.refinenet3 = FeatureFusionBlockCustom(4 * f, True)
        self.scratch.refinenet2 = FeatureFusionBlockCustom(2 * f, True)
        self.scratch.refinenet1 = FeatureFusionBlockCustom(f, False)
        h = scaled(32, width)
        self.scratch.output_conv = nn.Sequential(
            nn.Conv2d(f, h, 3, padding=1), Interpolate(2, "bilinear"), nn.Conv2d(h, h, 3, padding=1),
            nn.ReLU(False), nn.Conv2d(h, 1, 1), nn.ReLU(True) if non_negative else nn.Identity(), nn.Identity())

    def forward(self, x):
        l1 = self.pretrained.layer1(x)
        l2 = self.pretrained.layer2(l1)
        l3 = self.pretrained.layer3(l2)
        l4 = self.pretrained.layer4(l3)
        s = self.scratch
        p4 = s.refinenet4(s.layer4_rn(l4))
        p3 = s.refinenet3(p4, s.layer3_rn(l3))
        p2 = s.refinenet2(p3, s.layer2_rn(l2))
        p1 = s.refinenet1(p2, s.layer1_rn(l1))
        return torch.squeeze(s.output_conv(p1), dim=1)


IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def imagenet_normalize(rgb01):
    mean = torch.tensor(IMAGENET_MEAN, dtype=rgb01.dtype).view(1, 3, 1, 1)
    std = torch.tensor(IMAGENET_STD, dtype=rgb01.dtype).view(1, 3, 1, 1)
    return (rgb01 - mean) / std


def used_parameter_count(model):
    return sum(p.numel() for n, p in model.named_parameters() if "refinenet4.resConfUnit1" not in n)
