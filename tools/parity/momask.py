"""MoMask's networks against the authors' code (EricGuo5513/momask-codes): the residual VQ-VAE,
the masked transformer and the residual transformer, through ``intermask convert-reference``.

    python tools/parity/momask.py --reference PATH [--write-fixture] [--paper-size]

For each case the authors' ``RVQVAE``, ``MaskTransformer`` and ``ResidualTransformer`` are built
from an ``opt.txt`` read by their own ``get_opt`` (reduced widths: their code allows any; with
``--paper-size`` also the released sizes), given seeded random weights and saved in the release's
layout (``checkpoints/t2m/<name>/opt.txt``, ``model/<which>.tar``, the tokenizer's ``meta/``).
Their modules are then loaded back from those files as their ``gen_t2m.py`` loads them, and this
framework converts the same files with ``convert_momask``. Both sides are fed the same inputs;
their text tower is replaced: ``encode_text`` returns CLIP's sentence embedding of this
framework's seeded random CLIP-shaped tower (``configs/text/tiny_random.yaml``), its end-of-text
feature times its text projection. ``--write-fixture`` stores the options, the weights' recipe,
the inputs and the authors' outputs in ``tests/parity/fixtures/momask_models.pt``.
"""

from __future__ import annotations

import os
import sys
import tempfile
import types
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import OmegaConf
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
from test_parity_momask import (  # noqa: E402
    DECODING_SEEDS,
    EXACT,
    FILES,
    FIXTURE,
    ITERATIONS,
    MASK_CFG,
    RESIDUAL_CFG,
    TOLERANCES,
    TOP_K,
    convert,
    our_outputs,
    valid_steps,
    write_opt,
)

from intermask.convert_momask import clip_text_projection  # noqa: E402
from intermask.momask.model import sentence_features  # noqa: E402
from intermask.momask.sampler import decode_base  # noqa: E402

SEED = 20261129
MARKER = "models/mask_transformer/transformer.py"
CAPTIONS = ["a person walks forward and waves with the right hand.", "someone jumps twice."]
TRAINING = {"gpu_id": "-1", "checkpoints_dir": "./checkpoints", "is_train": "True",
            "is_continue": "False", "seed": "3407", "lr": "0.0002", "gamma": "0.1"}  # fmt: skip


def _options(**values: Any) -> dict[str, str]:
    return {k: str(v) for k, v in {**TRAINING, **values}.items()}


def case_options(
    name: str, *, width: int, codes: int, layers: int, latent: int, heads: int, depth: int,
    ff: int, share: bool,
) -> dict[str, dict[str, str]]:  # fmt: skip
    vq_name = f"rvq_{name}"
    vq = _options(dataset_name="t2m", name=vq_name, batch_size=256, window_size=64, max_epoch=50,
                  warm_up_iter=2000, milestones=[150000, 250000], weight_decay=0.0, commit=0.02,
                  loss_vel=0.5, recons_loss="l1_smooth", code_dim=width, nb_code=codes, mu=0.99,
                  down_t=2, stride_t=2, width=width, depth=3, dilation_growth_rate=3,
                  output_emb_width=width, vq_act="relu", vq_norm=None, num_quantizers=layers,
                  shared_codebook=False, quantize_dropout_prob=0.2, ext="default",
                  log_every=10, save_latest=500, save_every_e=2, eval_every_e=1, feat_bias=5,
                  which_epoch="all", vq_name="rvq_nq6_dc512_nc512_noshare_qdp0.2")  # fmt: skip
    transformer = dict(dataset_name="t2m", vq_name=vq_name, latent_dim=latent, n_heads=heads,
                       n_layers=depth, ff_size=ff, dropout=0.2, max_motion_length=196,
                       unit_length=4, force_mask=False, batch_size=64, max_epoch=500,
                       milestones=[50000], warm_up_iter=2000, gumbel_sample=False,
                       share_weight=share, log_every=50, eval_every_e=10, save_latest=500)  # fmt: skip
    return {
        "vq": vq,
        "mask": _options(name=f"mtrans_{name}", cond_drop_prob=0.1, **transformer),
        "residual": _options(name=f"rtrans_{name}", cond_drop_prob=0.2, **transformer),
    }


CASES = {
    "small": case_options("small", width=32, codes=64, layers=4, latent=64, heads=4, depth=2,
                          ff=96, share=True),
    "noshare": case_options("noshare", width=32, codes=64, layers=4, latent=64, heads=8,
                            depth=2, ff=96, share=False),
}  # fmt: skip
PAPER = case_options("paper", width=512, codes=512, layers=6, latent=384, heads=6, depth=8,
                     ff=1024, share=True)  # fmt: skip


def their_options(folder: Path) -> Any:
    """The folder's opt.txt read by the authors' ``get_opt`` (numbers, booleans, strings)."""
    from utils.get_opt import get_opt

    opt = get_opt(str(folder / "opt.txt"), torch.device("cpu"))
    opt.checkpoints_dir = str(folder.parent.parent)  # where this run wrote the release
    return opt


def build_theirs(model: str, opt: Any, vq_opt: Any | None) -> nn.Module:
    """Their module, constructed with the arguments their gen_t2m.py passes."""
    from models.mask_transformer.transformer import MaskTransformer, ResidualTransformer
    from models.vq.model import RVQVAE

    if model == "vq":
        return RVQVAE(opt, opt.dim_pose, opt.nb_code, opt.code_dim, opt.output_emb_width,
                      opt.down_t, opt.stride_t, opt.width, opt.depth, opt.dilation_growth_rate,
                      opt.vq_act, opt.vq_norm)  # fmt: skip
    opt.num_tokens, opt.num_quantizers = vq_opt.nb_code, vq_opt.num_quantizers
    opt.code_dim = vq_opt.code_dim
    common_args = dict(code_dim=vq_opt.code_dim, cond_mode="text", latent_dim=opt.latent_dim,
                       ff_size=opt.ff_size, num_layers=opt.n_layers, num_heads=opt.n_heads,
                       dropout=opt.dropout, clip_dim=CLIP_DIM, cond_drop_prob=opt.cond_drop_prob,
                       clip_version="ViT-B/32", opt=opt)  # fmt: skip
    if model == "mask":
        return MaskTransformer(**common_args)
    return ResidualTransformer(shared_codebook=vq_opt.shared_codebook,
                               share_weight=opt.share_weight, **common_args)  # fmt: skip


def load_theirs(model: str, folder: Path, vq_opt: Any | None) -> tuple[nn.Module, Any]:
    """As their loaders: strict but for the frozen CLIP's keys, weights only."""
    opt = their_options(folder)
    net = build_theirs(model, opt, vq_opt)
    entry, file = FILES[model]
    stored = torch.load(folder / "model" / file, map_location="cpu", weights_only=True)
    missing, unexpected = net.load_state_dict(stored[entry], strict=False)
    if unexpected or not all(k.startswith("clip_model.") for k in missing):
        raise SystemExit(f"{folder}: their loader would refuse it ({missing}, {unexpected})")
    return net.eval(), opt


RESIDUAL_TABLES = ("token_embed_weight", "output_proj_weight", "embed_proj_shared_weight",
                   "token_embed_weight_", "output_proj_weight_")  # fmt: skip
CLIP_DIM = 64  # the stand-in tower's embed_dim (configs/text/tiny_random.yaml)


class _ClipStub(nn.Module):
    """What ``clip.load`` returns: never called for features (``encode_text`` is patched)."""


def _text() -> tuple[torch.Tensor, torch.Tensor]:
    """(B, D_text) end-of-text features of the stand-in tower and its (D_text, D_clip)
    projection; CLIP's sentence embedding is their product."""
    from hydra.utils import instantiate

    config = OmegaConf.load(common.REPO / "configs" / "text" / "tiny_random.yaml")
    encoder = instantiate(config.encoder)
    return sentence_features(encoder.encode(CAPTIONS)), clip_text_projection(config)


def _weights(net: nn.Module, seed: int) -> tuple[dict, dict[str, torch.Tensor], list | None]:
    """(recipe, state, pe shape) of seeded weights for their module: every tensor but the
    frozen CLIP's and the position table (kept as their module computes it)."""
    state = {k: v for k, v in net.state_dict().items() if not k.startswith("clip_model.")}
    pe = state.pop("position_enc.pe", None)
    recipe = common.weight_recipe(state)
    for key, value in state.items():  # per-layer code tables: N(0, 1/E), as a code embedding
        if key in RESIDUAL_TABLES:
            recipe[key] = (tuple(value.shape), 0.0, float(value.shape[-1]) ** -0.5)
    built = common.build_state(recipe, seed=seed)
    if pe is not None:
        built["position_enc.pe"] = pe
    return recipe, built, None if pe is None else list(pe.shape)


def _inputs(options: dict[str, dict[str, str]], seed: int) -> dict[str, Any]:
    codes, layers = int(options["vq"]["nb_code"]), int(options["vq"]["num_quantizers"])
    steps, draw = 8, np.random.RandomState(seed)
    lengths = torch.tensor([steps, steps - 3])
    ids = torch.from_numpy(draw.randint(0, codes, size=(2, steps)))
    ids[torch.from_numpy(draw.rand(2, steps) < 0.3)] = codes  # [MASK]
    ids[~valid_steps(lengths, steps)] = codes + 1  # [PAD]
    motion = draw.standard_normal((2, 4 * steps, 263)).astype(np.float32)
    return {"motion": torch.from_numpy(motion), "lengths": lengths, "mask_ids": ids,
            "codes": torch.from_numpy(draw.randint(0, codes, size=(2, layers, steps)))}  # fmt: skip


@torch.no_grad()
def their_outputs(nets: dict[str, nn.Module], inputs: dict, sentence: torch.Tensor) -> dict:
    vq, mask, residual = nets["vq"], nets["mask"], nets["residual"]
    lengths, ids, codes, motion = (inputs[k] for k in ("lengths", "mask_ids", "codes", "motion"))
    valid = valid_steps(lengths, ids.shape[1])
    padding = ~valid
    for net in (mask, residual):  # their captions -> CLIP's sentence embedding
        net.encode_text = lambda raw: sentence[[CAPTIONS.index(c) for c in raw]]
    indices, _ = vq.encode(motion)
    out = {
        "latent": vq.encoder(vq.preprocess(motion)),
        "indices": indices.permute(0, 2, 1),
        "decoded": vq.forward_decoder(codes.permute(0, 2, 1)),
    }
    count, pad_id = residual.opt.num_tokens, residual.pad_id
    residual.process_embed_proj_weight()
    padded = codes.masked_fill(padding[:, None], pad_id)
    for name, force in (("", False), ("null_", True)):
        logits = mask.trans_forward(ids, sentence, padding, force_mask=force).permute(0, 2, 1)
        out[f"mask_{name}logits"] = logits * valid[..., None]
        layers = []
        for j in range(1, codes.shape[1]):
            history = sum(residual.token_embed_weight[i][padded[:, i]] for i in range(j))
            logits = residual.forward_with_cond_scale(history, j, sentence, padding, cond_scale=1,
                                                      force_mask=force)  # fmt: skip
            layers.append(logits.permute(0, 2, 1)[..., :count] * valid[..., None])
        out[f"residual_{name}logits"] = torch.stack(layers)
    # greedy residual decoding: their Gumbel draw at temperature 0 is the argmax
    base = codes[:, 0].masked_fill(padding, -1)
    decoded = residual.generate(base.clamp_min(0), CAPTIONS, lengths, temperature=0,
                                cond_scale=RESIDUAL_CFG)  # fmt: skip
    out["residual_tokens"] = decoded.permute(0, 2, 1)
    seeded = []
    for seed in DECODING_SEEDS:  # their base decoding, seeded as their gen_t2m seeds it
        torch.manual_seed(seed)
        seeded.append(mask.generate(CAPTIONS, lengths, timesteps=ITERATIONS, cond_scale=MASK_CFG,
                                    temperature=1, topk_filter_thres=1 - TOP_K))  # fmt: skip
    out["base_tokens"] = torch.stack(seeded)
    out["pad_drawn"] = int((decoded[valid] == -1).sum())  # [PAD] drawn at a valid step
    return out


def run_case(name: str, options: dict, root: Path, seed: int, sentence: torch.Tensor) -> dict:
    """Write the case's release, load it into theirs and ours, and compare; -> fixture entry."""
    release = root / name / "checkpoints" / "t2m"
    case: dict[str, Any] = {}
    nets, vq_opt, paths = {}, None, {}
    for model in FILES:
        folder = release / options[model]["name"]
        (folder / "model").mkdir(parents=True)
        write_opt(folder, options[model])
        opt = their_options(folder)
        recipe, state, pe = _weights(build_theirs(model, opt, vq_opt), seed)
        entry, file = FILES[model]
        paths[model] = folder / "model" / file
        torch.save({entry: state, "ep": 7, "total_it": 1234}, paths[model])
        case[model] = {"options": options[model], "recipe": recipe}
        if pe is not None:
            case[model]["pe"] = pe
        if model == "vq":
            draw = np.random.RandomState(seed + 1)
            meta = {"mean": draw.standard_normal(263), "std": 0.5 + draw.rand(263)}
            case["meta"] = {k: torch.from_numpy(v.astype(np.float32)) for k, v in meta.items()}
            (folder / "meta").mkdir()
            for key, value in case["meta"].items():
                np.save(folder / "meta" / f"{key}.npy", value.numpy())
        nets[model], opt = load_theirs(model, folder, vq_opt)
        vq_opt = opt if model == "vq" else vq_opt
    case["inputs"] = _inputs(options, seed)
    theirs = their_outputs(nets, case["inputs"], sentence)
    pad_drawn = theirs.pop("pad_drawn")
    ours_nets = convert(paths, root / name / "out")
    ours = our_outputs(ours_nets, case["inputs"], CAPTIONS)
    print(f"{name}:")
    for key in TOLERANCES:
        diff = common.max_abs(ours[key], theirs[key].reshape(ours[key].shape))
        print(f"  {key:22s} max abs diff {diff:.3g} (largest value {theirs[key].abs().max():.3g})")
    for key in EXACT:
        same = torch.equal(ours[key], theirs[key].reshape(ours[key].shape))
        differ = int((ours[key] != theirs[key].reshape(ours[key].shape)).sum())
        print(f"  {key:22s} {'equal' if same else f'{differ} differ'}")
    print(f"  their greedy residual decoding drew [PAD] at {pad_drawn} valid step(s)")
    sampler = decode_base(ours_nets.mask.net, ours_nets.text(CAPTIONS), case["inputs"]["lengths"],
                          iterations=ITERATIONS, cfg_scale=MASK_CFG, top_k_ratio=TOP_K,
                          generator=[torch.Generator().manual_seed(0)] * 2)  # fmt: skip
    differ = int((sampler != theirs["base_tokens"][0]).sum())
    print(f"  our default decoding (paper schedule, per-sample noise), seed 0: {differ} tokens "
          "differ from theirs (base_tokens above: schedule=reference, noise=reference)")  # fmt: skip
    case["outputs"] = theirs
    return case


def main() -> None:
    cli = common.parser(__doc__.splitlines()[0], marker=MARKER)
    cli.add_argument("--paper-size", action="store_true", help="also the released sizes")
    args = cli.parse_args()
    torch.set_num_threads(min(torch.get_num_threads(), 2))
    torch.Tensor.cuda = lambda self, *a, **k: self  # type: ignore[method-assign]
    features, projection = _text()
    sentence = features @ projection  # CLIP's sentence embedding of the stand-in tower
    with tempfile.TemporaryDirectory() as tmp, common.reference_modules(args.reference, MARKER):
        os.environ["INTERMASK_ROOT"] = tmp  # the converted runs' text cache
        sys.modules["clip"] = types.SimpleNamespace(load=lambda *a, **k: (_ClipStub(), None))
        cases = {name: run_case(name, options, Path(tmp), SEED, sentence)
                 for name, options in CASES.items()}  # fmt: skip
        if args.paper_size:
            run_case("paper", PAPER, Path(tmp), SEED, sentence)
    if args.write_fixture:
        record = {"seed": SEED, "captions": CAPTIONS, "cases": cases}
        path = common.save_fixture(FIXTURE, record)
        print(f"wrote {path} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
