"""Physical plausibility of two-person motion: a capsule body proxy, penetration metrics, a loss.

Shapes: B batch, T frames, J joints (22), K capsules (28), N points. Joints are in metres in any
frame (the proxy is rotation-invariant and the voxel lattice is invariant under axis swaps), so
Y-up positions from ``intermask.motion.to_joint_positions`` and Z-up raw joints both work.

Modules: ``capsules`` (the proxy and its signed distance), ``volume`` (Intersection Volume and
Frequency, ARFlow section 4.1), ``loss`` (relu(zeta - SDF) guidance loss, ARFlow eq. 10),
``mesh_volume`` (the same Intersection Volume on two body meshes, ARFlow's own definition).
The capsule numbers come from a skeleton proxy, not SMPL-X meshes: they compare only with each
other; fitted bodies (``intermask.body``) give the mesh measure.
"""

from intermask.physics.capsules import (
    CAPSULE_NAMES,
    DEFAULT_PROXY,
    DEFAULT_RADII,
    PARTS,
    TEMPLATE_HEIGHT,
    BodyProxy,
    Capsules,
    body_capsules,
    capsule_distances,
    segment_distances,
    signed_distance,
    skeleton_height,
)
from intermask.physics.loss import (
    DEFAULT_ZETA,
    bone_point_weights,
    bone_sample_points,
    penetration_loss,
)
from intermask.physics.mesh_volume import mesh_intersection_volume
from intermask.physics.volume import (
    DEFAULT_PITCH,
    DEFAULT_TOLERANCE,
    intersection_frequency,
    intersection_volume,
    penetrating_frames,
    shared_voxel_counts,
)

__all__ = [
    "CAPSULE_NAMES",
    "DEFAULT_PITCH",
    "DEFAULT_PROXY",
    "DEFAULT_RADII",
    "DEFAULT_TOLERANCE",
    "DEFAULT_ZETA",
    "PARTS",
    "TEMPLATE_HEIGHT",
    "BodyProxy",
    "Capsules",
    "body_capsules",
    "bone_point_weights",
    "bone_sample_points",
    "capsule_distances",
    "intersection_frequency",
    "intersection_volume",
    "mesh_intersection_volume",
    "penetrating_frames",
    "penetration_loss",
    "segment_distances",
    "shared_voxel_counts",
    "signed_distance",
    "skeleton_height",
]
