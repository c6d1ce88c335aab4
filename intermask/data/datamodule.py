"""LightningDataModule over the InterHuman / Inter-X readers.

Batches are the default collate of the dataset items: a dict of tensors ("motion" (B, 2, T, C...)
or (B, window, C...), "length" (B,), ...) and lists of strings ("caption", "id", ...).

Randomness: every item is drawn from a generator seeded by (seed, epoch, index) and the order from
(seed, epoch) (``EpochSampler``), so a pass is identical across runs, machines and worker counts;
Lightning moves the epoch forward during training. ``eval_dataloader(epoch=k)`` replays pass k.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

from lightning import LightningDataModule
from torch.utils.data import DataLoader, Dataset

from intermask.data.common import EpochSampler
from intermask.data.errors import DataError
from intermask.data.normalization import Normalizer, default_stats_dir, stats_exist
from intermask.data.reader import ClipReader, Mode
from intermask.data.readers import reader_class
from intermask.data.statistics import compute_and_save_stats
from intermask.motion.kinds import DatasetKind
from intermask.utils.seeds import keyed_generator

log = logging.getLogger(__name__)

# The key of a loader's own generator, (seed, WORKER_SEED_KEY, epoch): torch draws every
# iterator's worker base seed from the loader's generator, or from torch's global one when it has
# none, which would shift the dropout draws of a resumed run that makes one iterator more or less
# than the run it continues.
WORKER_SEED_KEY = 1

Split = Literal["train", "val", "test"]
STAGE_SPLITS: dict[str, tuple[Split, ...]] = {
    "fit": ("train", "val"),
    "validate": ("val",),
    "test": ("test",),
    "predict": ("test",),
}


class ResumableDataLoader(DataLoader):
    """The training loader: a fit resumed from a checkpoint saved in the middle of an epoch (a
    SIGTERM, Slurm's requeue signal) continues that epoch with the batch after the last one
    trained, so it sees the batches of the run that was never stopped.

    Lightning keeps ``state_dict()`` (the pass's epoch and the batches handed out so far) in every
    checkpoint of a fit, and gives it back through ``load_state_dict`` when a fit resumes from it
    (a loader with both methods is "stateful" to Lightning). The next pass of that epoch then
    starts that many batches in (``EpochSampler.skip``: the skipped items are never read). A
    checkpoint of an epoch's end resumes at the next epoch, from its start.

    The sampler's order is drawn at the first batch of a pass, not when the iterator is made:
    Lightning makes the first iterator before it sets the resumed epoch on the sampler, and with
    worker processes the order would otherwise be drawn for the wrong epoch. Each pass draws its
    workers' base seed from a generator keyed by (seed, epoch), never from torch's global one.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        if not isinstance(self.sampler, EpochSampler) or self.batch_size is None:
            raise TypeError("ResumableDataLoader needs an EpochSampler and a batch_size")
        self.pass_epoch: int | None = None  # the epoch of the pass under way
        self.batches_out = 0  # batches of that pass handed out (skipped ones included)
        self._resume: tuple[int, int] | None = None

    def state_dict(self) -> dict[str, int]:
        epoch = self.sampler.epoch if self.pass_epoch is None else self.pass_epoch
        return {"epoch": int(epoch), "batches": int(self.batches_out)}

    def load_state_dict(self, state_dict: dict[str, int]) -> None:
        self._resume = (int(state_dict["epoch"]), int(state_dict["batches"]))

    def __iter__(self) -> Iterator[Any]:
        return self._pass()

    def _pass(self) -> Iterator[Any]:
        sampler: EpochSampler = self.sampler
        skip = 0
        if self._resume is not None:
            epoch, batches = self._resume
            self._resume = None
            if epoch == sampler.epoch:  # else the checkpoint ended its epoch: start the next
                skip = batches
        sampler.skip = skip * self.batch_size
        self.pass_epoch, self.batches_out = sampler.epoch, skip
        self.generator = keyed_generator(sampler.seed, WORKER_SEED_KEY, sampler.epoch)
        for batch in super().__iter__():
            self.batches_out += 1
            yield batch


class EpochDataModule(LightningDataModule):
    """Reproducible train/val/test loaders over ``self.datasets`` (split -> dataset whose items
    take ``(index, epoch)`` keys): every pass is drawn by an :class:`EpochSampler` seeded by
    ``(seed, epoch)``, and data-parallel ranks read their blocks of every global batch.

    Subclasses set ``batch_size``, ``eval_batch_size``, ``num_workers``, ``pin_memory``,
    ``persistent_workers``, ``drop_last``, ``seed``, ``eval_shuffle`` and ``datasets``, and
    build a split's dataset in ``setup``.
    """

    batch_size: int
    eval_batch_size: int
    num_workers: int
    pin_memory: bool
    persistent_workers: bool
    drop_last: bool
    seed: int
    eval_shuffle: bool
    datasets: dict[str, Dataset]
    normalizer: Normalizer | None

    def _set_loading(
        self,
        *,
        batch_size: int,
        eval_batch_size: int | None,
        num_workers: int,
        pin_memory: bool,
        persistent_workers: bool,
        drop_last: bool,
        seed: int,
        eval_shuffle: bool,
    ) -> None:
        """The loader settings every subclass takes (checked), and no data yet."""
        if batch_size < 1:
            raise ValueError(f"batch_size must be >= 1, got {batch_size}")
        self.batch_size = batch_size
        self.eval_batch_size = eval_batch_size or batch_size
        self.num_workers, self.pin_memory = num_workers, pin_memory
        self.persistent_workers = persistent_workers and num_workers > 0
        self.drop_last = drop_last
        self.seed, self.eval_shuffle = seed, eval_shuffle
        self.normalizer = None
        self.datasets = {}
        self._train_loader: ResumableDataLoader | None = None
        self._train_position: dict[str, int] | None = None  # from a checkpoint, for the next one

    def load_normalizer(self) -> Normalizer | None:
        raise NotImplementedError

    def build_dataset(self, split: Split) -> Dataset:
        raise NotImplementedError

    def setup(self, stage: str | None = None) -> None:
        """Load the statistics once, then build the splits ``stage`` needs (all for None)."""
        if self.normalizer is None:
            self.normalizer = self.load_normalizer()
        for split in STAGE_SPLITS.get(stage or "", ("train", "val", "test")):
            if split not in self.datasets:
                self.datasets[split] = self.build_dataset(split)

    # ------------------------------------------------------------------ loaders

    def _processes(self) -> tuple[int, int]:
        """(rank, world size) of the attached trainer; (0, 1) outside one."""
        trainer = getattr(self, "trainer", None)
        if trainer is None:
            return 0, 1
        rank, world = int(trainer.global_rank), int(trainer.world_size)
        if world > 1 and getattr(trainer._accelerator_connector, "use_distributed_sampler", False):
            raise ValueError(
                "trainer.use_distributed_sampler must be false: the datamodule gives each process "
                "its block of every global batch itself (a second sampler would drop data)"
            )
        return rank, world

    def _loader(
        self,
        split: Split,
        *,
        batch_size: int,
        shuffle: bool,
        drop_last: bool,
        epoch: int = 0,
        sharded: bool = True,
        resumable: bool = False,
    ) -> DataLoader:
        """``sharded``: under a data-parallel trainer, each rank reads its block of every global
        batch (``EpochSampler``); the trainer must not add its own distributed sampler.
        ``resumable``: a :class:`ResumableDataLoader` (the training loader)."""
        if split not in self.datasets:
            self.setup({"train": "fit", "val": "validate", "test": "test"}[split])
        dataset = self.datasets[split]
        rank, world = self._processes() if sharded else (0, 1)
        loader = ResumableDataLoader if resumable else DataLoader
        sampler = EpochSampler(
            len(dataset),
            shuffle=shuffle,
            seed=self.seed,
            epoch=epoch,
            batch_size=batch_size,
            rank=rank,
            world_size=world,
            drop_last=drop_last,
        )
        return loader(
            dataset,
            batch_size=batch_size,
            sampler=sampler,
            num_workers=self.num_workers,
            pin_memory=self.pin_memory,
            persistent_workers=self.persistent_workers,
            drop_last=drop_last,
            generator=keyed_generator(self.seed, WORKER_SEED_KEY, epoch),
        )

    def train_dataloader(self) -> DataLoader:
        loader = self._loader(
            "train",
            batch_size=self.batch_size,
            shuffle=True,
            drop_last=self.drop_last,
            resumable=True,
        )
        if self._train_position is not None:
            loader.load_state_dict(self._train_position)
            self._train_position = None
        self._train_loader = loader
        return loader

    # The training loader's position travels in the datamodule's entry of every checkpoint, which
    # Lightning restores before it makes the loader. Lightning would also restore the loader's own
    # state (it is stateful), but only when the loader is made after the loops are restored; the
    # learning-rate schedules ask for the number of steps (estimated_stepping_batches), which
    # makes the loader earlier, so that path never runs.

    def state_dict(self) -> dict[str, Any]:
        if self._train_loader is None:
            return {}
        return {"train_loader": self._train_loader.state_dict()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        position = state_dict.get("train_loader")
        if position is None:
            return
        if self._train_loader is not None:
            self._train_loader.load_state_dict(position)
        else:
            self._train_position = dict(position)

    def val_dataloader(self) -> DataLoader:
        return self._loader(
            "val", batch_size=self.eval_batch_size, shuffle=self.eval_shuffle, drop_last=False
        )

    def test_dataloader(self) -> DataLoader:
        return self._loader(
            "test", batch_size=self.eval_batch_size, shuffle=self.eval_shuffle, drop_last=False
        )

    def eval_dataloader(
        self,
        split: Split = "test",
        *,
        batch_size: int | None = None,
        shuffle: bool = True,
        drop_last: bool = True,
        epoch: int = 0,
    ) -> DataLoader:
        """A reproducible evaluation pass: pass ``epoch`` re-draws crops, captions, order and
        person swaps; the same ``(seed, epoch)`` gives the same batches in every run.

        Defaults follow the protocol (shuffled eval batches, drop_last); the GT-vs-GT FID needs two
        passes with different epochs.
        """
        return self._loader(
            split,
            batch_size=batch_size or self.eval_batch_size,
            shuffle=shuffle,
            drop_last=drop_last,
            epoch=epoch,
            sharded=False,  # protocol passes run whole on one process (rank 0 during training)
        )


class InteractionDataModule(EpochDataModule):
    """Train/val/test loaders for one dataset folder.

    dataset: the dataset kind (the features every model and metric downstream expects).
    reader: the :class:`~intermask.data.reader.ClipReader` that reads ``root``, as a class or a
        dotted import path; None = the framework's reader of ``dataset``
        (:mod:`intermask.data.readers`). Its class attributes give the defaults below.
    max_length, min_length: None = the reader's defaults (InterHuman 300 / 15, Inter-X 150 / 24).
    normalize: None = dataset default (InterHuman yes, Inter-X no, as in the reference).
    swap_persons: None = dataset default (InterHuman yes in every split, Inter-X no).
    mirror: mirrored copies in the training split only (InterHuman only).
    stats_dir: where mean.npy/std.npy (or the reference global_mean.npy/global_std.npy) live;
        default ``<root>/stats``. Missing statistics are computed from the training split when
        ``compute_stats`` is on, otherwise setup raises with the command that computes them.
    synthesize_if_missing: build the synthetic dataset at ``root`` (``synthetic_clips`` clips,
        ``synthetic_seed``) in prepare_data when ``root`` does not exist.
    """

    def __init__(
        self,
        *,
        dataset: DatasetKind,
        root: str,
        reader: str | type[ClipReader] | None = None,
        mode: Mode = "interaction",
        batch_size: int = 32,
        eval_batch_size: int | None = None,
        num_workers: int = 0,
        pin_memory: bool = False,
        persistent_workers: bool = False,
        drop_last: bool = False,
        max_length: int | None = None,
        min_length: int | None = None,
        window: int = 64,
        stride: int = 10,
        window_persons: int = 1,
        mirror: bool = True,
        swap_persons: bool | None = None,
        normalize: bool | None = None,
        stats_dir: str | None = None,
        compute_stats: bool = True,
        seed: int = 3407,
        eval_shuffle: bool = False,
        synthesize_if_missing: bool = False,
        synthetic_clips: int = 200,
        synthetic_seed: int = 0,
    ):
        super().__init__()
        self.reader = reader_class(dataset, reader)
        if mode not in ("interaction", "window"):
            raise ValueError(f"mode must be 'interaction' or 'window', got {mode!r}")
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
        self.max_length = max_length or self.reader.default_max_length
        self.min_length = min_length or self.reader.default_min_length
        self.window, self.stride, self.window_persons = window, stride, window_persons
        # Inter-X has no mirror augmentation in the reference (no left/right caption tokens to
        # swap in its POS-tagged texts); the flag is ignored there, loudly.
        self.mirror = mirror and self.reader.supports_mirror
        if mirror and not self.reader.supports_mirror:
            log.info(
                "%s has no mirror augmentation; training runs without it", self.reader.__name__
            )
        self.swap_persons = (
            self.reader.default_swap_persons if swap_persons is None else swap_persons
        )
        self.normalize = self.reader.default_normalize if normalize is None else normalize
        self.stats_dir = Path(stats_dir) if stats_dir else default_stats_dir(root)
        self.compute_stats = compute_stats
        self.synthesize_if_missing = synthesize_if_missing
        self.synthetic_clips, self.synthetic_seed = synthetic_clips, synthetic_seed

    @property
    def feature_shape(self) -> tuple[int, ...]:
        """Per-person, per-frame feature shape: (262,) or (56, 6)."""
        return self.reader.feature_shape

    # ------------------------------------------------------------------ preparation

    def prepare_data(self) -> None:
        """Rank zero only: synthesize the dataset and compute statistics if they are missing."""
        if not self.root.exists() and self.synthesize_if_missing:
            from intermask.data.synthetic import generate_dataset

            log.info(
                "synthesizing %d %s clips into %s (seed %d)",
                self.synthetic_clips,
                self.dataset,
                self.root,
                self.synthetic_seed,
            )
            generate_dataset(
                self.root, format=self.dataset, clips=self.synthetic_clips, seed=self.synthetic_seed
            )
        if (
            self.normalize
            and self.compute_stats
            and self.root.is_dir()
            and not stats_exist(self.stats_dir)
        ):
            self._compute_stats()

    def _compute_stats(self) -> None:
        log.info(
            "computing normalization statistics of %s (train split) into %s",
            self.root,
            self.stats_dir,
        )
        compute_and_save_stats(
            self.root,
            dataset=self.dataset,
            reader=self.reader,
            split="train",
            out_dir=self.stats_dir,
        )

    def load_normalizer(self) -> Normalizer | None:
        if not self.normalize:
            return None
        if not stats_exist(self.stats_dir):
            if not self.compute_stats:
                command = f"intermask data stats {self.root} --format {self.dataset} --out {self.stats_dir}"
                raise DataError(
                    f"{self.stats_dir}: normalization statistics not found; compute them with "
                    f"`{command}` or set compute_stats=true"
                )
            self._compute_stats()
        return Normalizer.load(self.stats_dir, feature_shape=self.feature_shape)

    def build_dataset(self, split: Split, *, mode: Mode | None = None) -> ClipReader:
        """The dataset of ``split`` with this module's settings (mirroring in train only)."""
        common = dict(
            root=self.root,
            split=split,
            mode=mode or self.mode,
            max_length=self.max_length,
            min_length=self.min_length,
            window=self.window,
            stride=self.stride,
            window_persons=self.window_persons,
            swap_persons=self.swap_persons,
            normalizer=self.normalizer,
            seed=self.seed,
        )
        if self.reader.supports_mirror:
            common["mirror"] = self.mirror and split == "train"
        return self.reader(**common)
