"""ARFlow: action-to-reaction flow matching with physical guidance (Jiang et al.).

Shapes: B batch, T frames, D flat per-frame features (262 InterHuman, 56 x 6 = 336 Inter-X),
*F the dataset's per-frame feature shape, 22 joints.

Modules: ``roles`` (who acts: the dataset annotation, else person 1), ``representation`` (the
flow's space and its way to joints), ``network`` (the online / offline Transformer decoder),
``flow`` (path, x1-prediction Euler steps), ``guidance`` (vanilla and reprojection guidance,
stochastic sampling), ``losses`` (reconstruction and interaction loss), ``sampler`` (batched
generation: :func:`sample_reactions`), ``module`` (the LightningModule).
"""

from intermask.reaction.flow import SIGMA_MIN, STEPS, euler_step, interpolate, recover_x0
from intermask.reaction.guidance import Guidance, penetration_gradient
from intermask.reaction.losses import interaction_loss, reconstruction_loss
from intermask.reaction.module import ARFlowModule
from intermask.reaction.network import ReactionDecoder
from intermask.reaction.representation import FeatureSpace
from intermask.reaction.roles import actor_index, place_reaction, split_roles
from intermask.reaction.sampler import (
    ReactionParts,
    ReactionSample,
    generate_reaction,
    sample_reactions,
)

__all__ = [
    "SIGMA_MIN",
    "STEPS",
    "ARFlowModule",
    "FeatureSpace",
    "Guidance",
    "ReactionDecoder",
    "ReactionParts",
    "ReactionSample",
    "actor_index",
    "euler_step",
    "generate_reaction",
    "interaction_loss",
    "interpolate",
    "penetration_gradient",
    "place_reaction",
    "reconstruction_loss",
    "recover_x0",
    "sample_reactions",
    "split_roles",
]
