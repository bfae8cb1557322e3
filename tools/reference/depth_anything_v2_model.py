"""An independent PyTorch definition of Depth Anything V2 (DINOv2 ViT encoder + DPT head) with the
released state-dict names, for the fixtures of tests/test_depth_anything.cpp and ONNX exports
(offline only; the library never runs Python). Written from the architecture description in
docs/models.md, not from the upstream code; verify_reference_models.py-style checks against
upstream need its checkout.

Config (the published ones: vits 24.8 M parameters, vitb, vitl) or a reduced one for fixtures:
embed_dim, depth, heads, mlp_ratio, patch, pos_grid (the position embedding's grid side),
features, out_channels (4), layers (the 4 block indices the head reads).
"""
import math

import torch
import torch.nn as nn
import torch.nn.functional as F

VITS = dict(embed_dim=384, depth=12, heads=6, mlp_ratio=4, patch=14, pos_grid=37, features=64,
            out_channels=(48, 96, 192, 384), layers=(2, 5, 8, 11))
VITB = dict(VITS, embed_dim=768, heads=12, features=128, out_channels=(96, 192, 384, 768))
VITL = dict(VITS, embed_dim=1024, depth=24, heads=16, features=256,
            out_channels=(256, 512, 1024, 1024), layers=(4, 11, 17, 23))


class LayerScale(nn.Module):
    def __init__(self, dim, init=1.0):
        super().__init__()
        self.gamma = nn.Parameter(init * torch.ones(dim))

    def forward(self, x):
        return x * self.gamma


class Attention(nn.Module):
    def __init__(self, dim, heads):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x):
        b, n, c = x.shape
        d = c // self.heads
        qkv = self.qkv(x).reshape(b, n, 3, self.heads, d).permute(2, 0, 3, 1, 4)
        q, k, v = qkv[0] / math.sqrt(d), qkv[1], qkv[2]
        a = torch.softmax(q @ k.transpose(-2, -1), dim=-1)
        return self.proj((a @ v).transpose(1, 2).reshape(b, n, c))


class Mlp(nn.Module):
    def __init__(self, dim, hidden):
        super().__init__()
        self.fc1 = nn.Linear(dim, hidden)
        self.act = nn.GELU()
        self.fc2 = nn.Linear(hidden, dim)

    def forward(self, x):
        return self.fc2(self.act(self.fc1(x)))


class Block(nn.Module):
    def __init__(self, dim, heads, mlp_ratio):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = Attention(dim, heads)
        self.ls1 = LayerScale(dim)
        self.norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.mlp = Mlp(dim, dim * mlp_ratio)
        self.ls2 = LayerScale(dim)

    def forward(self, x):
        x = x + self.ls1(self.attn(self.norm1(x)))
        return x + self.ls2(self.mlp(self.norm2(x)))


class PatchEmbed(nn.Module):
    def __init__(self, patch, dim):
        super().__init__()
        self.proj = nn.Conv2d(3, dim, patch, stride=patch)

    def forward(self, x):
        return self.proj(x).flatten(2).transpose(1, 2)


class Encoder(nn.Module):
    def __init__(self, c):
        super().__init__()
        self.c = c
        dim, m = c["embed_dim"], c["pos_grid"]
        self.cls_token = nn.Parameter(torch.randn(1, 1, dim) * 1e-6)
        self.pos_embed = nn.Parameter(torch.randn(1, 1 + m * m, dim) * 0.02)
        self.mask_token = nn.Parameter(torch.zeros(1, dim))
        self.patch_embed = PatchEmbed(c["patch"], dim)
        self.blocks = nn.ModuleList(Block(dim, c["heads"], c["mlp_ratio"]) for _ in range(c["depth"]))
        self.norm = nn.LayerNorm(dim, eps=1e-6)

    def position_embedding(self, ph, pw, h, w):
        m, dim = self.c["pos_grid"], self.c["embed_dim"]
        if ph * pw == m * m and h == w:
            return self.pos_embed
        grid = self.pos_embed[:, 1:].reshape(1, m, m, dim).permute(0, 3, 1, 2)
        # DINOv2 passes scale factors (n + 0.1) / M, which set the sampling positions.
        grid = F.interpolate(grid, scale_factor=((ph + 0.1) / m, (pw + 0.1) / m), mode="bicubic",
                             align_corners=False)
        assert grid.shape[-2:] == (ph, pw)
        patches = grid.permute(0, 2, 3, 1).reshape(1, ph * pw, dim)
        return torch.cat((self.pos_embed[:, :1], patches), dim=1)

    def intermediate_layers(self, x, layers):
        n, _, h, w = x.shape
        p = self.c["patch"]
        ph, pw = h // p, w // p
        t = torch.cat((self.cls_token.expand(n, -1, -1), self.patch_embed(x)), dim=1)
        t = t + self.position_embedding(ph, pw, h, w)
        out = []
        for i, blk in enumerate(self.blocks):
            t = blk(t)
            if i in layers:
                out.append(self.norm(t)[:, 1:])
        return out


class ResidualConvUnit(nn.Module):
    def __init__(self, f):
        super().__init__()
        self.conv1 = nn.Conv2d(f, f, 3, padding=1)
        self.conv2 = nn.Conv2d(f, f, 3, padding=1)

    def forward(self, x):
        return x + self.conv2(F.relu(self.conv1(F.relu(x))))


class FusionBlock(nn.Module):
    def __init__(self, f):
        super().__init__()
        self.out_conv = nn.Conv2d(f, f, 1)
        self.resConfUnit1 = ResidualConvUnit(f)
        self.resConfUnit2 = ResidualConvUnit(f)

    def forward(self, x, skip=None, size=None):
        if skip is not None:
            x = x + self.resConfUnit1(skip)
        x = self.resConfUnit2(x)
        size = size if size is not None else (x.shape[2] * 2, x.shape[3] * 2)
        return self.out_conv(F.interpolate(x, size=size, mode="bilinear", align_corners=True))


class Scratch(nn.Module):
    def __init__(self, oc, f):
        super().__init__()
        for i in range(4):
            setattr(self, f"layer{i + 1}_rn", nn.Conv2d(oc[i], f, 3, padding=1, bias=False))
        for i in range(4):
            setattr(self, f"refinenet{i + 1}", FusionBlock(f))
        self.output_conv1 = nn.Conv2d(f, f // 2, 3, padding=1)
        self.output_conv2 = nn.Sequential(nn.Conv2d(f // 2, 32, 3, padding=1), nn.ReLU(),
                                          nn.Conv2d(32, 1, 1), nn.ReLU(), nn.Identity())


class DPTHead(nn.Module):
    def __init__(self, c):
        super().__init__()
        dim, oc, f = c["embed_dim"], c["out_channels"], c["features"]
        self.projects = nn.ModuleList(nn.Conv2d(dim, o, 1) for o in oc)
        self.resize_layers = nn.ModuleList([
            nn.ConvTranspose2d(oc[0], oc[0], 4, stride=4),
            nn.ConvTranspose2d(oc[1], oc[1], 2, stride=2),
            nn.Identity(),
            nn.Conv2d(oc[3], oc[3], 3, stride=2, padding=1)])
        self.scratch = Scratch(oc, f)

    def forward(self, tokens, ph, pw, patch):
        s = self.scratch
        rn = []
        for i, t in enumerate(tokens):
            m = t.transpose(1, 2).reshape(t.shape[0], t.shape[2], ph, pw)
            m = self.resize_layers[i](self.projects[i](m))
            rn.append(getattr(s, f"layer{i + 1}_rn")(m))
        p = s.refinenet4(rn[3], size=rn[2].shape[2:])
        p = s.refinenet3(p, rn[2], size=rn[1].shape[2:])
        p = s.refinenet2(p, rn[1], size=rn[0].shape[2:])
        p = s.refinenet1(p, rn[0])
        out = F.interpolate(s.output_conv1(p), (ph * patch, pw * patch), mode="bilinear",
                            align_corners=True)
        return s.output_conv2(out)


class DepthAnythingV2(nn.Module):
    """forward(x): x normalised RGB [N, 3, H, W], H and W multiples of the patch; returns the raw
    relative inverse depth [N, 1, H, W] (>= 0)."""

    def __init__(self, c=VITS):
        super().__init__()
        self.c = dict(c)
        self.pretrained = Encoder(self.c)
        self.depth_head = DPTHead(self.c)

    def forward(self, x):
        p = self.c["patch"]
        ph, pw = x.shape[-2] // p, x.shape[-1] // p
        tokens = self.pretrained.intermediate_layers(x, list(self.c["layers"]))
        return F.relu(self.depth_head(tokens, ph, pw, p))
