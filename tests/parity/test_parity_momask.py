"""MoMask's release, converted by ``intermask convert-reference``'s code, gives what the authors'
code gave (tests/parity/fixtures/momask_models.pt, written by ``tools/parity/momask.py
--write-fixture`` against EricGuo5513/momask-codes).

The fixture holds each case's ``opt.txt`` options, the recipe of the release's weights, the
inputs and the authors' outputs. The release is rebuilt on disk here (``checkpoints/t2m/<name>/``
with ``opt.txt``, ``model/<which>.tar`` and the tokenizer's ``meta/``) and converted as a user's
would be, so a change anywhere on that path (opt.txt mapping, key conversion, the folded text
projection, the networks, the loaders) that breaks parity fails here without the authors' code.
The helpers below are what ``tools/parity/momask.py`` runs on our side too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from fixtures_io import build_state, load_fixture

from intermask.convert_momask import convert_momask
from intermask.evaluator.interclip import PositionalEncoding
from intermask.momask.load import LoadedMoMask, load_momask
from intermask.momask.model import sentence_features
from intermask.momask.reference import rvq_overrides, transformer_overrides
from intermask.momask.sampler import decode_base, decode_residual
from intermask.release_options import UnsupportedOption

FIXTURE = "momask_models"
LOGITS, DECODED = 1e-4, 1e-5  # the tolerances
RESIDUAL_CFG = 5.0  # the authors' residual guidance scale (gen_t2m.py)
# model -> (checkpoint entry, file) as the authors' trainers save and their loaders read them
FILES = {
    "vq": ("vq_model", "net_best_fid.tar"),
    "mask": ("t2m_transformer", "latest.tar"),
    "residual": ("res_transformer", "net_best_fid.tar"),
}
TEXT = "tiny_random"  # the seeded random CLIP-shaped tower both sides read (no download)


# ---------------------------------------------------------------------------------------------
# the release on disk


def write_opt(folder: Path, options: dict[str, str]) -> None:
    """``opt.txt`` as the authors' option parsers write it."""
    lines = ["------------ Options -------------"]
    lines += [f"{k}: {v}" for k, v in sorted(options.items())]
    (folder / "opt.txt").write_text("\n".join([*lines, "-------------- End ----------------", ""]))


def sinusoid(shape: tuple[int, ...]) -> torch.Tensor:
    """The authors' ``position_enc.pe`` buffer, (max_len, 1, D): MDM's sinusoid table."""
    return PositionalEncoding(dim=shape[-1], max_len=shape[0], dropout=0.0).pe[:, None].clone()


def model_state(spec: dict[str, Any], seed: int) -> dict[str, torch.Tensor]:
    state = build_state(spec["recipe"], seed=seed)
    if "pe" in spec:
        state["position_enc.pe"] = sinusoid(tuple(spec["pe"]))
    return state


def write_release(
    root: Path,
    case: dict[str, Any],
    seed: int,
    *,
    options: dict[str, dict[str, str]] | None = None,
    states: dict[str, dict[str, torch.Tensor]] | None = None,
) -> dict[str, Path]:
    """``root/checkpoints/t2m/<name>/{opt.txt, model/<which>.tar}`` for the case's three models
    (``options`` or ``states`` replace a model's) and the tokenizer's ``meta/{mean,std}.npy``
    -> {model: checkpoint path}."""
    paths = {}
    for model, (entry, file) in FILES.items():
        opt = (options or {}).get(model, case[model]["options"])
        folder = root / "checkpoints" / "t2m" / opt["name"]
        (folder / "model").mkdir(parents=True)
        write_opt(folder, opt)
        state = (states or {}).get(model) or model_state(case[model], seed)
        paths[model] = folder / "model" / file
        torch.save({entry: state, "ep": 7, "total_it": 1234}, paths[model])
        if model == "vq":
            (folder / "meta").mkdir()
            np.save(folder / "meta" / "mean.npy", case["meta"]["mean"].numpy())
            np.save(folder / "meta" / "std.npy", case["meta"]["std"].numpy())
    return paths


# ---------------------------------------------------------------------------------------------
# our side


class Ours:
    """The converted runs, loaded as ``intermask generate`` loads them."""

    def __init__(self, out: Path) -> None:
        self.mask: LoadedMoMask = load_momask(out / "mask")
        self.residual: LoadedMoMask = load_momask(out / "residual", vq=self.mask.vq)
        self.vq = self.mask.vq

    def text(self, captions: list[str]) -> torch.Tensor:
        """(B, D_text) sentence features, straight from the run's text encoder (no cache)."""
        return sentence_features(self.mask.text.encoder.encode(captions))


def convert(paths: dict[str, Path], out: Path) -> Ours:
    convert_momask(vq=paths["vq"], mask=paths["mask"], residual=paths["residual"], out=out,
                   text=TEXT)  # fmt: skip
    return Ours(out)


def valid_steps(lengths: torch.Tensor, steps: int) -> torch.Tensor:
    return torch.arange(steps)[None] < lengths[:, None]  # (B, T')


@torch.no_grad()
def our_outputs(ours: Ours, inputs: dict[str, Any], captions: list[str]) -> dict[str, Any]:
    """Every figure the fixture stores, from our converted networks (padding zeroed)."""
    vq, lengths = ours.vq, inputs["lengths"]
    valid = valid_steps(lengths, inputs["mask_ids"].shape[1])
    text = ours.text(captions)
    motion, codes = inputs["motion"], inputs["codes"]  # (B, T, 263), (B, Q, T')
    out: dict[str, Any] = {
        "latent": vq.encoder(vq.view.to_joints(motion))[:, :, 0],  # (B, E, T')
        "indices": vq.encode(motion)[:, :, 0],  # (B, Q, T')
        "decoded": vq.decode(codes[:, :, None]),  # (B, T, 263)
    }
    drops = {"": torch.zeros(len(lengths), dtype=torch.bool)}
    drops["null_"] = ~drops[""]
    for name, drop in drops.items():
        logits = ours.mask.net(inputs["mask_ids"], text, lengths, drop)
        out[f"mask_{name}logits"] = logits * valid[..., None]
        tokens = codes.masked_fill(~valid[:, None], -1)
        residual = [
            ours.residual.net(tokens, text, lengths, drop, layer=j) * valid[..., None]
            for j in range(1, codes.shape[1])
        ]
        out[f"residual_{name}logits"] = torch.stack(residual)  # (Q-1, B, T', K)
    base = codes[:, 0].masked_fill(~valid, -1)
    out["residual_tokens"] = decode_residual(
        ours.residual.net, base, text, lengths, cfg_scale=RESIDUAL_CFG, temperature=0.0
    )
    out["base_tokens"] = torch.stack(
        [reference_order_base(ours.mask.net, text, lengths, seed) for seed in DECODING_SEEDS]
    )  # (seeds, B, T')
    return out


MASK_CFG, ITERATIONS, TOP_K = 4.0, 10, 0.1  # the authors' HumanML3D decoding (eval_option.py)
DECODING_SEEDS = (0, 1, 2, 3, 4)


def reference_order_base(net, text: torch.Tensor, lengths: torch.Tensor, seed: int) -> torch.Tensor:
    """Base-layer decoding in the authors' draw order: our sampler with ``schedule=reference``
    (their float32 counts and tie order) and ``noise=reference`` (one ``Categorical`` draw over
    the batch per pass, from a generator seeded as their ``torch.manual_seed``)."""
    return decode_base(net, text, lengths, iterations=ITERATIONS, cfg_scale=MASK_CFG,
                       top_k_ratio=TOP_K, generator=torch.Generator().manual_seed(seed),
                       schedule="reference", noise="reference")  # fmt: skip


TOLERANCES = {"latent": DECODED, "decoded": DECODED, "mask_logits": LOGITS,
              "mask_null_logits": LOGITS, "residual_logits": LOGITS,
              "residual_null_logits": LOGITS}  # fmt: skip
EXACT = ("indices", "residual_tokens", "base_tokens")


# ---------------------------------------------------------------------------------------------
# the tests


@pytest.fixture(scope="module")
def fixture() -> dict:
    torch.set_num_threads(min(torch.get_num_threads(), 2))
    return load_fixture(FIXTURE)


@pytest.fixture(autouse=True)
def _data_root(tmp_path, monkeypatch):
    """The converted runs' text cache under tmp_path, not the repository's data/."""
    monkeypatch.setenv("INTERMASK_ROOT", str(tmp_path))


@pytest.mark.parametrize("name", ["small", "noshare"])
def test_a_converted_release_gives_the_authors_outputs(fixture, name, tmp_path):
    case = fixture["cases"][name]
    ours = convert(write_release(tmp_path / "release", case, fixture["seed"]), tmp_path / "out")
    mine = our_outputs(ours, case["inputs"], fixture["captions"])
    theirs = case["outputs"]
    for key, tolerance in TOLERANCES.items():
        torch.testing.assert_close(mine[key], theirs[key], rtol=0, atol=tolerance, msg=key)
    for key in EXACT:
        assert torch.equal(mine[key], theirs[key]), key
    # tolerances that mean something: the values are O(1)
    assert float(theirs["mask_logits"].abs().max()) > 1.0
    assert float(theirs["residual_logits"].abs().max()) > 1.0
    assert float(theirs["decoded"].abs().max()) > 0.1


def test_every_architecture_option_is_mapped_or_refused_by_name(fixture):
    case = fixture["cases"]["noshare"]
    vq = rvq_overrides(case["vq"]["options"], source="opt.txt")
    assert vq == {"model.net.quantizer.codebook_size": 64, "model.net.encoder.width": 32,
                  "model.net.encoder.dilations": [9, 3, 1],
                  "model.net.quantizer.num_quantizers": 4, "model.net.quantizer.dropout_prob": 0.2,
                  "model.net.quantizer.decay": 0.99}  # fmt: skip
    residual = transformer_overrides(case["residual"]["options"], residual=True, source="opt.txt")
    assert residual == {"model.net.width": 64, "model.net.heads": 8, "model.net.depth": 2,
                        "model.net.ff": 96, "model.net.dropout": 0.2,
                        "model.condition_drop": 0.2, "model.net.share_weights": False}  # fmt: skip
    refused = {
        ("vq", "vq_act", "gelu"): r"vq_act: gelu \(this framework builds only relu\)",
        ("vq", "vq_norm", "LN"): r"vq_norm: LN \(this framework builds only None\)",
        ("vq", "code_dim", "64"): r"code_dim: 64 \(.*equal to width \(32\)\)",
        ("vq", "down_t", "3"): r"down_t: 3 \(this framework builds only 2\)",
        ("vq", "shared_codebook", "True"): r"shared_codebook: True \(.*only False\)",
        ("vq", "dataset_name", "kit"): r"dataset_name: kit \(this framework builds only t2m\)",
        ("mask", "n_heads", "5"): r"n_heads: 5 \(5 heads do not divide latent_dim 64\)",
        ("mask", "force_mask", "True"): r"force_mask: True \(.*only False\)",
        ("mask", "unit_length", "8"): r"unit_length: 8 \(this framework builds only 4\)",
        ("mask", "wandb", "True"): r"wandb: True \(not an option of the authors' code",
    }
    for (model, key, value), message in refused.items():
        options = {**case[model]["options"], key: value}
        with pytest.raises(UnsupportedOption, match=message):
            if model == "vq":
                rvq_overrides(options, source="opt.txt")
            else:
                transformer_overrides(options, residual=False, source="opt.txt")


def test_an_option_we_cannot_build_is_refused_by_name_and_nothing_is_written(fixture, tmp_path):
    case = fixture["cases"]["small"]
    gelu = {"vq": {**case["vq"]["options"], "vq_act": "gelu"}}
    paths = write_release(tmp_path / "release", case, fixture["seed"], options=gelu)
    with pytest.raises(UnsupportedOption, match=r"rvq_small/opt.txt: .*\n  vq_act: gelu \(this "):
        convert(paths, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_damaged_or_foreign_checkpoint_is_refused_naming_the_key(fixture, tmp_path):
    case, seed = fixture["cases"]["small"], fixture["seed"]
    residual = model_state(case["residual"], seed)
    residual["cond_emb.weight"] = residual["cond_emb.weight"][:, :-1]  # a damaged tensor
    residual["extra.layer.weight"] = torch.zeros(3)  # a key the authors' model does not have
    del residual["seqTransEncoder.layers.1.linear2.bias"]
    paths = write_release(tmp_path / "damaged", case, seed, states={"residual": residual})
    with pytest.raises(ValueError) as refused:
        convert(paths, tmp_path / "out")
    message = str(refused.value)
    assert "the MoMask residual transformer does not map onto this framework's" in message
    assert "cond_emb.weight: release (64, 63) takes 63-d sentence embeddings" in message
    assert "release keys with no place here (1): extra.layer.weight" in message
    assert "keys of ours without a value (2): backbone.condition_projection.weight, " \
        "backbone.encoder.layers.1.linear2.bias" in message  # fmt: skip
    assert not (tmp_path / "out").exists()


def test_a_foreign_checkpoint_is_refused_naming_what_it_holds(fixture, tmp_path):
    case, seed = fixture["cases"]["small"], fixture["seed"]
    paths = write_release(tmp_path / "release", case, seed)
    torch.save({"t2m_transformer_v2": {}, "ep": 1}, paths["mask"])  # another code's layout
    with pytest.raises(ValueError, match=r"latest.tar: not a MoMask masked transformer "
                                         r"checkpoint \(no t2m_transformer or trans; found "
                                         r"\['ep', 't2m_transformer_v2'\]\)"):  # fmt: skip
        convert(paths, tmp_path / "out")
    paths["mask"].write_bytes(b"PK\x03\x04 truncated")  # a damaged file
    with pytest.raises(ValueError, match=r"latest.tar: not a readable checkpoint"):
        convert(paths, tmp_path / "out")
    assert not (tmp_path / "out").exists()
