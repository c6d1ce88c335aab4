"""Frozen text encoders (open_clip CLIP) and their on-disk feature cache.

Shapes: ``B`` captions, ``L`` text tokens (CLIP: 77), ``D`` width (ViT-L/14: 768).
open_clip is imported lazily, on the first encoder construction, because it is slow to import.
"""

from intermask.text.cache import TextFeatureCache
from intermask.text.clip_encoder import (
    TINY_MODEL_NAME,
    FrozenCLIPTextEncoder,
    TextFeatures,
    register_model_configs,
)

__all__ = [
    "TINY_MODEL_NAME",
    "FrozenCLIPTextEncoder",
    "TextFeatureCache",
    "TextFeatures",
    "register_model_configs",
]
