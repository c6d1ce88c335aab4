"""LightningDataModule over a single-person text-to-motion release (HumanML3D's layout).

Two kinds of batch, as in MoMask: ``mode="window"`` gives the tokenizer's fixed windows
(:class:`~intermask.data.humanml3d.HumanML3DWindows`), ``mode="item"`` the text-motion items
of the transformers and the evaluation (:class:`~intermask.data.humanml3d.HumanML3DDataset`).
Statistics are the release's own ``Mean.npy`` / ``Std.npy`` (the reference z-scores with them);
loaders, seeding and data-parallel sharding are :class:`EpochDataModule`'s. A folder that fails to
load is reported whole: the DataError lists every problem of ``intermask data check``'s checker.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Literal

from intermask.data.datamodule import EpochDataModule, Split
from intermask.data.errors import DataError
from intermask.data.humanml3d import HumanML3DDataset, HumanML3DLayout, HumanML3DWindows
from intermask.data.normalization import Normalizer
from intermask.data.validation import all_problems_error
from intermask.motion.humanml3d import FEATURE_DIM

log = logging.getLogger(__name__)

TextMotionMode = Literal["window", "item"]


class TextMotionDataModule(EpochDataModule):
    """Train/val/test loaders for one HumanML3D-layout folder.

    mode: "window" (tokenizer training) or "item" (text-motion items).
    window, stride: the windows (MoMask: 64 frames, every start).
    max_length, min_length, max_frames, unit_length, length_jitter: the items (MoMask: crops of
        at most 196 frames, clips of [40, 200) frames, lengths in units of 4, one unit fewer
        with p = 1/3).
    synthesize_if_missing: write the embedded synthetic dataset at ``root`` (``synthetic_clips``
        clips, ``synthetic_seed``) in prepare_data when ``root`` does not exist.
    """

    feature_shape = (FEATURE_DIM,)

    def __init__(
        self,
        *,
        root: str,
        dataset: Literal["humanml3d"] = "humanml3d",
        mode: TextMotionMode = "item",
        batch_size: int = 64,
        eval_batch_size: int | None = None,
        num_workers: int = 0,
        pin_memory: bool = False,
        persistent_workers: bool = False,
        drop_last: bool = False,
        window: int = 64,
        stride: int = 1,
        max_length: int = 196,
        min_length: int = 40,
        max_frames: int = 200,
        unit_length: int = 4,
        length_jitter: bool = True,
        seed: int = 3407,
        eval_shuffle: bool = False,
        synthesize_if_missing: bool = False,
        synthetic_clips: int = 1000,
        synthetic_seed: int = 0,
    ):
        super().__init__()
        if dataset != "humanml3d":
            raise ValueError(f"dataset must be 'humanml3d', got {dataset!r}")
        if mode not in ("window", "item"):
            raise ValueError(f"mode must be 'window' or 'item', got {mode!r}")
        self.save_hyperparameters()
        self._set_loading(
            batch_size=batch_size,
            eval_batch_size=eval_batch_size,
            num_workers=num_workers,
            pin_memory=pin_memory,
            persistent_workers=persistent_workers,
            drop_last=drop_last,
            seed=seed,
            eval_shuffle=eval_shuffle,
        )
        self.dataset, self.root, self.mode = dataset, Path(root), mode
        self.window, self.stride = window, stride
        self.max_length, self.min_length, self.max_frames = max_length, min_length, max_frames
        self.unit_length, self.length_jitter = unit_length, length_jitter
        self.synthesize_if_missing = synthesize_if_missing
        self.synthetic_clips, self.synthetic_seed = synthetic_clips, synthetic_seed

    def prepare_data(self) -> None:
        """Rank zero only: synthesize the dataset when ``root`` is missing and asked to."""
        if not self.root.exists() and self.synthesize_if_missing:
            from intermask.data.synthetic.humanml3d import generate_humanml3d

            log.info(
                "synthesizing %d HumanML3D-layout clips into %s (seed %d)",
                self.synthetic_clips,
                self.root,
                self.synthetic_seed,
            )
            generate_humanml3d(self.root, clips=self.synthetic_clips, seed=self.synthetic_seed)

    def setup(self, stage: str | None = None) -> None:
        """As :meth:`EpochDataModule.setup`; a dataset that fails to load raises one DataError
        listing every problem ``intermask data check`` finds, not only the first."""
        try:
            super().setup(stage)
        except DataError as first:
            error = all_problems_error(self.root, "humanml3d", first)
            if error is first:
                raise
            raise error from None  # the list holds the first error's message

    def load_normalizer(self) -> Normalizer:
        layout = HumanML3DLayout(self.root)
        if not self.root.is_dir():
            raise DataError(f"{self.root}: dataset root not found (expected the HumanML3D folder)")
        return Normalizer.from_files(
            layout.mean_file, layout.std_file, feature_shape=(FEATURE_DIM,)
        )

    def build_dataset(
        self, split: Split, *, mode: TextMotionMode | None = None
    ) -> HumanML3DDataset | HumanML3DWindows:
        """The dataset of ``split`` with this module's settings."""
        if (mode or self.mode) == "window":
            return HumanML3DWindows(
                root=self.root,
                split=split,
                window=self.window,
                stride=self.stride,
                normalizer=self.normalizer,
            )
        return HumanML3DDataset(
            root=self.root,
            split=split,
            max_length=self.max_length,
            min_length=self.min_length,
            max_frames=self.max_frames,
            unit_length=self.unit_length,
            length_jitter=self.length_jitter,
            normalizer=self.normalizer,
            seed=self.seed,
        )
