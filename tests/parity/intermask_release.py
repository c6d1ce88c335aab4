"""InterMask releases at reduced widths, as the parity script and the fixture tests build them.

One place for what both sides must agree on: the ``opt.txt`` of each case, the fixed inputs, the
stand-in CLIP features, how a release is laid out on disk and converted through
``intermask convert-reference``'s code, and how our converted networks are run on the inputs.
``tools/parity/intermask_models.py`` imports it to make the fixture; the tests import it to
check it, without the authors' code.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from fixtures_io import build_state, seeded_state
from hydra.utils import instantiate
from omegaconf import OmegaConf
from torch import nn

from intermask.convert import convert_reference
from intermask.interm.model import TextFeatures
from intermask.vq.load import load_vq

TEXT, CONTEXT, VOCABULARY = 768, 77, 64  # CLIP's token width and context; the stand-in's vocabulary
SOT, EOT = VOCABULARY - 2, VOCABULARY - 1  # end-of-text is the largest id, as in CLIP
CAPTIONS = ["two people shake hands.", "one person pushes the other away with both hands."]


def _options(**architecture: Any) -> dict[str, str]:
    """An ``opt.txt`` as the authors' parser writes it (strings), training options included."""
    common = {"batch_size": 8, "checkpoints_dir": "./checkpoints", "gpu_id": 0, "is_train": True,
              "is_continue": False, "cache": True}  # fmt: skip
    return {k: str(v) for k, v in {**common, **architecture}.items()}


def _vq_options(dataset: str) -> dict[str, str]:
    return _options(dataset_name=dataset, name=f"vq_{dataset}", motion_rep="smpl", nb_code=32,
                    code_dim=32, output_emb_width=32, width=32, depth=2, dilation_growth_rate=3,
                    down_t=2, stride_t=2, vq_act="relu", vq_norm=None, num_quantizers=1,
                    shared_codebook=False, quantize_dropout_prob=0.2, mu=0.99, window_size=16,
                    lr=0.0002, commit=0.02, loss_fc=500)  # fmt: skip


def _generator_options(heads: int) -> dict[str, str]:
    return _options(dataset_name="interx", name=f"trans_{heads}", vq_name="vq_interx",
                    motion_rep="global", latent_dim=96, n_heads=heads, n_layers=2, ff_size=128,
                    dropout=0.2, force_mask=False, cond_drop_prob=0.1, step_unroll=1.0,
                    interaction_mask_prob=0.2, seed=3407, gumbel_sample=False, lr=0.0002)  # fmt: skip


def _motion(shape: tuple[int, ...], seed: int) -> torch.Tensor:
    return torch.from_numpy(np.random.RandomState(seed).standard_normal(shape).astype(np.float32))


def _vq_inputs(feature_shape: tuple[int, ...]) -> Callable[[int], dict[str, torch.Tensor]]:
    def inputs(codebook: int) -> dict[str, torch.Tensor]:
        codes = np.random.RandomState(2).randint(0, codebook, size=(2, 5 * 4, 1))  # (B, N, Q)
        return {"motion": _motion((2, 16, *feature_shape), 1), "codes": torch.from_numpy(codes)}

    return inputs


def _generator_inputs(codebook: int) -> dict[str, Any]:
    """Two interactions of 4 and 3 token steps (5 rows each): codes, a few [MASK]s, [PAD]s."""
    steps, lengths = 4, torch.tensor([4, 3])
    draw = np.random.RandomState(3)
    ids = torch.from_numpy(draw.randint(0, codebook, size=(2, 2 * 5 * steps)))
    ids[torch.from_numpy(draw.rand(2, 2 * 5 * steps) < 0.3)] = codebook  # [MASK]
    padding = torch.arange(steps).repeat(1, 10) >= lengths[:, None]  # (B, 2 * 5 * T')
    ids[padding] = codebook + 1  # [PAD]
    return {"ids": ids, "padding": padding, "lengths": lengths, "captions": CAPTIONS}


CASES: dict[str, dict[str, Any]] = {
    "vq_interx": {"dataset": "interx", "options": _vq_options("interx"),
                  "inputs": _vq_inputs((56, 6))},
    "vq_interhuman": {"dataset": "interhuman", "options": _vq_options("interhuman"),
                      "inputs": _vq_inputs((262,))},
    "generator": {"vq": "vq_interx", "options": _generator_options(6),
                  "inputs": _generator_inputs},
    "generator_8_heads": {"vq": "vq_interx", "options": _generator_options(8),
                          "inputs": _generator_inputs},
}  # fmt: skip
GENERATOR_CASES = ("generator", "generator_8_heads")
PAPER_SIZE = {  # InterMask appendix C: the released models' widths
    "vq": {"nb_code": "1024", "code_dim": "512", "output_emb_width": "512", "width": "512"},
    "generator": {"latent_dim": "384", "n_layers": "6", "ff_size": "1024"},
}


def use_paper_size() -> None:
    """Every case at the paper's widths (the parity script's ``--size paper``; no fixture)."""
    for case in CASES.values():
        case["options"] = {**case["options"], **PAPER_SIZE["generator" if "vq" in case else "vq"]}


def tokenize(texts: list[str] | str, truncate: bool = True) -> torch.Tensor:
    """The stand-in for ``clip.tokenize``: [SOT] word ids [EOT] then zeros, (B, 77) int64."""
    texts = [texts] if isinstance(texts, str) else texts
    tokens = torch.zeros(len(texts), CONTEXT, dtype=torch.long)
    for row, text in enumerate(texts):
        words = [zlib.crc32(w.encode()) % SOT for w in text.lower().split()][: CONTEXT - 2]
        tokens[row, : len(words) + 2] = torch.tensor([SOT, *words, EOT])
    return tokens


def text_features(seed: int) -> dict[str, torch.Tensor]:
    """The stand-in CLIP tower's token and position embeddings (rebuilt from the seed)."""
    return seeded_state(
        {"token_embedding": (VOCABULARY, TEXT), "positions": (CONTEXT, TEXT)}, seed=seed, scale=1.0
    )


def our_features(clip: dict[str, torch.Tensor], captions: list[str]) -> TextFeatures:
    """What the text cache would hold for these captions with the stand-in tower."""
    tokens = tokenize(captions)
    eot = tokens.argmax(-1)
    features = clip["token_embedding"][tokens] + clip["positions"]
    padding = torch.arange(CONTEXT)[None] > eot[:, None]
    return TextFeatures(features, eot, padding)


def write_release(folder: Path, entry: str, state: dict, options: dict[str, str]) -> Path:
    """``<folder>/opt.txt`` and ``<folder>/model/net_best_fid.tar`` as the authors' trainers
    write them (their optimizer states left out)."""
    (folder / "model").mkdir(parents=True)
    lines = ["------------ Options -------------"]
    lines += [f"{k}: {v}" for k, v in sorted(options.items())]
    (folder / "opt.txt").write_text("\n".join([*lines, "-------------- End ----------------"]))
    checkpoint = folder / "model" / "net_best_fid.tar"
    torch.save({entry: state, "ep": 12, "total_it": 3400}, checkpoint)
    return checkpoint


def _vq_release(name: str, record: dict, folder: Path) -> tuple[Path, tuple[Path, Path] | None]:
    state = build_state(record[name]["recipe"], seed=record["seed"])
    checkpoint = write_release(folder / name, "vq_model", state, CASES[name]["options"])
    if CASES[name]["dataset"] != "interhuman":
        return checkpoint, None
    statistics = (folder / "global_mean.npy", folder / "global_std.npy")
    np.save(statistics[0], np.zeros(262, dtype=np.float32))
    np.save(statistics[1], np.ones(262, dtype=np.float32))
    return checkpoint, statistics


def convert_case(
    name: str, record: dict, folder: Path, options: dict[str, str] | None = None
) -> nn.Module:
    """Our network converted from the case's release (written from the fixture's recipe under
    ``folder``, with ``options`` as its opt.txt when given) by
    ``intermask.convert.convert_reference``, loaded from the run folder."""
    vq_name = CASES[name].get("vq", name)
    vq, statistics = _vq_release(vq_name, record, folder)
    generator = None
    if name in GENERATOR_CASES:
        state = build_state(record[name]["recipe"], seed=record["seed"])
        options = options or CASES[name]["options"]
        generator = write_release(folder / name, "t2m_transformer", state, options)
    done = convert_reference(vq=vq, generator=generator, out=folder / "out", statistics=statistics)
    if generator is None:
        return load_vq(done.vq_run)
    config = OmegaConf.load(done.gen_run / "config.yaml")
    stored = torch.load(done.gen_run / "checkpoints" / "last.ckpt", weights_only=True)
    net = instantiate(config.model.net)(codebook_size=stored["hyper_parameters"]["codebook_size"])
    net.load_state_dict({k[4:]: v for k, v in stored["state_dict"].items()})
    return net.eval()


def our_decode(vq: nn.Module, codes: torch.Tensor) -> torch.Tensor:
    """Their (B, N, Q) row-major indices through our decoder -> (B, T, *F)."""
    batch, tokens, layers = codes.shape
    return vq.decode(codes.permute(0, 2, 1).reshape(batch, layers, 5, tokens // 5))


def our_logits(
    net: nn.Module, features: TextFeatures, inputs: dict, drop: bool, theirs: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Our logits and theirs ((B, K, 2N), [SEP] left out) at the valid positions, (V, K) each."""
    ids, padding, lengths = inputs["ids"], inputs["padding"], inputs["lengths"]
    batch, width = ids.shape
    a, b = ids.reshape(batch, 2, 5, width // 10).unbind(1)
    drop_condition = torch.full((batch,), drop)
    with torch.no_grad():
        mine = net(a, b, features, lengths, drop_condition)
    mine = torch.cat([m.flatten(1, 2) for m in mine], dim=1)  # (B, 2N, K)
    return mine[~padding], theirs.permute(0, 2, 1)[~padding]
