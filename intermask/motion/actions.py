"""The interaction action vocabulary: the labels of the embedded dataset's clips
(``interaction_meta.json``) and the rows of the geometric interaction success metric.

Action id = position in :data:`ACTIONS` (Inter-X-layout names carry it as ``Aaaa``). The
synthetic data generator choreographs each of these (``intermask.data.synthetic.clips``) and the
success metric checks each (``intermask.metrics.interaction``); both read them from here.
"""

from __future__ import annotations

ACTIONS: tuple[str, ...] = (
    "handshake",
    "hug",
    "push",
    "punch_dodge",
    "wave",
    "bow",
    "walk_meet",
    "dance",
    "pass_object",
    "high_five",
    "kick_block",
    "chase",
    "pat_shoulder",
    "beckon",
)
# the actions whose success needs the two bodies to touch
CONTACT_ACTIONS: tuple[str, ...] = (
    "handshake",
    "hug",
    "push",
    "pass_object",
    "high_five",
    "pat_shoulder",
)
