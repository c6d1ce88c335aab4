"""Fitted bodies as glTF characters and as meshes: what the exports and the viewer draw."""

from __future__ import annotations

import numpy as np
import torch

from intermask.body.fit import BodyParams
from intermask.body.model import FACE_JOINTS, BodyModel, full_rotations
from intermask.body.standin import FINGERS
from intermask.motion.skeleton import JOINT_NAMES
from intermask.render.frames import DEFAULT_STYLE
from intermask.render.gltf import Character

POSE_CHUNK = 256  # frames posed at once by smplx's skinning (bounds the (N, V, 4, 4) temporaries)


def model_joint_names(model: BodyModel) -> tuple[str, ...]:
    """The model's joint names in its order (body, then SMPL-X's jaw and eyes, then the hands)."""
    face = ("jaw", "l_eye", "r_eye")[: FACE_JOINTS[model.kind]]
    hands = tuple(
        f"{side}_{finger}{k}" for side in ("l", "r") for finger in FINGERS for k in (1, 2, 3)
    )
    return (*JOINT_NAMES, *face, *hands)


def person_color(person: int) -> tuple[float, float, float]:
    """The viewer's and the renders' colour of a person, in [0, 1]."""
    color = DEFAULT_STYLE.person_colors[person % len(DEFAULT_STYLE.person_colors)]
    return tuple(c / 255.0 for c in color)  # type: ignore[return-value]


def body_characters(
    model: BodyModel, params: BodyParams, *, name: str = "person"
) -> list[Character]:
    """One skinned glTF character per fitted person: the shaped rest mesh, the model's skinning
    weights and the fitted rotations, Y up."""
    characters = []
    for person in range(params.betas.shape[0]):
        betas = params.betas[person].to(model.v_template)
        hands = None if params.hands is None else params.hands[person]
        rotations = full_rotations(model, params.rotations[person], hands)
        rest = model.rest_joints(betas)
        characters.append(
            Character(
                name=f"{name}{person + 1}",
                parents=model.parents,
                joint_names=model_joint_names(model),
                rest_joints=rest.double().cpu().numpy(),
                rotations=rotations.double().cpu().numpy(),
                root_positions=(rest[0] + params.transl[person].to(rest)).double().cpu().numpy(),
                vertices=model.shaped_vertices(betas).double().cpu().numpy(),
                faces=model.faces.cpu().numpy(),
                weights=model.weights.double().cpu().numpy(),
                color=person_color(person),
            )
        )
    return characters


@torch.no_grad()
def body_vertices(model: BodyModel, params: BodyParams) -> torch.Tensor:
    """(P, T, V, 3) posed vertices of the fitted bodies, pose correctives included (smplx's
    skinning), in chunks of POSE_CHUNK frames."""
    people = []
    for person in range(params.betas.shape[0]):
        hands = None if params.hands is None else params.hands[person]
        rotations = full_rotations(model, params.rotations[person], hands).to(model.v_template)
        transl = params.transl[person].to(model.v_template)
        betas = params.betas[person : person + 1].to(model.v_template)
        chunks = [
            model.pose(betas, rotations[k : k + POSE_CHUNK], transl[k : k + POSE_CHUNK])[0]
            for k in range(0, rotations.shape[0], POSE_CHUNK)
        ]
        people.append(torch.cat(chunks))
    return torch.stack(people)


def as_numpy(x: torch.Tensor | np.ndarray) -> np.ndarray:
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)
