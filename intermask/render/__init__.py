"""Renderings and exports of interactions: GIF/MP4 animations, a self-contained HTML viewer, BVH.

Inputs are joint positions ``(T, P, 22, 3)`` in metres on the SMPL 22-joint skeleton
(:mod:`intermask.motion.skeleton`), Y-up unless a function takes ``up_axis="z"``.

Modules: ``projection`` (joint validation, cameras, perspective projection), ``frames`` (PIL
frames), ``animation`` (GIF/MP4 files), ``html_viewer`` (one-file offline viewer, its page in
``viewer_template.html``), ``bvh`` (BVH writer/parser, forward kinematics of a file),
``bvh_export`` (BVH clips from the InterHuman, Inter-X and HumanML3D representations) and
``gltf`` (``.glb`` files of skinned, animated characters: bodies or limb meshes).
"""

from intermask.render.animation import (
    quantize_exact,
    save_gif,
    save_mp4,
    style_palette,
    write_gif,
    write_mp4,
)
from intermask.render.bvh import BvhClip, bvh_joint_positions, read_bvh, write_bvh
from intermask.render.bvh_export import (
    estimate_offsets,
    humanml3d_bvh_clips,
    humanml3d_offsets,
    interhuman_bvh_clips,
    interx_bvh_clips,
    read_bvh_joints,
    root_rotation_from_joints,
    write_interaction_bvh,
)
from intermask.render.frames import DEFAULT_STYLE, Style, person_color, render_frames
from intermask.render.gltf import Character, limb_character, write_glb
from intermask.render.html_viewer import ViewerSample, viewer_html, write_html_viewer
from intermask.render.projection import VIEWS, Camera, prepare_joints

__all__ = [
    "DEFAULT_STYLE",
    "VIEWS",
    "BvhClip",
    "Camera",
    "Character",
    "Style",
    "ViewerSample",
    "bvh_joint_positions",
    "estimate_offsets",
    "humanml3d_bvh_clips",
    "humanml3d_offsets",
    "interhuman_bvh_clips",
    "interx_bvh_clips",
    "limb_character",
    "person_color",
    "prepare_joints",
    "quantize_exact",
    "read_bvh",
    "read_bvh_joints",
    "render_frames",
    "root_rotation_from_joints",
    "save_gif",
    "save_mp4",
    "style_palette",
    "viewer_html",
    "write_bvh",
    "write_gif",
    "write_glb",
    "write_html_viewer",
    "write_interaction_bvh",
    "write_mp4",
]
