"""The three released evaluators against the authors' evaluation wrappers: InterGen's InterCLIP
(InterHuman) and the Inter-X T2M matcher from gohar-malik/InterMask, T2M's HumanML3D matcher
from EricGuo5513/momask-codes.

    python tools/parity/evaluators.py --reference-intermask PATH --reference-momask PATH
        [--write-fixture] [--case interclip|interx|humanml3d ...]

Per evaluator: the authors' networks (paper sizes) get seeded random weights, which are written
in the release's file layout (``interclip.ckpt``; ``finest.tar`` + GloVe files + ``meta/``).
Their wrapper loads that file itself (their ``build_models``, from the release's folder) and
embeds a batch made by their own dataset code (``__getitem__`` and collate: padding, sorting,
tokens) from fixed raw motions and captions; this framework loads the same files through
``load_evaluator`` (strict) and embeds the same raw inputs on the path ``intermask evaluate``
takes (ground-truth row, the protocol's encode calls). Printed: every release key and whether
it was loaded or dropped (and why), the tensor handed to each encoder on both sides, and the
max abs difference of the text and motion embeddings (goal <= 1e-5, fp32, CPU).
``--write-fixture`` stores ``tests/parity/fixtures/evaluator_<case>.pt``, which
``tests/parity/test_parity_evaluators.py`` checks without the authors' code.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import types
from argparse import Namespace
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
from test_parity_evaluators import (  # noqa: E402
    INTERCLIP_FILE,
    SINUSOID,
    STAGES,
    T2M_TREES,
    TOLERANCE,
    capture,
    external_keys,
    glove_table,
    key_report,
    load_release,
    our_outputs,
    stage_differences,
    their_stages,
    write_release,
)

SEED = 20261129
LATENT_SCALE = 3.5  # InterCLIP's learned scale: a positive value of a trained model's size
INTERMASK_MARKER = "models/evaluator/evaluator_interx.py"
MOMASK_MARKER = "models/t2m_eval_wrapper.py"
INTERGEN_MARKER = "datasets/evaluator_models.py"
CLIP_VOCABULARY, CLIP_CONTEXT, CLIP_WIDTH = 49408, 77, 768  # ViT-L/14@336px text embeddings

# ---------------------------------------------------------------------------- fixed inputs
INTERHUMAN_CAPTIONS = [
    "Two people shake hands and then step back.",
    "One person pushes the other, who stumbles backward and then regains balance.",
    "The first person raises the left hand while the second walks around them clockwise.",
    "Both people walk toward each other, stop, bow politely, and then the first person "
    "offers a hand which the second person takes; they dance in a slow circle, spin twice, "
    "release their hands, step apart, wave goodbye, turn around, and walk away in opposite "
    "directions until they are far apart from each other on the wide stage.",  # > 77 tokens
]
INTERHUMAN_LENGTHS = [24, 17, 9, 17]  # a tie: their argsort order among equals is kept
INTERX_TEXT = [
    ("Two people shake hands.", "two/NUM people/NOUN shake/VERB hand/NOUN"),
    (
        "The first person walks up to the second person from behind and taps the left "
        "shoulder, and the second person turns around and waves back.",
        "the/DET first/ADJ person/NOUN walk/VERB up/ADP to/ADP the/DET second/ADJ "
        "person/NOUN from/ADP behind/ADV and/CCONJ tap/VERB the/DET left/ADJ shoulder/NOUN "
        "and/CCONJ the/DET second/ADJ person/NOUN turn/VERB around/ADV and/CCONJ wave/VERB "
        "back/ADV",
    ),  # 25 tokens: more than T2M's 20, fewer than InterMask's 35
    (
        "The first person raises both arms and hugs the second person tightly, the second "
        "person pats the back of the first person twice with the right hand, and then both "
        "of them step back slowly and smile at each other.",
        "the/DET first/ADJ person/NOUN raise/VERB both/DET arm/NOUN and/CCONJ hug/VERB "
        "the/DET second/ADJ person/NOUN tightly/ADV the/DET second/ADJ person/NOUN pat/VERB "
        "the/DET back/NOUN of/ADP the/DET first/ADJ person/NOUN twice/ADV with/ADP the/DET "
        "right/ADJ hand/NOUN and/CCONJ then/ADV both/DET of/ADP they/PRON step/VERB back/ADV "
        "slowly/ADV and/CCONJ smile/VERB at/ADP each/DET other/ADJ",
    ),  # 41 tokens: cropped at 35
    ("Jack kicks at the other one.", "Jack/PROPN kick/VERB at/ADP the/DET other/ADJ one/NUM"),
]
INTERX_LENGTHS = [28, 16, 24, 16]  # multiples of 4 (their loader crops to them)
HUMANML3D_TEXT = [
    ("a person walks forward slowly.", "a/DET person/NOUN walk/VERB forward/ADV slowly/ADV"),
    (
        "a person steps forward with the left foot, raises both arms above the head, then "
        "turns around and jumps twice before sitting down on the chair.",
        "a/DET person/NOUN step/VERB forward/ADV with/ADP the/DET left/ADJ foot/NOUN "
        "raise/VERB both/DET arm/NOUN above/ADP the/DET head/NOUN then/ADV turn/VERB "
        "around/ADV and/CCONJ jump/VERB twice/ADV before/ADP sit/VERB down/ADP on/ADP "
        "the/DET chair/NOUN",
    ),  # 26 tokens: cropped at 20
    (
        "someone kicks with the right leg.",
        "someone/PRON kick/VERB with/ADP the/DET right/ADJ leg/NOUN",
    ),
    (
        "the man waves his hand in greeting",
        "the/DET man/NOUN wave/VERB his/PRON hand/NOUN in/ADP greeting/NOUN",
    ),
]
HUMANML3D_LENGTHS = [40, 24, 32, 24]
MISSING_WORDS = {"tap", "tightly", "greeting", "Jack"}  # not in the fake GloVe: unk/OTHER


def _normal(seed: int, shape: tuple[int, ...], scale: float = 1.0) -> np.ndarray:
    return (np.random.RandomState(seed).standard_normal(shape) * scale).astype(np.float32)


def _zero_beyond(raw: np.ndarray, lengths: Sequence[int], time_axis: int) -> torch.Tensor:
    raw = raw.copy()
    for row, length in enumerate(lengths):
        index = [row] + [slice(None)] * (raw.ndim - 1)
        index[time_axis] = slice(length, None)
        raw[tuple(index)] = 0.0
    return torch.from_numpy(raw)


def interhuman_inputs() -> dict[str, Any]:
    frames = max(INTERHUMAN_LENGTHS)
    raw = _normal(SEED + 1, (4, 2, frames, 262))
    raw[..., -4:] = (raw[..., -4:] > 0).astype(np.float32)  # foot contacts are 0/1
    return {
        "kind": "interhuman",
        "raw": _zero_beyond(raw, INTERHUMAN_LENGTHS, 2),  # (B, 2, T, 262) de-normalized
        "lengths": torch.tensor(INTERHUMAN_LENGTHS),
        "captions": INTERHUMAN_CAPTIONS,
        "dataset_mean": torch.from_numpy(_normal(SEED + 2, (262,), 0.5)),
        "dataset_std": torch.from_numpy(np.random.RandomState(SEED + 3).uniform(0.5, 1.5, 262)),
    }


def interx_inputs() -> dict[str, Any]:
    frames = max(INTERX_LENGTHS)
    raw = _normal(SEED + 4, (4, frames, 56, 6), 0.6)  # axis-angle rows, [P1 3 | P2 3]
    raw[:, :, 55] = np.cumsum(_normal(SEED + 5, (4, frames, 6), 0.02), axis=1) + 0.5
    return {
        "kind": "interx",
        "raw": _zero_beyond(raw, INTERX_LENGTHS, 1),  # (B, T, 56, 6) processed release rows
        "lengths": torch.tensor(INTERX_LENGTHS),
        "captions": [c for c, _ in INTERX_TEXT],
        "tokens": [t for _, t in INTERX_TEXT],
    }


def humanml3d_inputs() -> dict[str, Any]:
    frames = max(HUMANML3D_LENGTHS)
    raw = _normal(SEED + 6, (4, frames, 263), 1.5) + 0.3
    return {
        "kind": "humanml3d",
        "raw": _zero_beyond(raw, HUMANML3D_LENGTHS, 1),  # (B, T, 263) de-normalized
        "lengths": torch.tensor(HUMANML3D_LENGTHS),
        "captions": [c for c, _ in HUMANML3D_TEXT],
        "tokens": [t for _, t in HUMANML3D_TEXT],
        "dataset_mean": torch.from_numpy(_normal(SEED + 7, (263,), 0.4)),
        "dataset_std": torch.from_numpy(np.random.RandomState(SEED + 8).uniform(0.6, 1.4, 263)),
    }


def fake_glove(prefix: str, token_strings: Sequence[str]) -> dict[str, Any]:
    """Every word of the captions but MISSING_WORDS, plus sos/eos/unk and a few unused ones;
    ``_idx.pkl`` points into a table with more rows than words, in shuffled order."""
    words = {t.rpartition("/")[0] for text in token_strings for t in text.split()}
    words = ["sos", "eos", "unk", *sorted(words - MISSING_WORDS), "jump", "ball", "chair"]
    words = list(dict.fromkeys(words))
    rows = np.random.RandomState(SEED + 9).permutation(len(words) + 5)[: len(words)]
    return {
        "prefix": prefix,
        "words": words,
        "rows": [int(r) for r in rows],
        "vectors": ((len(words) + 5, 300), 0.0, 0.4),  # a build_state recipe: GloVe-sized values
    }


def _opt_txt(options: dict[str, Any]) -> str:
    lines = [f"{k}: {v}" for k, v in options.items()]
    return (
        "\n".join(
            ["------------ Options -------------", *lines, "-------------- End ----------------"]
        )
        + "\n"
    )


def _adam_state(module: nn.Module, optimizer: type = torch.optim.Adam, **kwargs) -> dict:
    """An optimizer's state dict over ``module`` before any step: the release's entry, without
    the moments (they would only make the fixture's file bigger)."""
    return optimizer(module.parameters(), **kwargs).state_dict()


# ---------------------------------------------------------------------------- the authors' side
def _their_order(batch_captions: Sequence[str], captions: Sequence[str]) -> np.ndarray:
    """Input index of each row of their batch (their collate sorts by caption length)."""
    return np.array([list(captions).index(c) for c in batch_captions])


def _to_input_order(rows: torch.Tensor, order: np.ndarray) -> torch.Tensor:
    out = torch.empty_like(rows)
    out[torch.from_numpy(order)] = rows
    return out


def _stub_plot_script() -> None:
    """Their evaluator module imports a plotting module (for visualizations only) whose imports
    fail on numpy 2; it is never called here."""
    plot = types.ModuleType("utils.plot_script")
    plot.preprocess_plot_motion = None
    sys.modules["utils.plot_script"] = plot


class _ClipStub(nn.Module):
    """What their InterCLIP takes from ``clip.load``: the token and position embeddings (their
    values come from the release file, which their ``build_models`` loads strictly)."""

    def __init__(self) -> None:
        super().__init__()
        self.token_embedding = nn.Embedding(CLIP_VOCABULARY, CLIP_WIDTH)
        self.positional_embedding = nn.Parameter(torch.zeros(CLIP_CONTEXT, CLIP_WIDTH))
        self.dtype = torch.float32


def _tokenize(texts, context_length: int = CLIP_CONTEXT, truncate: bool = False):
    import open_clip  # OpenAI's BPE; open_clip truncates as clip.tokenize(truncate=True)

    return open_clip.tokenize(texts, context_length)


def _their_interclip_modules(origin: str) -> tuple[Any, type, Callable[[Path], Any]]:
    """(their evaluator module, their InterCLIP, their config reader) from the checkout on
    sys.path: InterMask's copy (models/evaluator/) or InterGen's original (datasets/)."""
    if origin == "intergen":
        from datasets import evaluator as their
        from datasets.evaluator_models import InterCLIP

        def read(path: Path) -> Any:  # their configs.get_config needs yacs; the same keys
            return Namespace(**{k: _yaml_value(v) for k, v in (
                line.split(": ", 1) for line in path.read_text().splitlines() if line)})  # fmt: skip

        return their, InterCLIP, read
    _stub_plot_script()
    from models.evaluator import evaluator as their
    from models.evaluator.evaluator_models import InterCLIP
    from utils.get_opt import get_opt

    return their, InterCLIP, lambda path: get_opt(str(path), "cpu", complete=False)


def _yaml_value(text: str) -> Any:
    for kind in (int, float):
        with contextlib.suppress(ValueError):
            return kind(text)
    return {"True": True, "False": False}.get(text, text)


def their_interclip(checkout: Path, root: Path, origin: str = "intermask") -> dict[str, Any]:
    """InterCLIP and its wrapper from a checkout of InterMask (``origin="intermask"``) or of
    InterGen, whose evaluator InterMask copied (``origin="intergen"``, the same release file)."""
    inputs = interhuman_inputs()
    marker = INTERGEN_MARKER if origin == "intergen" else INTERMASK_MARKER
    with common.reference_modules(checkout, marker):
        common.clip_stub(_ClipStub(), _tokenize)
        their, InterCLIP, get_config = _their_interclip_modules(origin)  # noqa: N806

        config = INTERCLIP_FILE.rsplit("/", 1)[0] + "/eval_model.yaml"
        yaml = (
            "NAME: InterCLIP\nNUM_LAYERS: 8\nNUM_HEADS: 8\nDROPOUT: 0.1\nINPUT_DIM: 258\n"
            "LATENT_DIM: 1024\nFF_SIZE: 2048\nACTIVATION: gelu\nMOTION_REP: global\n"
            "FINETUNE: False\n"
        )  # fmt: skip  (InterGen's eval_model.yaml)
        (root / config).parent.mkdir(parents=True, exist_ok=True)
        (root / config).write_text(yaml)
        cfg = get_config(root / config)
        model = InterCLIP(cfg)
        state = model.state_dict()
        recipe = common.weight_recipe(state)
        recipe["latent_scale"] = torch.tensor([LATENT_SCALE])
        pe = "motion_encoder.sequence_pos_encoder.pe"
        recipe[pe] = (SINUSOID, *state[pe].shape)
        pe_rows = state[pe][: max(INTERHUMAN_LENGTHS) + 1].clone()  # their formula's values
        extras = {  # what Lightning's ModelCheckpoint writes besides the weights (InterGen)
            "epoch": 1499,
            "global_step": 228000,
            "pytorch-lightning_version": "2.0.5",
            "loops": {"fit_loop": {"state_dict": {}, "epoch_loop.state_dict": {"_batches_that_stepped": 228000}}},
            "callbacks": {"ModelCheckpoint{'monitor': None, 'mode': 'min', 'every_n_train_steps': 0, 'every_n_epochs': 100, 'train_time_interval': None}": {"monitor": None, "best_model_score": None, "best_model_path": "", "current_score": None, "dirpath": "checkpoints/interclip/model", "best_k_models": {}, "kth_best_model_path": "", "kth_value": torch.tensor(float("inf")), "last_model_path": ""}},
            "optimizer_states": [_adam_state(model, torch.optim.AdamW, lr=1e-4, weight_decay=2e-5)],
            "lr_schedulers": [{"warmup": 10, "max_num_iters": 1500, "base_lrs": [1e-4], "last_epoch": 1500, "_step_count": 1501, "_last_lr": [1.1e-10]}],
        }  # fmt: skip
        del model
        fixture = {"case": "interclip", "seed": SEED, "recipe": recipe, "extras": extras,
                   "text_files": {config: yaml}, "inputs": inputs}  # fmt: skip
        write_release(root, fixture)
        # their build_models reads checkpoints/eval_model/... (InterMask) or eval_model/...
        with contextlib.chdir(root / "checkpoints" if origin == "intergen" else root):
            wrapper = their.EvaluatorModelWrapper(cfg, "cpu")
        raw = inputs["raw"].double().numpy()
        items = []
        for row, (caption, length) in enumerate(
            zip(inputs["captions"], INTERHUMAN_LENGTHS, strict=True)
        ):
            # their loader: de-normalized persons, zero-padded to 300 frames (float64 arrays)
            padded = np.zeros((2, 300, 262))
            padded[:, :length] = raw[row, :, :length]
            items.append((f"clip{row}", caption, padded[0], padded[1], length))
        batch = torch.utils.data.default_collate(items)
        with capture(wrapper.model, STAGES["interclip"]) as stages:
            text, motion = wrapper.get_co_embeddings(batch)
        motion_only = wrapper.get_motion_embeddings(batch)
    align = np.argsort(batch[4].data.tolist())[::-1].copy()  # as their wrapper sorts
    stages = {
        "token_ids": stages["token_ids"],  # text rows stay in input order
        "motion_input": _to_input_order(stages["motion_input"], align),
        "padding_mask": _to_input_order(stages["padding_mask"], align),
    }
    fixture["reference"] = {
        "text": _to_input_order(text, align),  # get_co_embeddings re-indexes text rows too
        "motion": _to_input_order(motion, align),
        "motion_only": _to_input_order(motion_only, align),
        "align_idx": torch.from_numpy(align),
        "stages": stages,
        "pe_rows": pe_rows,
    }
    return fixture


def _t2m_networks(module, motion_input: int) -> dict[str, nn.Module]:
    """Their three parts, in the order T2M's trainer saves them."""
    return {
        "text_encoder": module.TextEncoderBiGRUCo(word_size=300, pos_size=15, hidden_size=512,
                                                  output_size=512, device="cpu"),
        "motion_encoder": module.MotionEncoderBiGRUCo(input_size=512, hidden_size=1024,
                                                      output_size=512, device="cpu"),
        "movement_encoder": module.MovementConvEncoder(motion_input, 512, 512),
    }  # fmt: skip


def _t2m_fixture(case: str, networks: dict[str, nn.Module], inputs: dict, extra: dict) -> dict:
    state = {
        f"{part}.{k}": v for part, net in networks.items() for k, v in net.state_dict().items()
    }
    extras = {
        "opt_text_encoder": _adam_state(networks["text_encoder"], lr=1e-4),
        "opt_motion_encoder": _adam_state(networks["motion_encoder"], lr=1e-4),
        "epoch": 99,
        "iter": 24800,
    }  # T2M's TextMotionMatchTrainer.save
    tree = T2M_TREES[case]
    return {"case": case, "seed": SEED, "recipe": common.weight_recipe(state), "extras": extras,
            "inputs": inputs, "glove": fake_glove(tree["prefix"], inputs["tokens"]), **extra}  # fmt: skip


@contextlib.contextmanager
def _single_crop():
    """Their loaders shorten a third of the motions by 4 frames at random ('double'); the parity
    feeds both sides the same frames, so always 'single' (length kept: it is a multiple of 4)."""
    real = np.random.choice

    def fake(options, *args, **kwargs):
        if list(options) == ["single", "single", "double"]:
            return "single"
        return real(options, *args, **kwargs)

    with mock.patch("numpy.random.choice", fake):
        yield


def _t2m_items(dataset_class, attributes: dict, inputs: dict, motion: Callable) -> list:
    """Their dataset's ``__getitem__`` over the fixed clips, one caption each."""
    dataset = dataset_class.__new__(dataset_class)
    names = [f"clip{row}" for row in range(len(inputs["captions"]))]
    dataset.data_dict = {
        name: {"motion": motion(row), "length": length,
               "text": [{"caption": caption, "tokens": tokens.split(" ")}]}
        for row, (name, caption, tokens, length) in enumerate(
            zip(names, inputs["captions"], inputs["tokens"], inputs["lengths"].tolist(), strict=True))
    }  # fmt: skip
    dataset.name_list, dataset.pointer = names, 0
    for key, value in attributes.items():
        setattr(dataset, key, value)
    with _single_crop():
        return [dataset[row] for row in range(len(names))]


def _t2m_reference(wrapper, batch, inputs, co: Callable, only: Callable, table: np.ndarray) -> dict:
    order = _their_order(batch[2], inputs["captions"])
    with capture(wrapper, STAGES["t2m"]) as stages:
        text, motion = co()
    motion_only = only()
    align = np.argsort(batch[5].data.tolist())[::-1].copy()
    motion_rows = order[align]  # their motion rows: batch rows sorted by length
    frames = inputs["raw"].shape[1]
    vectors = stages["word_vectors"].float()
    word_rows = torch.full(vectors.shape[:2], -1, dtype=torch.int64)
    flat = torch.from_numpy(table)
    for b in range(vectors.shape[0]):
        for t in range(int(stages["cap_lens"][b])):
            match = (flat == vectors[b, t]).all(dim=1).nonzero()
            word_rows[b, t] = int(match[0]) if len(match) else -2
    return {
        "text": _to_input_order(text, motion_rows),
        "motion": _to_input_order(motion, motion_rows),
        "motion_only": _to_input_order(motion_only, motion_rows),
        "align_idx": torch.from_numpy(align),
        "movement_frames": stages["movement_input"].shape[1],  # their padded length
        "stages": {
            # up to 4 frames past the longest motion: the zero frames the last step reads
            "movement_input": _to_input_order(
                stages["movement_input"][:, : frames + 4], motion_rows
            ),
            "steps": _to_input_order(stages["steps"], motion_rows),
            "word_rows": _to_input_order(word_rows, order),  # rows of <prefix>_data.npy
            "pos_one_hot": _to_input_order(stages["pos_one_hot"].float(), order),
            "cap_lens": _to_input_order(torch.as_tensor(stages["cap_lens"]), order),
        },
    }


def their_interx(checkout: Path, root: Path) -> dict[str, Any]:
    inputs = interx_inputs()
    tree = T2M_TREES["interx"]
    opt_path = "checkpoints/hhi/Comp_v6_KLD01/opt.txt"  # eval.py's wrapper options
    opt_text = _opt_txt({"name": "Comp_v6_KLD01", "dataset_name": "hhi", "checkpoints_dir":
                         "./checkpoints", "dim_movement_enc_hidden": 512, "dim_movement_latent":
                         512, "unit_length": 4})  # fmt: skip
    with common.reference_modules(checkout, INTERMASK_MARKER):
        from data.interx import Text2MotionDatasetV2HHI, collate_fn
        from models.evaluator import evaluator_interx as their
        from utils.get_opt import get_opt
        from utils.word_vectorizer import WordVectorizer

        networks = _t2m_networks(their, 56 * 12)
        fixture = _t2m_fixture("interx", networks, inputs, {"text_files": {opt_path: opt_text}})
        write_release(root, fixture)
        with contextlib.chdir(root):
            wrapper = their.EvaluatorModelWrapper(get_opt(opt_path, "cpu", complete=False))
        attributes = {  # eval.py's Inter-X options: max_text_len 35, unit_length 4, smpl rows
            "opt": Namespace(max_text_len=35, unit_length=4),
            "motion_rep": "smpl",
            "max_motion_length": 150,
            "num_person": 2,
            "w_vectorizer": WordVectorizer(str(root / tree["glove"]), tree["prefix"]),
        }
        raw = inputs["raw"].numpy()
        lengths = inputs["lengths"].tolist()
        items = _t2m_items(Text2MotionDatasetV2HHI, attributes, inputs,
                           lambda row: raw[row, : lengths[row]].copy())  # fmt: skip
        batch = collate_fn(items)
        table = glove_table(fixture["glove"], SEED)
        fixture["reference"] = _t2m_reference(
            wrapper, batch, inputs, lambda: wrapper.get_co_embeddings(batch),
            lambda: wrapper.get_motion_embeddings(batch), table,
        )  # fmt: skip
    return fixture


def their_humanml3d(checkout: Path, root: Path) -> dict[str, Any]:
    inputs = humanml3d_inputs()
    tree = T2M_TREES["humanml3d"]
    opt_path = "checkpoints/t2m/Comp_v6_KLD005/opt.txt"  # MoMask's dataset_opt_path
    opt_text = _opt_txt({"name": "Comp_v6_KLD005", "dataset_name": "t2m", "checkpoints_dir":
                         "./checkpoints", "dim_movement_enc_hidden": 512, "dim_movement_latent":
                         512, "unit_length": 4})  # fmt: skip
    meta = {"mean": torch.from_numpy(_normal(SEED + 10, (263,), 0.5)),
            "std": torch.from_numpy(np.random.RandomState(SEED + 11).uniform(0.3, 1.2, 263).astype(np.float32))}  # fmt: skip
    with common.reference_modules(checkout, MOMASK_MARKER):
        from data.t2m_dataset import Text2MotionDatasetEval, collate_fn
        from models import t2m_eval_wrapper as their
        from utils.get_opt import get_opt
        from utils.word_vectorizer import WordVectorizer

        networks = _t2m_networks(their, 263 - 4)
        fixture = _t2m_fixture("humanml3d", networks, inputs,
                               {"text_files": {opt_path: opt_text}, "meta": meta})  # fmt: skip
        write_release(root, fixture)
        with contextlib.chdir(root):
            opt = get_opt(opt_path, "cpu")
            wrapper = their.EvaluatorModelWrapper(opt)
            mean, std = np.load(f"{opt.meta_dir}/mean.npy"), np.load(f"{opt.meta_dir}/std.npy")
        attributes = {  # their dataset_motion_loader: the evaluator's meta statistics
            "opt": Namespace(max_text_len=20, unit_length=4),
            "max_motion_length": 196,
            "mean": mean,
            "std": std,
            "w_vectorizer": WordVectorizer(str(root / tree["glove"]), tree["prefix"]),
        }
        raw = inputs["raw"].numpy()
        lengths = inputs["lengths"].tolist()
        items = _t2m_items(Text2MotionDatasetEval, attributes, inputs,
                           lambda row: raw[row, : lengths[row]].copy())  # fmt: skip
        batch = collate_fn(items)
        words, pos, _, sent_len, motion, m_length, _ = batch
        table = glove_table(fixture["glove"], SEED)
        fixture["reference"] = _t2m_reference(
            wrapper, batch, inputs,
            lambda: wrapper.get_co_embeddings(words, pos, sent_len, motion, m_length),
            lambda: wrapper.get_motion_embeddings(motion, m_length), table,
        )  # fmt: skip
    return fixture


# ---------------------------------------------------------------------------- report
def report(fixture: dict[str, Any], root: Path) -> dict[str, float]:
    """Load the fixture's release (rebuilt under ``root``) as a user would, run our path,
    print the key report and the stage / embedding differences; -> the figures."""
    case = fixture["case"]
    path, evaluator = load_release(root, fixture)
    print(
        f"\n=== {case}: {path.relative_to(root)} -> {evaluator.name} (sha256 {evaluator.file_hash})"
    )
    print("release keys:")
    for key, status, detail in key_report(path, evaluator):
        print(f"  {key:<58} {status:<10} {detail}")
    for key, source in external_keys(evaluator, path).items():
        print(f"  (ours) {key:<51} {'external':<10} {source}")
    ours = our_outputs(evaluator, fixture)
    reference = fixture["reference"]
    theirs = their_stages(fixture)
    print("preprocessing: the tensor each encoder receives (padding compared where it is read)")
    for name, (difference, shapes) in stage_differences(
        case, ours["stages"], theirs, fixture["inputs"]["lengths"]
    ).items():
        print(f"  {name:<16} max abs diff {difference:.3g}  ({shapes})")
    if "movement_frames" in reference:
        print(
            f"  (their movement input is {reference['movement_frames']} frames long: stored up "
            "to 4 frames past the longest motion, the rest is zero frames)"
        )
    figures = {
        "text": common.max_abs(ours["text"], reference["text"]),
        "motion (get_co_embeddings)": common.max_abs(ours["motion"], reference["motion"]),
        "motion (get_motion_embeddings)": common.max_abs(ours["motion"], reference["motion_only"]),
    }
    print(f"embeddings (largest |value| {float(reference['motion'].abs().max()):.3f}):")
    for name, value in figures.items():
        verdict = "ok" if value <= TOLERANCE else "OVER THE GOAL"
        print(f"  {name:<32} max abs diff {value:.3g}  [goal <= {TOLERANCE:g}: {verdict}]")
    return figures


def _commit(checkout: Path) -> str:
    try:
        return subprocess.run(["git", "-C", str(checkout), "rev-parse", "HEAD"], check=True,
                              capture_output=True, text=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument(
        "--reference-intermask",
        type=Path,
        required=True,
        help=f"a checkout of gohar-malik/InterMask (it holds {INTERMASK_MARKER})",
    )
    cli.add_argument(
        "--reference-momask",
        type=Path,
        required=True,
        help=f"a checkout of EricGuo5513/momask-codes (it holds {MOMASK_MARKER})",
    )
    cli.add_argument(
        "--reference-intergen",
        type=Path,
        help="also InterCLIP from a checkout of tr3e/InterGen, where InterMask's copy comes "
        f"from (it holds {INTERGEN_MARKER}); printed, no fixture",
    )
    cli.add_argument(
        "--write-fixture",
        action="store_true",
        help="also (re)write tests/parity/fixtures/evaluator_<case>.pt",
    )
    cli.add_argument("--case", action="append", choices=("interclip", "interx", "humanml3d"),
                     help="only these evaluators (default: all three)")  # fmt: skip
    args = cli.parse_args()
    torch.set_grad_enabled(False)
    runs = {
        "interclip": (their_interclip, args.reference_intermask),
        "interx": (their_interx, args.reference_intermask),
        "humanml3d": (their_humanml3d, args.reference_momask),
    }
    worst = 0.0
    for case in args.case or list(runs):
        run, checkout = runs[case]
        with tempfile.TemporaryDirectory() as theirs, tempfile.TemporaryDirectory() as ours:
            fixture = run(checkout.resolve(), Path(theirs))
            fixture["reference_commit"] = _commit(checkout)
            worst = max(worst, *report(fixture, Path(ours)).values())
        if args.write_fixture:
            path = common.save_fixture(f"evaluator_{case}", fixture)
            print(f"wrote {path.relative_to(common.REPO)} ({path.stat().st_size} bytes)")
        del fixture
    if args.reference_intergen is not None:
        print("InterCLIP from InterGen (the original of InterMask's copy):")
        with tempfile.TemporaryDirectory() as theirs, tempfile.TemporaryDirectory() as ours:
            fixture = their_interclip(args.reference_intergen.resolve(), Path(theirs), "intergen")
            fixture["reference_commit"] = _commit(args.reference_intergen)
            worst = max(worst, *report(fixture, Path(ours)).values())
    return 0 if worst <= TOLERANCE else 1


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "2")
    sys.exit(main())
