"""Encoder and decoder of the 2D-token motion VQ-VAE (InterMask section 3.1, appendix C.1).

A person's motion is an image ``(B, C, J, T)``: joints are the height, frames the width, the
per-joint features the channels. Two strided convolutions reduce joints to 5 body-part rows and
time by 4, giving a ``(B, D, 5, T/4)`` latent grid. With ``token_layout="1d"`` (the Table 2
ablation) joints are folded into channels and only time is convolved, giving ``(B, D, 1, T/4)``.
"""

from __future__ import annotations

from typing import Literal

import torch
from einops import rearrange
from torch import nn

from intermask.motion.skeleton import KINEMATIC_CHAINS, NUM_JOINTS

TokenLayout = Literal["2d", "1d"]


def _conv(
    layout: TokenLayout,
    in_channels: int,
    out_channels: int,
    kernel: tuple[int, int],
    stride: tuple[int, int] = (1, 1),
    padding: tuple[int, int] = (1, 1),
    dilation: tuple[int, int] = (1, 1),
) -> nn.Module:
    """A Conv2d over (joints, time), or its Conv1d restriction to time for the 1D layout."""
    if layout == "2d":
        return nn.Conv2d(in_channels, out_channels, kernel, stride, padding, dilation)
    return nn.Conv1d(in_channels, out_channels, kernel[1], stride[1], padding[1], dilation[1])


class ResidualBlock(nn.Module):
    """Pre-activation residual unit: x + Dropout(Conv1x1(ReLU(Conv3x3_dilated(ReLU(x)))))."""

    def __init__(self, *, width: int, dilation: int, dropout: float, layout: TokenLayout) -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.ReLU(),
            _conv(
                layout,
                width,
                width,
                (3, 3),
                padding=(dilation, dilation),
                dilation=(dilation, dilation),
            ),
            nn.ReLU(),
            _conv(layout, width, width, (1, 1), padding=(0, 0)),
            nn.Dropout(dropout),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)


def residual_stack(
    *, width: int, dilations: tuple[int, ...], dropout: float, layout: TokenLayout
) -> nn.Sequential:
    return nn.Sequential(
        *(ResidualBlock(width=width, dilation=d, dropout=dropout, layout=layout) for d in dilations)
    )


def channels_last(x: torch.Tensor) -> torch.Tensor:
    """(B, C, H, W) in NHWC memory order. The CPU convolution kernels (oneDNN) take a much faster
    path for it with few channels: 4x (fp32) to 7x (bf16) per VQ training step at width 64
    (measured on 2 EPYC cores); CUDA is not slower either way."""
    return x.contiguous(memory_format=torch.channels_last)


def _to_grid(x: torch.Tensor, layout: TokenLayout) -> torch.Tensor:
    """(B, T, J, C) features -> the convolution input, (B, C, J, T) or (B, J*C, T)."""
    if layout == "2d":
        return channels_last(rearrange(x, "b t j c -> b c j t"))
    return rearrange(x, "b t j c -> b (j c) t")


GraphEnds = Literal["conv", "graph", "graph_first_frame", "graph_batch_first_frame"]
GraphFrames = Literal["all", "first", "batch_first"]  # which frames aggregate their neighbours
_GRAPH_FRAMES: dict[str, GraphFrames] = {
    "graph": "all",
    "graph_first_frame": "first",
    "graph_batch_first_frame": "batch_first",
}


class SkeletonGraphLayer(nn.Module):
    """A GraphSAGE layer over the 22-joint skeleton, on (B, C, J, T) grids: each joint's output is
    ``lin_l(mean over its neighbours of relu(lin(x_n))) + lin_r(x)`` (the reference's
    ``SAGEConv(project=True)``, mean aggregation, edges both ways along the kinematic chains).

    ``frames`` says which nodes aggregate their neighbours; the others get
    ``lin_l.bias + lin_r(x)``. ``all``: every frame (what the reference meant). The reference
    passes one skeleton's edge index for a call's B x T x J nodes, so only frame 0 of the call's
    first sequence aggregates: ``batch_first`` is that, for a batch; ``first`` is frame 0 of every
    sequence, what the reference computes for each sequence encoded or decoded alone, as its
    evaluation does (batch 1), and does not depend on the batch (docs/fidelity.md, row 10b).
    """

    def __init__(self, in_channels: int, out_channels: int, *, frames: GraphFrames) -> None:
        super().__init__()
        if frames not in ("all", "first", "batch_first"):
            raise ValueError(f"frames must be 'all', 'first' or 'batch_first', got {frames!r}")
        self.frames = frames
        self.lin = nn.Linear(in_channels, in_channels)
        self.lin_l = nn.Linear(in_channels, out_channels)
        self.lin_r = nn.Linear(in_channels, out_channels, bias=False)
        adjacency = torch.zeros(NUM_JOINTS, NUM_JOINTS)
        for chain in KINEMATIC_CHAINS:
            for parent, child in zip(chain, chain[1:], strict=False):
                adjacency[parent, child] = adjacency[child, parent] = 1.0
        self.register_buffer("mean", adjacency / adjacency.sum(1, keepdim=True), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        nodes = rearrange(x, "b c j t -> b t j c")
        neighbours = torch.relu(self.lin(nodes))
        if self.frames == "batch_first":
            mean = torch.zeros_like(neighbours)
            mean[0, 0] = self.mean @ neighbours[0, 0]
        elif self.frames == "first":
            mean = torch.zeros_like(neighbours)
            mean[:, 0] = torch.einsum("ij,bjc->bic", self.mean, neighbours[:, 0])
        else:
            mean = torch.einsum("ij,btjc->btic", self.mean, neighbours)
        out = self.lin_l(mean) + self.lin_r(nodes)
        return channels_last(rearrange(out, "b t j c -> b c j t"))


def _end(
    ends: GraphEnds, layout: TokenLayout, in_channels: int, out_channels: int, width: int
) -> nn.Module:
    """The encoder's first layer or the decoder's last: a 3x3 convolution (the paper) or two
    skeleton graph layers through ``width`` channels with a ReLU between them (the reference's
    InterHuman release, docs/fidelity.md)."""
    if ends == "conv":
        return _conv(layout, in_channels, out_channels, (3, 3))
    if ends not in _GRAPH_FRAMES:
        raise ValueError(f"ends must be 'conv' or one of {sorted(_GRAPH_FRAMES)}, got {ends!r}")
    if layout != "2d":
        raise ValueError(f"graph ends need the 2d token layout, got {layout!r}")
    frames = _GRAPH_FRAMES[ends]
    return nn.Sequential(
        SkeletonGraphLayer(in_channels, width, frames=frames),
        nn.ReLU(),
        SkeletonGraphLayer(width, out_channels, frames=frames),
    )


class MotionEncoder(nn.Module):
    """(B, T, J, C) per-joint features -> (B, D, rows, T/4) latent grid (rows = 5, or 1 for "1d")."""

    def __init__(
        self,
        *,
        num_joints: int,
        in_channels: int,
        width: int = 512,
        joint_kernel: int = 4,
        joint_stride: int = 2,
        dilations: tuple[int, ...] = (3, 1),
        dropout: float = 0.2,
        layout: TokenLayout = "2d",
        ends: GraphEnds = "conv",
    ) -> None:
        super().__init__()
        self.layout, self.num_joints, self.in_channels = layout, num_joints, in_channels
        stem_in = in_channels if layout == "2d" else num_joints * in_channels
        downsample = [
            layer
            for _ in range(2)
            for layer in (
                _conv(layout, width, width, (joint_kernel, 4), stride=(joint_stride, 2)),
                residual_stack(
                    width=width, dilations=tuple(dilations), dropout=dropout, layout=layout
                ),
            )
        ]
        self.net = nn.Sequential(
            _end(ends, layout, stem_in, width, width),
            nn.ReLU(),
            *downsample,
            _conv(layout, width, width, (3, 3)),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        latent = self.net(_to_grid(x, self.layout))
        return latent if self.layout == "2d" else latent[:, :, None, :]


class MotionDecoder(nn.Module):
    """(B, D, rows, T') latent grid -> (B, 4 T', J, C) per-joint features.

    Each stage upsamples by nearest neighbour with (joint_scale[i], 2) and convolves; the joint
    scales (InterHuman 2.2, 2 -> 5, 11, 22; Inter-X 3.5, 3.3 -> 5, 17, 56) come from the
    reference implementation and are checked against ``num_joints`` at construction.
    ``reverse_dilations`` runs each residual stack's dilations in the reverse of the encoder's
    order (this framework's first reading, kept as the default of the class so that runs saved
    before the switch decode as they trained); the configs set False: the reference decoder
    uses the encoder's order, (3, 1), and the paper is silent (docs/fidelity.md).
    """

    def __init__(
        self,
        *,
        num_joints: int,
        out_channels: int,
        width: int = 512,
        joint_scales: tuple[float, float] = (2.2, 2.0),
        latent_rows: int = 5,
        dilations: tuple[int, ...] = (3, 1),
        reverse_dilations: bool = True,
        dropout: float = 0.2,
        layout: TokenLayout = "2d",
        ends: GraphEnds = "conv",
    ) -> None:
        super().__init__()
        self.layout, self.num_joints, self.out_channels = layout, num_joints, out_channels
        self.latent_rows = latent_rows if layout == "2d" else 1  # token rows it decodes
        if layout == "2d":
            rows = latent_rows
            for scale in joint_scales:
                rows = int(rows * scale)
            if rows != num_joints:
                raise ValueError(
                    f"joint_scales {tuple(joint_scales)} take {latent_rows} latent rows to {rows} joints, "
                    f"expected {num_joints}"
                )
        stages = []
        for scale in joint_scales:
            time_only = layout == "1d"
            stages += [
                residual_stack(
                    width=width,
                    dilations=tuple(reversed(dilations)) if reverse_dilations else tuple(dilations),
                    dropout=dropout,
                    layout=layout,
                ),
                nn.Upsample(scale_factor=2.0 if time_only else (float(scale), 2.0), mode="nearest"),
                _conv(layout, width, width, (3, 3)),
            ]
        head_out = out_channels if layout == "2d" else num_joints * out_channels
        self.net = nn.Sequential(
            _conv(layout, width, width, (3, 3)),
            nn.ReLU(),
            *stages,
            _conv(layout, width, width, (3, 3)),
            nn.ReLU(),
            _end(ends, layout, width, head_out, width),
        )

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        if self.layout == "2d":
            return rearrange(self.net(channels_last(latent)), "b c j t -> b t j c")
        out = self.net(latent[:, :, 0, :])
        return rearrange(out, "b (j c) t -> b t j c", j=self.num_joints)
