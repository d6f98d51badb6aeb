"""A FastestDet-style single-class person detector (our own PyTorch implementation).

Shape of the network (FastestDet's, reference notes section 13, with fewer backbone repeats):
- Backbone: ShuffleNetV2-like. Stem 3x3 conv stride 2 + 3x3 max-pool (stride 4), then three
  stages of ShuffleNetV2 units (channel split, 1x1 -> depthwise 3x3 -> 1x1 on one half, concat,
  channel shuffle; the first unit of a stage halves the resolution with both branches).
  Strides 8 / 16 / 32 give P1, P2, P3.
- Neck: P1 average-pooled (3x3, stride 2) and P3 upsampled x2 (nearest) are concatenated with P2
  at stride 16, then a light "SPP": a 1x1 conv to NECK_CHANNELS, three branches of 1, 2 and 3
  stacked 5x5 depthwise convs, their concatenation fused by a 1x1 conv, a residual add and ReLU.
- Head: one anchor-free head at stride 16: a 1x1 conv, then two branches (5x5 depthwise + 1x1):
  objectness (1 channel, a logit) and box regression (4 channels: tx, ty, tw, th). One class, so
  no class branch. Output (N, 5, H/16, W/16) in `dodt.learned.layout`'s channel order.
- Stride-8 sizes (ours, not FastestDet's): the neck's output is upsampled x2 (nearest) and added
  to P1 brought to the neck's width by a 1x1 conv (a top-down step as in a feature pyramid), a
  5x5 depthwise conv mixes them, and the same head runs on that stride-8 grid: people walking
  close together, or small and far, each get a cell of their own. Output (N, 5, H/8, W/8).
"""
from __future__ import annotations

import torch
from torch import nn
import torch.nn.functional as F

STAGE_REPEATS = (2, 6, 2)
STAGE_CHANNELS = (24, 48, 96, 192)  # stem, stride 8, stride 16, stride 32 (FastestDet's)
NECK_CHANNELS = 96
# Named sizes of the same network: "base" is the shape above (180,629 parameters); "wide" has
# more channels and one more unit per stage, for training where compute is cheap (a GPU).
# "wide8" is "wide" with its head at stride 8.
ARCHS = {
    "base": {"repeats": STAGE_REPEATS, "channels": STAGE_CHANNELS, "neck": NECK_CHANNELS, "stride": 16},
    "wide": {"repeats": (3, 7, 3), "channels": (32, 64, 128, 256), "neck": 128, "stride": 16},
    "wide8": {"repeats": (3, 7, 3), "channels": (32, 64, 128, 256), "neck": 128, "stride": 8},
}


def conv_bn(c_in: int, c_out: int, k: int = 1, stride: int = 1, groups: int = 1, relu: bool = True) -> nn.Sequential:
    layers = [nn.Conv2d(c_in, c_out, k, stride, k // 2, groups=groups, bias=False), nn.BatchNorm2d(c_out)]
    if relu:
        layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


def channel_shuffle(x: torch.Tensor, groups: int = 2) -> torch.Tensor:
    n, c, h, w = x.shape
    return x.reshape(n, groups, c // groups, h, w).transpose(1, 2).reshape(n, c, h, w)


class ShuffleUnit(nn.Module):
    """A ShuffleNetV2 unit. stride 1: split the channels in half, transform one half, concat and
    shuffle. stride 2: both halves see the whole input, each downsampled by a depthwise conv."""

    def __init__(self, c_in: int, c_out: int, stride: int):
        super().__init__()
        self.stride = stride
        half = c_out // 2
        main_in = c_in if stride == 2 else c_in // 2
        self.main = nn.Sequential(
            conv_bn(main_in, half, 1),
            conv_bn(half, half, 3, stride, groups=half, relu=False),
            conv_bn(half, half, 1),
        )
        if stride == 2:
            self.proj = nn.Sequential(
                conv_bn(c_in, c_in, 3, 2, groups=c_in, relu=False),
                conv_bn(c_in, half, 1),
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.stride == 2:
            out = torch.cat([self.proj(x), self.main(x)], dim=1)
        else:
            keep, rest = x.chunk(2, dim=1)
            out = torch.cat([keep, self.main(rest)], dim=1)
        return channel_shuffle(out, 2)


class Backbone(nn.Module):
    def __init__(self, repeats=STAGE_REPEATS, channels=STAGE_CHANNELS):
        super().__init__()
        self.stem = nn.Sequential(conv_bn(3, channels[0], 3, 2), nn.MaxPool2d(3, 2, 1))
        stages = []
        c_in = channels[0]
        for n, c_out in zip(repeats, channels[1:]):
            units = [ShuffleUnit(c_in, c_out, 2)] + [ShuffleUnit(c_out, c_out, 1) for _ in range(n - 1)]
            stages.append(nn.Sequential(*units))
            c_in = c_out
        self.stages = nn.ModuleList(stages)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.stem(x)
        feats = []
        for stage in self.stages:
            x = stage(x)
            feats.append(x)
        return feats  # strides 8, 16, 32


def dw_stack(c: int, n: int) -> nn.Sequential:
    """n stacked 5x5 depthwise convs (each with BN + ReLU)."""
    return nn.Sequential(*[conv_bn(c, c, 5, groups=c) for _ in range(n)])


class LightSPP(nn.Module):
    def __init__(self, c_in: int, c: int):
        super().__init__()
        self.reduce = conv_bn(c_in, c, 1)
        self.branches = nn.ModuleList([dw_stack(c, n) for n in (1, 2, 3)])
        self.fuse = conv_bn(3 * c, c, 1, relu=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.reduce(x)
        y = self.fuse(torch.cat([b(x) for b in self.branches], dim=1))
        return F.relu(x + y)


class Head(nn.Module):
    def __init__(self, c: int):
        super().__init__()
        self.pre = conv_bn(c, c, 1)
        self.obj = nn.Sequential(conv_bn(c, c, 5, groups=c), nn.Conv2d(c, 1, 1))
        self.reg = nn.Sequential(conv_bn(c, c, 5, groups=c), nn.Conv2d(c, 4, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.pre(x)
        return torch.cat([self.obj(x), self.reg(x)], dim=1)


class TopDown(nn.Module):
    """The stride-16 neck brought to stride 8: upsampled x2 and added to P1 projected to the same
    width, then a 5x5 depthwise conv."""

    def __init__(self, c_p1: int, c: int):
        super().__init__()
        self.lateral = conv_bn(c_p1, c, 1, relu=False)
        self.mix = conv_bn(c, c, 5, groups=c)

    def forward(self, neck: torch.Tensor, p1: torch.Tensor) -> torch.Tensor:
        return self.mix(F.interpolate(neck, scale_factor=2.0, mode="nearest") + self.lateral(p1))


class PersonDetector(nn.Module):
    """(N, 3, H, W) RGB in [0, 1] -> (N, 5, H/s, W/s) raw (objectness logit, tx, ty, tw, th), with
    the head's stride s 16 (FastestDet's) or 8."""

    def __init__(self, repeats=STAGE_REPEATS, channels=STAGE_CHANNELS, neck=NECK_CHANNELS, stride: int = 16):
        super().__init__()
        if stride not in (8, 16):
            raise ValueError(f"stride: expected 8 or 16, got {stride!r}")
        self.stride = stride
        self.backbone = Backbone(repeats, channels)
        self.spp = LightSPP(sum(channels[1:]), neck)
        self.top_down = TopDown(channels[1], neck) if stride == 8 else None
        self.head = Head(neck)
        # Normalisation inside the graph keeps the run-time contract at plain [0, 1] RGB.
        self.register_buffer("mean", torch.tensor([0.45, 0.45, 0.45]).view(1, 3, 1, 1))
        self.register_buffer("inv_std", torch.tensor([1 / 0.25] * 3).view(1, 3, 1, 1))
        self._init_weights()

    def _init_weights(self) -> None:
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
                if m.bias is not None:
                    nn.init.zeros_(m.bias)
        # A low prior for objectness (most cells are background) and small initial boxes.
        obj_out = self.head.obj[-1]
        nn.init.normal_(obj_out.weight, std=0.01)
        nn.init.constant_(obj_out.bias, -4.0)
        reg_out = self.head.reg[-1]
        nn.init.normal_(reg_out.weight, std=0.01)
        nn.init.constant_(reg_out.bias, 0.0)
        with torch.no_grad():
            reg_out.bias[2:] = -2.0  # sigmoid(-2) = 0.12 of the image

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = (x - self.mean) * self.inv_std
        p1, p2, p3 = self.backbone(x)
        pooled = F.avg_pool2d(p1, 3, 2, 1)
        p3 = F.interpolate(p3, scale_factor=2.0, mode="nearest")
        neck = self.spp(torch.cat([pooled, p2, p3], dim=1))
        if self.top_down is not None:
            neck = self.top_down(neck, p1)
        return self.head(neck)


def build_model(arch: str = "base") -> PersonDetector:
    """The network of one of the named sizes in ARCHS."""
    if arch not in ARCHS:
        raise ValueError(f"arch: unknown {arch!r}; expected one of {', '.join(ARCHS)}")
    a = ARCHS[arch]
    return PersonDetector(a["repeats"], a["channels"], a["neck"], a["stride"])


def describe(arch: str = "base") -> str:
    """The architecture in words, for the model's record."""
    a = ARCHS[arch]
    return ("FastestDet-style: ShuffleNetV2-like backbone (repeats %s, channels %s), avg-pooled stride-8 + "
            "upsampled stride-32 + stride-16 concat, light SPP (5x5 depthwise stacks 1/2/3, residual, %d "
            "channels), %sone anchor-free stride-%d head"
            % (list(a["repeats"]), list(a["channels"]), a["neck"],
               "a top-down step to stride 8 (upsampled neck + 1x1 of the stride-8 features, 5x5 depthwise), "
               if a["stride"] == 8 else "", a["stride"]))


def count_parameters(model: nn.Module) -> int:
    """Trainable parameters (weights, biases and BatchNorm affine terms; not running stats)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
