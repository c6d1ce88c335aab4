"""InterMask: text-driven two-person interaction generation as a Lightning + Hydra framework.

Shape glossary used in every docstring:
    B  batch            P  persons (2)         T  frames            J  joints
    C  channels         N  tokens per person   Q  quantizer layers  K  codebook size
    D  model width      L  text tokens

Stages live in sub-packages named after them: ``motion`` (representations, pure functions),
``data`` (readers, synthetic dataset, DataModule), ``text``, ``vq``, ``interm``, ``evaluator``,
``metrics``, ``reaction``, ``render`` and ``body`` (SMPL-X / SMPL-H bodies fitted to motion).
"""

__version__ = "0.1.0"
