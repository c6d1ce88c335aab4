"""Bodies, not sticks: SMPL-H / SMPL-X body parameters fitted to generated or dataset motion.

Modules: ``model`` (finding, checking and posing the user's licensed body-model file), ``standin``
(a generated stand-in with the official keys and kinematic tree, for tests and offline demos),
``fit`` (rotations from the representation, refined against the joint positions).
"""
