"""The replication protocol on a fake split and evaluator whose embeddings are known exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from intermask.data.common import single_threaded
from intermask.data.synthetic import generate_clip
from intermask.evaluation.protocol import (
    MotionSource,
    ProtocolConstants,
    ProtocolRunner,
    Summary,
    repeat_items,
    sample_seeds,
)
from intermask.evaluation.report import action_table, format_summary, markdown_table, write_results

ITEMS, FRAMES, DIM = 48, 8, 6


def _split() -> dict:
    generator = torch.Generator().manual_seed(0)
    return {
        "motion": torch.randn(ITEMS, 2, FRAMES, DIM, generator=generator),
        "length": torch.full((ITEMS,), FRAMES),
        "caption": [f"item {i}" for i in range(ITEMS)],
    }


class Loader:
    """Shuffled, drop_last eval batches; the order depends on the epoch only."""

    def __init__(self, split: dict, batch_size: int):
        self.split, self.batch_size = split, batch_size
        self.items = ITEMS

    def __call__(self, epoch: int):
        order = torch.randperm(self.items, generator=torch.Generator().manual_seed(epoch))
        for start in range(0, self.items - self.batch_size + 1, self.batch_size):
            yield repeat_items(self.split, order[start : start + self.batch_size], 1)


class ExactEvaluator:
    """Motion embedding = flattened motion; text "item i" embeds to item i's GT motion."""

    name, file_hash = "exact", "0" * 16

    def __init__(self, split: dict):
        self.table = {
            c: m.flatten() for c, m in zip(split["caption"], split["motion"], strict=True)
        }

    def encode_motion(self, motion, lengths):
        return motion.flatten(1)

    def encode_text(self, captions, tokens=None):
        return torch.stack([self.table[c] for c in captions])


class Truth(MotionSource):
    name = "Ground Truth"

    def __call__(self, batch, seeds):
        return batch["motion"], batch["length"]


class Noise(MotionSource):
    """A 'generator' whose sample depends only on its seed."""

    name, generates = "Noise", True

    def __call__(self, batch, seeds):
        motion = torch.stack(
            [
                torch.randn(2, FRAMES, DIM, generator=torch.Generator().manual_seed(int(s)))
                for s in seeds
            ]
        )
        return motion, batch["length"]


class Copy(Truth):
    """A 'generator' that returns the GT whatever the seed: MultiModality 0."""

    name, generates = "Copy", True


def _runner(sources, **constants) -> ProtocolRunner:
    split = _split()
    settings = dict(
        eval_batch_size=8,
        replications=3,
        diversity_pairs=20,
        mm_texts=4,
        mm_generations=6,
        mm_pairs=3,
        emb_scale=1.0,
        divide_by=1.0,
        mm_scale=1.0,
    )
    settings.update(constants)
    c = ProtocolConstants(**settings)
    return ProtocolRunner(
        loader=Loader(split, c.eval_batch_size),
        evaluator=ExactEvaluator(split),
        ground_truth=Truth(),
        sources=sources,
        constants=c,
        generation_batch_size=12,
    )


def test_ground_truth_row_is_exact_and_noise_is_at_chance():
    result = _runner([Truth(), Noise(), Copy()]).run({"dataset": "fake", "mode": "interaction"})
    truth, noise, copy = (result.rows[name] for name in ("Ground Truth", "Noise", "Copy"))
    for k in (1, 2, 3):
        assert truth[f"top{k}"].mean == 1.0 and truth[f"top{k}"].ci95 == 0.0
    assert truth["mm_dist"].mean == pytest.approx(0.0, abs=1e-6)
    # the two passes hold the same 48 items in another order: identical embedding statistics
    assert truth["fid"].mean == pytest.approx(0.0, abs=1e-4)  # singular covariances
    assert noise["fid"].mean > 1.0 and noise["top3"].mean < 0.75
    assert "multimodality" not in truth
    assert noise["multimodality"].mean > 1.0 and copy["multimodality"].mean == pytest.approx(0.0)
    assert len(noise["top1"].values) == 3


def test_same_pass_fid_compares_each_row_with_the_gt_of_its_own_items():
    # 10-item batches of 48 items: each pass holds 40, a different 40 per epoch
    separate = _runner([Truth(), Noise()], eval_batch_size=10, replications=2)
    same = _runner(
        [Truth(), Noise()], eval_batch_size=10, replications=2, fid_reference="same_pass"
    )
    epochs = []
    loader = same.loader
    same.loader = lambda epoch: (epochs.append(epoch), loader(epoch))[1]
    apart, together = separate.run({}), same.run({})
    assert min(apart.rows["Ground Truth"]["fid"].values) > 1e-3  # two different 40-item sets
    assert together.rows["Ground Truth"]["fid"].values == pytest.approx([0.0, 0.0], abs=1e-4)
    assert [e for e in epochs if e < 10_000] == [1, 3]  # no reference pass (epochs 0, 2)
    assert together.rows["Noise"]["fid"].mean > 1.0
    assert together.rows["Noise"]["top1"].values == apart.rows["Noise"]["top1"].values
    with pytest.raises(ValueError, match="fid_reference must be one of .*got 'other_pass'"):
        ProtocolConstants(fid_reference="other_pass")


def test_rows_are_reproducible_and_replications_differ():
    first = _runner([Truth(), Noise()]).run({})
    second = _runner([Truth(), Noise()]).run({})
    assert first.rows["Noise"]["fid"].values == second.rows["Noise"]["fid"].values
    assert len(set(first.rows["Noise"]["fid"].values)) == 3  # fresh seeds every replication


def test_multimodality_respects_its_replication_count_and_switch():
    result = _runner([Noise()], mm_replications=1).run({})
    assert len(result.rows["Noise"]["multimodality"].values) == 1
    fast = _runner([Noise()])
    fast.multimodality = False
    assert "multimodality" not in fast.run({}).rows["Noise"]


def test_summary_is_mean_and_ci95_with_population_std():
    values = [0.3, 0.5, 0.4, 0.45]
    summary = Summary.of(values)
    assert summary.mean == pytest.approx(np.mean(values))
    assert summary.ci95 == pytest.approx(1.96 * np.std(values) / math.sqrt(4))
    assert format_summary(Summary(0.44912, 0.0041, [])) == "0.449±.004"
    assert format_summary(Summary(5.154, 1.234, [])) == "5.154±1.234"


def test_seeds_are_distinct_per_sample_stream_and_replication():
    c = ProtocolConstants()
    seeds = torch.cat(
        [sample_seeds(c, r, s, 50, o) for r in range(3) for s in range(2) for o in (0, 50)]
    )
    assert seeds.unique().numel() == seeds.numel()


def test_empty_split_and_duplicate_rows_are_errors():
    with pytest.raises(ValueError, match="gave no batch of 96 items"):
        _runner([Truth()], eval_batch_size=96).run({})
    with pytest.raises(ValueError, match="row names must be unique"):
        _runner([Truth(), Truth()])
    with pytest.raises(ValueError, match=r"mm_generations \(2\) must be >= mm_pairs \(3\)"):
        ProtocolConstants(mm_generations=2, mm_pairs=3)


def test_results_are_written_as_json_and_a_paper_style_table(tmp_path):
    result = _runner([Truth(), Noise()], replications=2).run(
        {
            "dataset": "fake",
            "split": "test",
            "mode": "interaction",
            "replications": 2,
            "evaluator": "exact (0000)",
            "fast": True,
        }
    )
    json_path, markdown_path = write_results(result, tmp_path)
    table = markdown_path.read_text()
    assert (
        "FAST MODE" in table and "| Ground Truth | 1.000±.000 | 1.000±.000 | 1.000±.000 |" in table
    )
    assert "R-Prec Top 1 ↑" in table and "MModality ↑" in table and "MPJPE" not in table
    assert "eval_batch_size=8" in table and "evaluator**: exact (0000)" in table
    assert '"Noise"' in json_path.read_text()
    assert markdown_table(result) == table


# ---------------------------------------------------------------------- interaction success
SUCCESS_ACTIONS = ("handshake", "wave", "push", "walk_meet")


def _labelled_split() -> dict:
    """8 generated clips (2 per action) as flattened joints (2, T, 66), with action labels."""
    with single_threaded():
        clips = [generate_clip(seed=9, index=i, action=a) for a in SUCCESS_ACTIONS for i in (0, 1)]
    frames = max(c.frames for c in clips)
    motion = torch.zeros(len(clips), 2, frames, 66)
    for row, clip in enumerate(clips):
        motion[row, :, : clip.frames] = clip.positions.flatten(2).float()
    return {
        "motion": motion,
        "length": torch.tensor([c.frames for c in clips]),
        "caption": [f"clip {i}" for i in range(len(clips))],
        "action": [c.action for c in clips],
        "actor": torch.tensor([c.actor for c in clips]),
    }


def _flat_joints(motion: torch.Tensor) -> torch.Tensor | None:
    """(B, 2, T, 66) -> (B, T, 2, 22, 3); None for any other width (no positions)."""
    if motion.shape[-1] != 66:
        return None
    return motion.unflatten(-1, (22, 3)).transpose(1, 2)


class FrozenReactor(MotionSource):
    name = "Frozen reactor"

    def __call__(self, batch, seeds):
        motion = batch["motion"].clone()
        rows = torch.arange(motion.shape[0])
        reactor = 2 - batch["actor"]  # the index of the person who is not the actor
        motion[rows, reactor] = motion[rows, reactor, :1]
        return motion, batch["length"]


class SwappedGeneration(MotionSource):
    """Persons in the other order: wrong for the annotation, right when roles are unknown."""

    name, knows_roles = "Swapped", False

    def __call__(self, batch, seeds):
        return batch["motion"].flip(1), batch["length"]


class NoPositions(MotionSource):
    """The same numbers in a layout the joints function does not know (as Inter-X rows without
    a body model would be)."""

    name = "No positions"

    def __call__(self, batch, seeds):
        return batch["motion"].unflatten(-1, (33, 2)), batch["length"]


class CornerEvaluator(ExactEvaluator):
    """The first 16 numbers of the flattened motion: small embeddings, cheap FID."""

    def __init__(self, split: dict):
        super().__init__(split)
        self.table = {c: m[:16] for c, m in self.table.items()}

    def encode_motion(self, motion, lengths):
        return motion.flatten(1)[:, :16]


def _success_runner(split: dict, sources: list[MotionSource]) -> ProtocolRunner:
    c = ProtocolConstants(eval_batch_size=4, replications=2, diversity_pairs=4, mm_replications=0)
    loader = Loader(split, c.eval_batch_size)
    loader.items = len(split["caption"])
    return ProtocolRunner(
        loader=loader,
        evaluator=CornerEvaluator(split),
        ground_truth=Truth(),
        sources=sources,
        constants=c,
        joints=_flat_joints,
    )


def test_labelled_batches_give_every_row_with_positions_a_success_column():
    split = _labelled_split()
    sources = [Truth(), FrozenReactor(), SwappedGeneration(), NoPositions()]
    result = _success_runner(split, sources).run({"dataset": "synthetic"})
    truth, frozen, swapped = (result.rows[n] for n in ("Ground Truth", "Frozen reactor", "Swapped"))
    assert truth["success"].mean == 1.0 and truth["success"].values == [1.0, 1.0]
    assert frozen["success"].mean == 0.0
    assert swapped["success"].mean == 1.0  # actor unknown: either person may act
    assert "success" not in result.rows["No positions"]
    assert truth["success/handshake"].mean == 1.0 and "success/hug" not in truth
    table = markdown_table(result)
    assert "Success % ↑" in table
    assert table.splitlines()[-4].endswith("| 100.0±0.0 |")  # the GT row
    assert table.splitlines()[-1].endswith("| - |")  # no positions
    # per action: each row's rate and the check its motions fail most (the share failing it,
    # the median of its signal: a frozen reactor never recoils nor walks, its hands stay low)
    actions = action_table(result).splitlines()
    assert actions[2] == "| Action | Motions | Ground Truth | Frozen reactor | Swapped |"
    assert actions[4:] == [  # 2 clips per action, 2 replications
        "| handshake | 4 | 100 | 0 (hand_gap<=hand_gap 100, median 0.59) | 100 |",
        "| push | 4 | 100 | 0 (recoil>=push_recoil 100, median 0.00) | 100 |",
        "| wave | 4 | 100 | 0 (reactor_raise>=raise_height 100, median -0.47) | 100 |",
        "| walk_meet | 4 | 100 | 0 (reactor_travel>=walked 100, median 0.00) | 100 |",
    ]
    assert frozen["fails/handshake/hand_gap<=hand_gap"].mean == 1.0
    assert frozen["fails/handshake/spacing>=spacing"].mean == 0.0
    assert frozen["signal/push/recoil>=push_recoil"].mean == 0.0
    # the ground truth's hands meet: its median gap is under the threshold the frozen one misses
    assert truth["signal/handshake/hand_gap<=hand_gap"].mean < 0.31  # SuccessThresholds().hand_gap
    unlabelled = {k: v for k, v in split.items() if k != "action"}
    plain = _success_runner(unlabelled, [Truth()]).run({})
    assert "success" not in plain.rows["Ground Truth"]
    assert "Success" not in markdown_table(plain)
    assert action_table(plain) == ""


def test_the_constants_defaults_are_interhuman_s_config():
    """One owner: configs/protocol/interhuman.yaml states the constants with their sources; the
    dataclass's defaults (what code that builds it directly gets) must say the same."""
    from dataclasses import fields

    from omegaconf import OmegaConf

    from intermask.config_files import config_dir

    stated = OmegaConf.load(config_dir() / "protocol" / "interhuman.yaml")
    defaults = {f.name: f.default for f in fields(ProtocolConstants)}
    assert {k: v for k, v in stated.items() if k != "_target_"} == {
        k: v for k, v in defaults.items() if k in stated
    }
    assert defaults["mm_replications"] == 5  # the paper's (section 4), once 20 here
    assert set(defaults) - set(stated) == {"fid_reference"}  # InterGen's default, named in code
