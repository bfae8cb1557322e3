"""PyTorch definition of the Mannequin Challenge hourglass (HourglassModel(3), google/mannequinchallenge
models/hourglass.py) with a width multiplier, written from the facts in docs/models.md section 4.
Parameter / buffer names equal the released state dict at every width.

Width multiplier (shared with models/mannequin.cpp): 16 * width must be a whole number; every
channel count c becomes round(c * width).
"""
import torch
import torch.nn as nn

A1 = [[64], [3, 32, 64], [5, 32, 64], [7, 32, 64]]
A2 = [[64], [3, 64, 64], [7, 64, 64], [11, 64, 64]]
B1 = [[32], [3, 32, 32], [5, 32, 32], [7, 32, 32]]
BC = [[32], [3, 64, 32], [7, 64, 32], [11, 64, 32]]
BB3 = [[32], [3, 64, 32], [5, 64, 32], [7, 64, 32]]
BA = [[16], [3, 32, 16], [7, 32, 16], [11, 32, 16]]
A = [[16], [3, 64, 16], [7, 64, 16], [11, 64, 16]]


class Scale:
    def __init__(self, width):
        if not (width > 0 and abs(width * 16 - round(width * 16)) < 1e-9):
            raise ValueError(f"width {width}: 16 * width must be a whole number")
        self.w = width

    def __call__(self, c):
        return int(round(c * self.w))

    def config(self, cfg):
        return [[self(cfg[0][0])]] + [[k, self(a), self(b)] for k, a, b in cfg[1:]]


class Inception(nn.Module):
    def __init__(self, input_size, config):
        super().__init__()
        self.convs = nn.ModuleList()
        self.convs.append(nn.Sequential(
            nn.Conv2d(input_size, config[0][0], 1), nn.BatchNorm2d(config[0][0], affine=False), nn.ReLU(True)))
        for filt, out_a, out_b in config[1:]:
            pad = (filt - 1) // 2
            self.convs.append(nn.Sequential(
                nn.Conv2d(input_size, out_a, 1), nn.BatchNorm2d(out_a, affine=False), nn.ReLU(True),
                nn.Conv2d(out_a, out_b, filt, padding=pad), nn.BatchNorm2d(out_b, affine=False), nn.ReLU(True)))

    def forward(self, x):
        return torch.cat([conv(x) for conv in self.convs], dim=1)


class TwoBranch(nn.Module):
    def __init__(self, first, second):
        super().__init__()
        self.list = nn.ModuleList([first, second])

    def forward(self, x):
        return self.list[0](x) + self.list[1](x)


class HourglassModel(nn.Module):
    def __init__(self, width=1.0, num_input=3):
        super().__init__()
        s = Scale(width)

        def inc(cin, cfg):
            return Inception(s(cin), s.config(cfg))

        def up():
            return nn.UpsamplingBilinear2d(scale_factor=2)

        channels1 = TwoBranch(
            nn.Sequential(inc(256, A1), inc(256, A1)),
            nn.Sequential(nn.AvgPool2d(2), inc(256, A1), inc(256, A1), inc(256, A1), up()))
        channels2 = TwoBranch(
            nn.Sequential(inc(256, A1), inc(256, A2)),
            nn.Sequential(nn.AvgPool2d(2), inc(256, A1), inc(256, A1), channels1, inc(256, A1), inc(256, A2), up()))
        channels3 = TwoBranch(
            nn.Sequential(nn.AvgPool2d(2), inc(128, B1), inc(128, A1), channels2, inc(256, A1), inc(256, B1), up()),
            nn.Sequential(inc(128, B1), inc(128, BC)))
        channels4 = TwoBranch(
            nn.Sequential(nn.AvgPool2d(2), inc(128, B1), inc(128, B1), channels3, inc(128, BB3), inc(128, BA), up()),
            nn.Sequential(inc(128, A)))
        self.seq = nn.Sequential(nn.Conv2d(num_input, s(128), 7, padding=3), nn.BatchNorm2d(s(128)), nn.ReLU(True),
                                 channels4)
        self.uncertainty_layer = nn.Sequential(nn.Conv2d(s(64), 1, 3, padding=1), nn.Sigmoid())
        self.pred_layer = nn.Conv2d(s(64), 1, 3, padding=1)

    def forward(self, x):
        feature = self.seq(x)
        return self.pred_layer(feature), self.uncertainty_layer(feature)
