"""The three released evaluators, loaded by ``load_evaluator`` and run on the path ``intermask
evaluate`` takes, give what the authors' evaluation wrappers gave (fixtures
``tests/parity/fixtures/evaluator_{interclip,interx,humanml3d}.pt``, written by
``tools/parity/evaluators.py --write-fixture`` against gohar-malik/InterMask and
EricGuo5513/momask-codes).

A fixture holds the recipe of the release's weights (full paper sizes: the files are the
release's layout), the non-weight entries of the file, fake GloVe words and statistics, the raw
inputs, and the authors' outputs in input order: embeddings from ``get_co_embeddings`` and
``get_motion_embeddings``, and the tensors their wrapper handed to each encoder. Here the
release tree is rebuilt on disk, loaded as a user would (strict), and the batch goes through
the ground-truth row and the protocol's two encode calls. Without the authors' code.

The helpers above the tests are shared with the script (it imports this module).
"""

from __future__ import annotations

import contextlib
import operator
import pickle
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from fixtures_io import build_state, load_fixture

from intermask.data.normalization import Normalizer
from intermask.evaluation.protocol import ProtocolConstants, ProtocolRunner
from intermask.evaluation.sources import GroundTruth
from intermask.evaluator import FrozenEvaluator, load_evaluator
from intermask.evaluator.checkpoints import INTERCLIP_PREFIX, T2M_PARTS
from intermask.evaluator.interclip import PositionalEncoding
from intermask.motion.masks import length_mask

TOLERANCE = 1e-5  # fp32 on CPU, as the issue asks
CASES = ("interclip", "interx", "humanml3d")
SINUSOID = (
    "sinusoid"  # recipe marker: InterCLIP's position-encoding buffer is a formula, not a weight
)

# where each release keeps its files, relative to the folder the authors' code runs from
INTERCLIP_FILE = "checkpoints/eval_model/interclip.ckpt"
T2M_TREES = {
    "interx": {  # InterMask's Inter-X evaluator (models/evaluator/evaluator_interx.py)
        "finest": "checkpoints/hhi/text_mot_match/model/finest.tar",
        "glove": "data/InterX/glove",
        "prefix": "hhi_vab",
        "meta": None,
    },
    "humanml3d": {  # T2M's matcher as MoMask's evaluator zip lays it out
        "finest": "checkpoints/t2m/text_mot_match/model/finest.tar",
        "glove": "glove",
        "prefix": "our_vab",
        "meta": "checkpoints/t2m/Comp_v6_KLD005/meta",
    },
}

# Entries of a release file that are not weights, and why loading leaves them out.
DROPPED = {
    "epoch": "training counter",
    "global_step": "Lightning training counter",
    "pytorch-lightning_version": "Lightning metadata",
    "loops": "Lightning loop progress (resuming training only)",
    "callbacks": "Lightning ModelCheckpoint bookkeeping",
    "optimizer_states": "AdamW state (resuming training only)",
    "lr_schedulers": "learning-rate schedule state (resuming training only)",
    "opt_text_encoder": "Adam state of the text encoder (resuming training only)",
    "opt_motion_encoder": "Adam state of the motion encoder (resuming training only)",
    "iter": "T2M training counter",
}

# The tensor each side hands to an encoder: name -> (module path, positional index or keyword).
# The module paths are the same in the authors' networks and ours (names follow the release).
STAGES = {
    "interclip": {
        "token_ids": ("token_embedding", 0),
        "motion_input": ("motion_encoder.embed_motion", 0),
        "padding_mask": ("motion_encoder.transformer", "src_key_padding_mask"),
    },
    "t2m": {
        "movement_input": ("movement_encoder", 0),
        "steps": ("motion_encoder", 1),
        "word_vectors": ("text_encoder", 0),
        "pos_one_hot": ("text_encoder", 1),
        "cap_lens": ("text_encoder", 2),
    },
}


def stage_names(case: str) -> dict[str, tuple[str, int | str]]:
    return STAGES["interclip" if case == "interclip" else "t2m"]


# ---------------------------------------------------------------------------- release files
def sinusoid(max_len: int, dim: int) -> torch.Tensor:
    return PositionalEncoding(dim=dim, max_len=max_len, dropout=0.0).pe.clone()


def release_state(recipe: Mapping[str, Any], seed: int) -> dict[str, torch.Tensor]:
    """The release's tensors, in the release's key order: seeded draws, and the sinusoid."""
    drawn = build_state(
        {k: v for k, v in recipe.items() if not (isinstance(v, tuple) and v[0] == SINUSOID)},
        seed=seed,
    )
    state = {}
    for key, entry in recipe.items():
        state[key] = (
            sinusoid(*entry[1:])
            if isinstance(entry, tuple) and entry[0] == SINUSOID
            else drawn[key]
        )
    return state


def glove_table(glove: Mapping[str, Any], seed: int) -> np.ndarray:
    """(rows, 300) float32 rows of ``<prefix>_data.npy``."""
    return build_state({"glove": glove["vectors"]}, seed=seed)["glove"].numpy()


def write_glove(folder: Path, glove: Mapping[str, Any], seed: int) -> None:
    """``<prefix>_data.npy``, ``_words.pkl`` (list) and ``_idx.pkl`` (dict word -> row), pickled
    as plain containers as T2M's ``WordVectorizer`` reads them."""
    folder.mkdir(parents=True, exist_ok=True)
    prefix = glove["prefix"]
    np.save(folder / f"{prefix}_data.npy", glove_table(glove, seed))
    (folder / f"{prefix}_words.pkl").write_bytes(pickle.dumps(list(glove["words"])))
    index = dict(zip(glove["words"], (int(r) for r in glove["rows"]), strict=True))
    (folder / f"{prefix}_idx.pkl").write_bytes(pickle.dumps(index))


def write_release(root: Path, fixture: Mapping[str, Any]) -> Path:
    """The release tree of ``fixture`` under ``root``; -> the checkpoint file."""
    state = release_state(fixture["recipe"], fixture["seed"])
    for relative, text in fixture.get("text_files", {}).items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_text(text)
    if fixture["case"] == "interclip":
        path = root / INTERCLIP_FILE
        path.parent.mkdir(parents=True, exist_ok=True)
        extras = dict(fixture["extras"])
        checkpoint = {
            k: extras.pop(k) for k in ("epoch", "global_step", "pytorch-lightning_version")
        }
        checkpoint["state_dict"] = {INTERCLIP_PREFIX + k: v for k, v in state.items()}
        torch.save({**checkpoint, **extras}, path)
        return path
    tree = T2M_TREES[fixture["case"]]
    parts: dict[str, dict[str, torch.Tensor]] = {}
    for name, tensor in state.items():
        part, key = name.split(".", 1)
        parts.setdefault(part, {})[key] = tensor
    path = root / tree["finest"]
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({**parts, **fixture["extras"]}, path)
    write_glove(root / tree["glove"], fixture["glove"], fixture["seed"])
    if tree["meta"] is not None:
        meta = root / tree["meta"]
        meta.mkdir(parents=True, exist_ok=True)
        np.save(meta / "mean.npy", fixture["meta"]["mean"].numpy())
        np.save(meta / "std.npy", fixture["meta"]["std"].numpy())
    return path


def load_release(root: Path, fixture: Mapping[str, Any]) -> tuple[Path, FrozenEvaluator]:
    """Rebuild the release and load it as a user would: the file, and GloVe where needed."""
    path = write_release(root, fixture)
    if fixture["case"] == "interclip":
        return path, load_evaluator(path)
    return path, load_evaluator(path, glove_dir=root / T2M_TREES[fixture["case"]]["glove"])


def key_report(path: Path, evaluator: FrozenEvaluator) -> list[tuple[str, str, str]]:
    """Every entry of the release file: (key, "loaded" | "dropped" | "NOT LOADED", where / why).
    A tensor counts as loaded when our network holds exactly it under the mapped name."""
    checkpoint = torch.load(path, map_location="cpu", weights_only=True)
    own = evaluator.net.state_dict()
    if "state_dict" in checkpoint:
        tensors = {
            f"state_dict/{k}": (k.removeprefix(INTERCLIP_PREFIX), v)
            for k, v in checkpoint["state_dict"].items()
        }
        others = [k for k in checkpoint if k != "state_dict"]
    else:
        tensors = {
            f"{part}/{k}": (f"{part}.{k}", v)
            for part in T2M_PARTS
            for k, v in checkpoint[part].items()
        }
        others = [k for k in checkpoint if k not in T2M_PARTS]
    rows = []
    for name, (ours, value) in tensors.items():
        if ours in own and own[ours].shape == value.shape and torch.equal(own[ours], value):
            rows.append((name, "loaded", f"net.{ours} {tuple(value.shape)}"))
        else:
            rows.append((name, "NOT LOADED", f"net.{ours}: absent or different"))
    for key in others:
        rows.append((key, "dropped", DROPPED.get(key, "UNKNOWN entry: nobody reads it")))
    return rows


def external_keys(evaluator: FrozenEvaluator, path: Path) -> dict[str, str]:
    """Our network's tensors that do not come from the release file, and where they come from."""
    state = torch.load(path, map_location="cpu", weights_only=True)
    if "state_dict" in state:
        filed = {k.removeprefix(INTERCLIP_PREFIX) for k in state["state_dict"]}
    else:
        filed = {f"{part}.{k}" for part in T2M_PARTS for k in state[part]}
    sources = {
        "word_embedding.weight": "GloVe <prefix>_data.npy rows, ordered by <prefix>_words.pkl/_idx.pkl",
        "mean": "meta/mean.npy",
        "std": "meta/std.npy",
        "has_statistics": "set when meta/ is read",
    }
    return {k: sources.get(k, "UNACCOUNTED") for k in evaluator.net.state_dict() if k not in filed}


# ---------------------------------------------------------------------------- our path
def our_batch(inputs: Mapping[str, Any]) -> tuple[dict[str, Any], Normalizer | None]:
    """The eval batch our datamodules give for the raw inputs: InterHuman and HumanML3D z-scored
    with the dataset's statistics and zero-padded in that space; Inter-X the raw 6D
    representation, per person (not normalized, as the reference trains on it)."""
    raw, lengths = inputs["raw"], inputs["lengths"]
    normalizer = None
    if "dataset_mean" in inputs:
        normalizer = Normalizer(inputs["dataset_mean"], inputs["dataset_std"], source="fixture")
    if inputs["kind"] == "interx":
        from intermask.data.interx import person_features

        motion = torch.zeros(raw.shape[0], 2, raw.shape[1], 56, 6)
        for row, length in enumerate(lengths.tolist()):
            motion[row, :, :length] = person_features(raw[row, :length])
    else:
        time_axis = 2 if inputs["kind"] == "interhuman" else 1
        valid = length_mask(lengths, raw.shape[time_axis])
        valid = valid[:, None, :, None] if time_axis == 2 else valid[:, :, None]
        motion = torch.where(valid, normalizer.normalize(raw), 0.0)
    batch = {"motion": motion, "length": lengths, "caption": list(inputs["captions"])}
    if "tokens" in inputs:
        batch["tokens"] = list(inputs["tokens"])
    return batch, normalizer


@contextlib.contextmanager
def capture(root: Any, stages: Mapping[str, tuple[str, int | str]]) -> Iterator[dict[str, Any]]:
    """What each module of ``stages`` receives on its first call (forward pre-hooks)."""
    seen: dict[str, Any] = {}
    handles = []
    for name, (module_path, which) in stages.items():

        def hook(module, args, kwargs, name=name, which=which):
            if name not in seen:
                value = kwargs.get(which) if isinstance(which, str) else args[which]
                seen[name] = value.detach().clone() if isinstance(value, torch.Tensor) else value

        module = operator.attrgetter(module_path)(root)
        handles.append(module.register_forward_pre_hook(hook, with_kwargs=True))
    try:
        yield seen
    finally:
        for handle in handles:
            handle.remove()


def our_outputs(evaluator: FrozenEvaluator, fixture: Mapping[str, Any]) -> dict[str, Any]:
    """Text and motion embeddings (input order) through the ground-truth row and the protocol's
    encode calls, and the tensors our network handed to its encoders."""
    batch, normalizer = our_batch(fixture["inputs"])
    truth = GroundTruth(normalizer=normalizer)
    runner = ProtocolRunner(
        loader=lambda epoch: [],
        evaluator=evaluator,
        ground_truth=truth,
        sources=[truth],
        constants=ProtocolConstants(),
    )
    seeds = torch.zeros(len(batch["caption"]), dtype=torch.int64)
    with capture(evaluator.net, stage_names(fixture["case"])) as stages:
        text = runner._text_embeddings(batch)
        motion = runner._motion_embeddings(truth, batch, seeds)
    return {"text": text, "motion": motion, "stages": stages}


def their_stages(fixture: Mapping[str, Any]) -> dict[str, torch.Tensor]:
    """The authors' stage tensors; their word vectors come back from the GloVe rows the fixture
    names (NaN where a vector matched no row, or past a caption's end)."""
    stages = dict(fixture["reference"]["stages"])
    if "word_rows" in stages:
        rows = stages.pop("word_rows")
        table = torch.from_numpy(glove_table(fixture["glove"], fixture["seed"]))
        vectors = table[rows.clamp_min(0)]
        stages["word_vectors"] = torch.where((rows >= 0)[..., None], vectors, torch.nan)
    return stages


def stage_differences(
    case: str, ours: Mapping[str, Any], theirs: Mapping[str, Any], lengths: torch.Tensor
) -> dict[str, tuple[float, str]]:
    """Per stage: max abs difference on what the encoder reads, and the shapes compared."""
    out: dict[str, tuple[float, str]] = {}
    for name in stage_names(case):
        a, b = ours[name], theirs[name]
        shapes = f"ours {tuple(a.shape)} vs theirs {tuple(b.shape)}"
        if name in ("motion_input", "movement_input"):
            frames = min(a.shape[1], b.shape[1])
            a, b = a[:, :frames], b[:, :frames]
            if name == "motion_input":  # padded frames are masked out: compare valid ones
                valid = length_mask(lengths, frames)[:, :, None]
                a, b = torch.where(valid, a, 0.0), torch.where(valid, b, 0.0)
        elif name in ("word_vectors", "pos_one_hot"):
            tokens = min(a.shape[1], b.shape[1])
            valid = length_mask(ours["cap_lens"].cpu(), tokens)[:, :, None]
            if int(ours["cap_lens"].max()) > tokens or int(theirs["cap_lens"].max()) > tokens:
                out[name] = (float("inf"), shapes + " (fewer tokens than the lengths)")
                continue
            a, b = torch.where(valid, a[:, :tokens], 0.0), torch.where(valid, b[:, :tokens], 0.0)
        if a.shape != b.shape:
            out[name] = (float("inf"), shapes)
            continue
        out[name] = (float((a.double() - b.double()).abs().max()), shapes)
    return out


# ---------------------------------------------------------------------------- tests
@pytest.fixture(scope="module", params=CASES)
def loaded(request, tmp_path_factory) -> dict[str, Any]:
    torch.set_num_threads(min(torch.get_num_threads(), 2))
    fixture = load_fixture(f"evaluator_{request.param}")
    path, evaluator = load_release(tmp_path_factory.mktemp(request.param), fixture)
    return {"fixture": fixture, "path": path, "evaluator": evaluator}


def test_every_release_key_is_loaded_or_dropped_for_a_reason(loaded):
    fixture, path, evaluator = loaded["fixture"], loaded["path"], loaded["evaluator"]
    rows = key_report(path, evaluator)
    assert [r for r in rows if r[1] == "NOT LOADED"] == []
    dropped = {key: why for key, status, why in rows if status == "dropped"}
    assert dropped == {k: DROPPED[k] for k in fixture["extras"]}
    assert sum(status == "loaded" for _, status, _ in rows) == len(fixture["recipe"])
    external = external_keys(evaluator, path)
    expected = {
        "interclip": set(),
        "interx": {"word_embedding.weight"},
        "humanml3d": {"word_embedding.weight", "mean", "std", "has_statistics"},
    }[fixture["case"]]
    assert set(external) == expected and "UNACCOUNTED" not in external.values()
    net = evaluator.net
    if fixture["case"] != "interclip":  # the GloVe rows in our vocabulary's order
        glove = fixture["glove"]
        table = glove_table(glove, fixture["seed"])
        rows_of = dict(zip(glove["words"], glove["rows"], strict=True))
        expected_rows = torch.from_numpy(table[[rows_of[w] for w in net.vocabulary.words]])
        assert torch.equal(net.word_embedding.weight, expected_rows)
    if fixture["case"] != "interclip":  # InterMask's max_text_len 35, T2M's and MoMask's 20
        assert net.max_words == {"interx": 35, "humanml3d": 20}[fixture["case"]]
    if fixture["case"] == "humanml3d":  # read from MoMask's Comp_v6_KLD005/meta, no meta_dir
        assert torch.equal(net.mean, fixture["meta"]["mean"])
        assert torch.equal(net.std, fixture["meta"]["std"])


@pytest.mark.parametrize("loaded", ["interclip"], indirect=True)
def test_the_release_holds_the_authors_position_encoding(loaded):
    """The file's sinusoid is rebuilt here with our formula: it must be theirs."""
    pe = loaded["evaluator"].net.motion_encoder.sequence_pos_encoder.pe
    reference = loaded["fixture"]["reference"]["pe_rows"]
    torch.testing.assert_close(pe[: len(reference)], reference, rtol=0, atol=1e-6)


def test_embeddings_match_the_authors_wrapper(loaded):
    fixture = loaded["fixture"]
    ours = our_outputs(loaded["evaluator"], fixture)
    reference = fixture["reference"]
    torch.testing.assert_close(ours["text"], reference["text"], rtol=0, atol=TOLERANCE)
    torch.testing.assert_close(ours["motion"], reference["motion"], rtol=0, atol=TOLERANCE)
    torch.testing.assert_close(ours["motion"], reference["motion_only"], rtol=0, atol=TOLERANCE)
    # a tolerance that means something: the embeddings are O(0.1) and differ between rows
    assert float(reference["motion"].abs().max()) > 0.1
    assert float(torch.cdist(reference["text"], reference["text"]).triu(1).max()) > 0.1


def test_each_encoder_receives_what_the_authors_wrapper_hands_it(loaded):
    fixture = loaded["fixture"]
    ours = our_outputs(loaded["evaluator"], fixture)["stages"]
    lengths = fixture["inputs"]["lengths"]
    differences = stage_differences(fixture["case"], ours, their_stages(fixture), lengths)
    assert {k: v for k, v in differences.items() if not v[0] <= TOLERANCE} == {}
    if "movement_frames" in fixture["reference"]:  # padded to their max_motion_length
        assert ours["movement_input"].shape[1] == fixture["reference"]["movement_frames"]


@pytest.mark.parametrize("dataset", ["interx", "humanml3d"])
def test_a_motion_that_fills_the_tensor_embeds_as_if_padded_to_the_reference_length(dataset):
    """What the Inter-X fixture first exposed: the reference pads every motion with zero frames
    to max_motion_length, so the last movement step of a motion that fills the tensor must read
    the first convolution of zero frames, not the second convolution's padding."""
    from intermask.evaluator import GRUMatcher, HumanML3DMatcher

    torch.manual_seed(0)
    sizes = dict(
        word_dim=12, movement_hidden=16, movement_latent=16, motion_hidden=20, text_hidden=18
    )
    words = ["sos", "eos", "unk"]
    if dataset == "interx":
        net, motion, time = GRUMatcher(vocabulary=words, **sizes), torch.randn(2, 2, 24, 56, 6), 2
    else:
        statistics = {"mean": torch.zeros(263), "std": torch.ones(263)}
        net = HumanML3DMatcher(vocabulary=words, **statistics, **sizes)
        motion, time = torch.randn(2, 24, 263), 1
    assert net.max_frames == {"interx": 150, "humanml3d": 196}[dataset]  # max_motion_length
    net.eval()
    lengths = torch.tensor([24, 16])  # the first one fills the tensor
    with torch.no_grad():
        filled = net.encode_motion(motion, lengths)
        padded = net.encode_motion(torch.cat([motion, torch.zeros_like(motion)], time), lengths)
        net.max_frames = 24  # what the encoder did before: no zero frames after the first motion
        unpadded = net.encode_motion(motion, lengths)
    torch.testing.assert_close(filled, padded, rtol=0, atol=1e-6)
    torch.testing.assert_close(unpadded[1], filled[1], rtol=0, atol=1e-6)
    assert float((unpadded[0] - filled[0]).abs().max()) > 1e-3
