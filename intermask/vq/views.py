"""How each dataset's features enter and leave the VQ-VAE, and where their geometry lives.

A *view* turns a person's dataset features into the per-joint image the convolutions see,
``(B, T, J, C)``, turns the decoder output back, and exposes the de-normalized geometry
(positions, 6D rotations, foot contacts) the geometric losses and MPJPE need. The
normalization statistics are buffers, so checkpoints carry them.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from einops import rearrange
from torch import nn

from intermask.motion import humanml3d as hml
from intermask.motion import interhuman as ih
from intermask.motion import interx as ix
from intermask.motion.skeleton import NUM_JOINTS

_HORIZONTAL = [0, 2]  # x and z of a position (Y up); the height stays in the shared frame


def _with_horizontal(joints: torch.Tensor, horizontal: torch.Tensor) -> torch.Tensor:
    """``joints (..., 22, 12)`` with the x and z position channels of joints 1..21 replaced by
    ``horizontal (..., 21, 2)`` (a new tensor: autograd sees both inputs)."""
    body = joints[..., 1:, :]
    x, y, z = horizontal[..., :1], body[..., 1:2], horizontal[..., 1:]
    body = torch.cat((x, y, z, body[..., 3:]), dim=-1)
    return torch.cat((joints[..., :1, :], body), dim=-2)


class Geometry(NamedTuple):
    positions: (
        torch.Tensor | None
    )  # (B, T, 22, 3) metres, None when the representation has no positions
    rot6d: torch.Tensor  # (B, T, R, 6) local rotations in the "rows" 6D layout
    contacts: torch.Tensor | None  # (B, T, 4) in {0, 1} (l_ankle, l_foot, r_ankle, r_foot) or None


class NormalizedView(nn.Module):
    """A view of z-scored features whose statistics are buffers (``mean``, ``std``, and
    ``has_statistics``), so checkpoints carry them. Subclasses set ``feature_shape``."""

    feature_shape: tuple[int, ...]

    def __init__(self, *, mean: torch.Tensor | None = None, std: torch.Tensor | None = None):
        super().__init__()
        self.register_buffer("mean", torch.zeros(self.feature_shape))
        self.register_buffer("std", torch.ones(self.feature_shape))
        self.register_buffer("has_statistics", torch.tensor(False))
        if (mean is None) != (std is None):
            raise ValueError("give both mean and std, or neither")
        if mean is not None:
            self.set_statistics(mean, std)

    def set_statistics(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        mean, std = (
            torch.as_tensor(mean, dtype=torch.float32),
            torch.as_tensor(std, dtype=torch.float32),
        )
        if mean.shape != self.feature_shape or std.shape != self.feature_shape:
            raise ValueError(
                f"{type(self).__name__} statistics must have shape {self.feature_shape}, got "
                f"{tuple(mean.shape)} and {tuple(std.shape)}"
            )
        self.mean.copy_(mean)
        self.std.copy_(std)
        self.has_statistics.fill_(True)

    def denormalize(self, features: torch.Tensor) -> torch.Tensor:
        return features * self.std + self.mean


class InterHumanView(NormalizedView):
    """Normalized (B, T, 262) features <-> (B, T, 22, 12) [pos, vel, rot6d] per joint.

    ``relative_positions`` (off in the paper's configuration): the horizontal (x, z) position of
    every joint but the root enters the image in metres from the root, not in the shared frame.
    Then only the root's channels say where the person stands, and the other joints' codes are
    free for the pose: in the shared frame every joint's code must also say where the person
    stands. On the CPU demo's tokenizer (two seeds) it raised reconstruction success from 39.5%
    to 45.5% on average and lowered MPJPE, FID and the wrists' error on both seeds
    (docs/decisions.md: model.net.view.relative_positions). The map is linear and exactly
    inverted by :meth:`from_joints`, so the features, the losses and the decoded motion keep the
    dataset's frame.
    """

    num_joints = NUM_JOINTS
    channels = ih.JOINT_VIEW_CHANNELS
    feature_shape = (ih.FEATURE_DIM,)

    def __init__(
        self,
        *,
        mean: torch.Tensor | None = None,
        std: torch.Tensor | None = None,
        relative_positions: bool = False,
    ) -> None:
        """Statistics may come later (``set_statistics``, called with the datamodule's); a
        checkpoint restores them with the weights."""
        super().__init__(mean=mean, std=std)
        self.relative_positions = relative_positions

    def to_joints(self, features: torch.Tensor) -> torch.Tensor:
        """(B, T, 262) normalized -> (B, T, 22, 12); the root's absent rotation is 0."""
        joints = ih.features_to_joint_view(features)
        if not self.relative_positions:
            return joints
        mean, std = self._position_statistics()
        metres = (joints[..., :3] * std + mean)[..., _HORIZONTAL]  # (B, T, 22, 2)
        return _with_horizontal(joints, metres[..., 1:, :] - metres[..., :1, :])

    def from_joints(self, joints: torch.Tensor) -> torch.Tensor:
        """(B, T, 22, 12) -> (B, T, 262); contacts come back as 0 in normalized space."""
        if self.relative_positions:
            mean, std = (s[..., _HORIZONTAL] for s in self._position_statistics())  # (22, 2)
            root = joints[..., :1, _HORIZONTAL] * std[:1] + mean[:1]  # (B, T, 1, 2) metres
            shared = joints[..., 1:, _HORIZONTAL] + root  # metres in the shared frame
            joints = _with_horizontal(joints, (shared - mean[1:]) / std[1:])
        return ih.joint_view_to_features(joints)

    def _position_statistics(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(22, 3) mean and std of the joint positions, in metres."""
        return (
            self.mean[ih.POSITIONS].view(NUM_JOINTS, 3),
            self.std[ih.POSITIONS].view(NUM_JOINTS, 3),
        )

    def reconstruction_mask(self, device: torch.device) -> torch.Tensor:
        """(262,) bool: the dims the reconstruction loss covers (all but the 4 contacts)."""
        mask = torch.ones(ih.FEATURE_DIM, dtype=torch.bool, device=device)
        mask[ih.CONTACTS] = False
        return mask

    @property
    def has_positions(self) -> bool:
        """InterHuman features carry joint positions (InterXView needs a body model for them)."""
        return True

    def geometry(self, features: torch.Tensor) -> Geometry:
        """(B, T, 262) normalized -> de-normalized Geometry."""
        parts = ih.split_features(self.denormalize(features))
        return Geometry(parts.positions, parts.rot6d, (parts.contacts > 0.5).to(features.dtype))


class InterXView(nn.Module):
    """(B, T, 56, 6) representation, which already is a per-joint image (no normalization).

    Positions need a body model: pass its ``(22, 3)`` rest offsets as ``body_offsets``; without
    them positions are None and the position-based losses are switched off by the caller.
    """

    num_joints = ix.NUM_ROWS
    channels = ix.RAW_CHANNELS
    feature_shape = (ix.NUM_ROWS, ix.RAW_CHANNELS)

    def __init__(self, *, body_offsets: torch.Tensor | None = None, up_axis: str = "z") -> None:
        super().__init__()
        self.up_axis = up_axis
        if body_offsets is not None:
            body_offsets = torch.as_tensor(body_offsets, dtype=torch.float32)
            if body_offsets.shape != (NUM_JOINTS, 3):
                raise ValueError(
                    f"body_offsets must have shape (22, 3), got {tuple(body_offsets.shape)}"
                )
        self.register_buffer("body_offsets", body_offsets)

    @property
    def has_positions(self) -> bool:
        return self.body_offsets is not None

    def to_joints(self, features: torch.Tensor) -> torch.Tensor:
        return features

    def from_joints(self, joints: torch.Tensor) -> torch.Tensor:
        return joints

    def reconstruction_mask(self, device: torch.device) -> torch.Tensor:
        return torch.ones(self.feature_shape, dtype=torch.bool, device=device)

    def denormalize(self, features: torch.Tensor) -> torch.Tensor:
        return features

    def geometry(self, features: torch.Tensor) -> Geometry:
        rot6d = features[..., : ix.NUM_ROTATION_ROWS, :]
        if not self.has_positions:
            return Geometry(None, rot6d, None)
        positions = ix.person_joint_positions(
            features, "interx", offsets=self.body_offsets, up_axis=self.up_axis
        )
        contacts = ih.foot_contacts(positions)
        contacts = torch.cat(
            (contacts, contacts[..., -1:, :]), dim=-2
        )  # repeat the last frame's label
        return Geometry(positions, rot6d, contacts)


class HumanML3DView(NormalizedView):
    """Normalized (B, T, 263) HumanML3D features <-> (B, T, 1, 263): the whole frame is one
    row of channels, MoMask's 1D temporal tokenizer (``layout: 1d`` with one "joint").

    Geometry: positions rebuilt from the features (:func:`~intermask.motion.humanml3d.
    recover_from_ric`, the root integrated over the window), the 21 local 6D rotations, and the
    four foot-contact labels.
    """

    num_joints = 1
    channels = hml.FEATURE_DIM
    feature_shape = (hml.FEATURE_DIM,)

    def to_joints(self, features: torch.Tensor) -> torch.Tensor:
        return features[..., None, :]

    def from_joints(self, joints: torch.Tensor) -> torch.Tensor:
        return joints[..., 0, :]

    def reconstruction_mask(self, device: torch.device) -> torch.Tensor:
        """(263,) all True: MoMask reconstructs every dimension, foot contacts included."""
        return torch.ones(hml.FEATURE_DIM, dtype=torch.bool, device=device)

    @property
    def has_positions(self) -> bool:
        return True

    def geometry(self, features: torch.Tensor) -> Geometry:
        """(B, T, 263) normalized -> de-normalized Geometry."""
        raw = self.denormalize(features)
        rot6d = raw[..., hml.ROTATIONS].unflatten(-1, (NUM_JOINTS - 1, 6))
        contacts = (raw[..., hml.FOOT_CONTACTS] > 0.5).to(features.dtype)
        return Geometry(hml.recover_from_ric(raw), rot6d, contacts)


class TwoPersonView(nn.Module):
    """Both persons as one image (the interaction-level VQ ablation, InterMask Table 2).

    Features (B, T, 2, *F) -> (B, T, J, 2C): the per-joint channels of person 1, then person 2,
    so one token grid describes the pair. Losses and geometry stay per person
    (:meth:`split_persons` folds the persons into the batch).
    """

    def __init__(self, *, person: nn.Module) -> None:
        super().__init__()
        self.person = person
        self.num_joints = person.num_joints
        self.channels = 2 * person.channels
        self.feature_shape = (2, *person.feature_shape)

    def to_joints(self, features: torch.Tensor) -> torch.Tensor:
        return rearrange(self.person.to_joints(features), "b t p j c -> b t j (p c)")

    def from_joints(self, joints: torch.Tensor) -> torch.Tensor:
        return self.person.from_joints(rearrange(joints, "b t j (p c) -> b t p j c", p=2))

    @staticmethod
    def split_persons(features: torch.Tensor) -> torch.Tensor:
        """(B, T, 2, *F) -> (2B, T, *F)."""
        return rearrange(features, "b t p ... -> (b p) t ...")


def person_view(view: nn.Module) -> nn.Module:
    """The single-person view inside ``view`` (itself unless it is a TwoPersonView)."""
    return view.person if isinstance(view, TwoPersonView) else view
