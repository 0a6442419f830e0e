"""YOLOv3-tiny-style landmark detector (torch; training only, never imported at run time).

Backbone as YOLOv3-tiny (3x3 conv + max-pool ladder, stride 32) at a reduced width.  Heads:

- 13x13 (stride 32) and 26x26 (stride 16) as in YOLOv3-tiny: the 26x26 head fuses the
  up-sampled 13x13 neck with the stride-16 backbone layer;
- with ``three_scales=True`` the paper's change (sec. 2.4): two extra 26x26 convolution layers
  on the fused 26x26 features, up-sampled and fused with the stride-8 backbone layer to feed an
  added 52x52 (stride 8) head.

Each head outputs raw logits, shape (B, A*(5+C), H, W), channel order per anchor:
tx, ty, tw, th, objectness, class logits.  Decoding lives in ``tracker/detector_decode.py``.
"""

from __future__ import annotations

import torch
from torch import nn


def conv(c_in: int, c_out: int, k: int = 3) -> nn.Sequential:
    """Conv + BatchNorm + LeakyReLU(0.1), 'same' padding."""
    return nn.Sequential(nn.Conv2d(c_in, c_out, k, 1, k // 2, bias=False),
                         nn.BatchNorm2d(c_out), nn.LeakyReLU(0.1, inplace=True))


class TinyYolo(nn.Module):
    """Two-scale (YOLOv3-tiny) or three-scale (paper: + 52x52 head) detector."""

    def __init__(self, num_classes: int, anchors_per_scale: int = 3,
                 three_scales: bool = True) -> None:
        super().__init__()
        self.three_scales = three_scales
        out = anchors_per_scale * (5 + num_classes)
        pool = nn.MaxPool2d(2, 2)
        self.stem = nn.Sequential(conv(3, 8), pool, conv(8, 16), pool, conv(16, 32), pool,
                                  conv(32, 64))  # stride 8 (52x52 at 416)
        self.down16 = nn.Sequential(pool, conv(64, 128))  # stride 16 (26x26)
        self.down32 = nn.Sequential(pool, conv(128, 192), conv(192, 192))  # stride 32
        self.neck32 = conv(192, 96, 1)
        self.head32 = nn.Sequential(conv(96, 192), nn.Conv2d(192, out, 1))
        self.lat16 = conv(96, 48, 1)
        self.fuse16 = conv(48 + 128, 96)
        self.head16 = nn.Conv2d(96, out, 1)
        if three_scales:
            # the paper's two added 26x26 convolution layers, then fusion at 52x52
            self.extra26 = nn.Sequential(conv(96, 48, 1), conv(48, 48))
            self.fuse8 = conv(48 + 64, 48)
            self.head8 = nn.Conv2d(48, out, 1)
        self.up = nn.Upsample(scale_factor=2, mode="nearest")

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Raw head outputs, finest scale first."""
        f8 = self.stem(x)
        f16 = self.down16(f8)
        n32 = self.neck32(self.down32(f16))
        p32 = self.head32(n32)
        g16 = self.fuse16(torch.cat([self.up(self.lat16(n32)), f16], 1))
        p16 = self.head16(g16)
        if not self.three_scales:
            return [p16, p32]
        g8 = self.fuse8(torch.cat([self.up(self.extra26(g16)), f8], 1))
        return [self.head8(g8), p16, p32]
