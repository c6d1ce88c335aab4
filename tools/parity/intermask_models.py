"""InterMask's networks against the authors' code (gohar-malik/InterMask): the Inter-M
generator's logits, both tokenizers (InterHuman with its graph ends, Inter-X) and seeded decoding.

    python tools/parity/intermask_models.py --reference PATH [--write-fixture]

For each case the authors' module is built from an ``opt.txt`` (reduced widths: the code allows
any), given seeded random weights, and saved in the release's layout; this framework converts
that release with the code ``intermask convert-reference`` runs and the two are fed the same
inputs. ``--write-fixture`` stores the recipe of the weights, the inputs and the authors'
outputs in ``tests/parity/fixtures/intermask_models.pt``, which ``make test`` checks without the
authors' code (tests/parity/test_parity_intermask.py).
"""

from __future__ import annotations

import math
import sys
import tempfile
from argparse import Namespace
from pathlib import Path

import torch
from torch import nn

from intermask.vq.convolutions import SkeletonGraphLayer

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
from intermask_release import (  # noqa: E402
    CASES,
    GENERATOR_CASES,
    TEXT,
    convert_case,
    our_decode,
    our_features,
    our_logits,
    text_features,
    tokenize,
    use_paper_size,
)

SEED = 20261128


class _ClipStub(nn.Module):
    """What the authors' transformer takes from ``clip.load``: a token embedding and position
    embedding whose sum is the per-token feature (the text tower itself is the identity, so both
    sides see exactly the features a test can rebuild)."""

    def __init__(self, token_embedding: torch.Tensor, positions: torch.Tensor) -> None:
        super().__init__()
        self.token_embedding = nn.Embedding.from_pretrained(token_embedding, freeze=True)
        self.positional_embedding = nn.Parameter(positions, requires_grad=False)
        self.transformer = nn.Identity()
        self.ln_final = nn.Identity()
        self.dtype = torch.float32


def _patch_cuda() -> None:
    """Their quantizer allocates its codebook with ``.cuda()``: a no-op on this CPU run."""
    torch.Tensor.cuda = lambda self, *args, **kwargs: self  # type: ignore[method-assign]


def their_options(options: dict[str, str], folder: Path) -> Namespace:
    """The options as their ``get_opt`` parses an ``opt.txt`` (numbers, booleans, None)."""
    from utils.get_opt import get_opt

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "their_opt.txt"
    path.write_text("".join(f"{k}: {v}\n" for k, v in options.items()))
    return get_opt(str(path), "cpu", complete=False)


def reference_vq(options: dict, dataset: str, folder: Path) -> nn.Module:
    from models.vq.model import RVQVAE

    opt = their_options(options, folder)
    opt.joints_num = 22 if dataset == "interhuman" else 56
    net = RVQVAE(opt, 12 if dataset == "interhuman" else 6, opt.nb_code, opt.code_dim,
                 opt.code_dim, opt.down_t, opt.stride_t, opt.width, opt.depth,
                 opt.dilation_growth_rate, opt.vq_act, None)  # fmt: skip
    return net.eval()


def reference_generator(
    options: dict, codebook: int, code_dim: int, clip: dict, folder: Path
) -> nn.Module:
    common.clip_stub(_ClipStub(clip["token_embedding"], clip["positions"]), tokenize)
    from models.mask_transformer.transformer import MaskTransformer

    opt = their_options(options, folder)
    opt.num_tokens, opt.code_dim = codebook, code_dim
    net = MaskTransformer(code_dim=code_dim, cond_mode="text", latent_dim=opt.latent_dim,
                          ff_size=opt.ff_size, num_layers=opt.n_layers, num_heads=opt.n_heads,
                          dropout=opt.dropout, clip_dim=TEXT, cond_drop_prob=opt.cond_drop_prob,
                          clip_version="ViT-L/14@336px", opt=opt)  # fmt: skip
    return net.eval()


def _release_state(net: nn.Module) -> dict[str, torch.Tensor]:
    return {k: v for k, v in net.state_dict().items() if not k.startswith("clip_")}


def _vq_case(name: str, case: dict, folder: Path, record: dict) -> dict[str, float]:
    dataset = case["dataset"]
    net = reference_vq(case["options"], dataset, folder / "theirs")
    recipe = common.weight_recipe(_release_state(net))
    net.load_state_dict(common.build_state(recipe, seed=SEED), strict=False)
    inputs = case["inputs"](int(case["options"]["nb_code"]))
    with torch.no_grad():
        latent = net.encoder(net.preprocess(inputs["motion"]))
        decoded = net.forward_decoder(inputs["codes"])
    record[name] = {"recipe": recipe, "inputs": inputs, "latent": latent, "decoded": decoded}
    ours = convert_case(name, record, folder)
    figures = {}
    graph_layers = [m for m in ours.modules() if isinstance(m, SkeletonGraphLayer)]
    if graph_layers:  # as converted (frame 0 of every sequence): theirs given each one alone
        alone = [_encode_decode(net, ours, inputs, i, theirs=True) for i in range(2)]
        mine = [_encode_decode(ours, ours, inputs, i, theirs=False) for i in range(2)]
        figures["each sequence alone: latent"] = max(
            common.max_abs(m[0], a[0].reshape(m[0].shape)) for m, a in zip(mine, alone, strict=True)
        )
        figures["each sequence alone: decoded"] = max(
            common.max_abs(m[1], a[1].reshape(m[1].shape)) for m, a in zip(mine, alone, strict=True)
        )
        for layer in graph_layers:  # their module on a batch: the first sequence's frame 0 only
            layer.frames = "batch_first"
    with torch.no_grad():
        our_latent = ours.encoder(ours.view.to_joints(inputs["motion"]))
        our_decoded = our_decode(ours, inputs["codes"])
    return {
        **figures,
        "encoder latent": common.max_abs(our_latent, latent.reshape(our_latent.shape)),
        "decoded features": common.max_abs(our_decoded, decoded.reshape(our_decoded.shape)),
        "largest decoded": float(decoded.abs().max()),
    }


def _encode_decode(net, ours, inputs, i: int, *, theirs: bool):
    """Sequence ``i`` alone through the authors' module (``theirs``) or ours."""
    motion, codes = inputs["motion"][i : i + 1], inputs["codes"][i : i + 1]
    with torch.no_grad():
        if theirs:
            return net.encoder(net.preprocess(motion)), net.forward_decoder(codes)
        return ours.encoder(ours.view.to_joints(motion)), our_decode(ours, codes)


def _generator_case(name: str, case: dict, folder: Path, record: dict) -> dict[str, float]:
    clip = text_features(record["seed"])
    vq = CASES[case["vq"]]["options"]
    net = reference_generator(
        case["options"], int(vq["nb_code"]), int(vq["code_dim"]), clip, folder / "theirs"
    )
    recipe = common.weight_recipe(_release_state(net), keep=("position_enc.",))
    net.load_state_dict(common.build_state(recipe, seed=SEED), strict=False)
    inputs = case["inputs"](int(vq["nb_code"]))
    with torch.no_grad():
        condition = net.encode_text(inputs["captions"])
        logits = {
            drop: net.trans_forward(inputs["ids"], condition, inputs["padding"], force_mask=drop)
            for drop in (False, True)
        }
    record[name] = {"recipe": recipe, "inputs": inputs, "logits": logits[False],
                    "null_logits": logits[True]}  # fmt: skip
    ours = convert_case(name, record, folder)
    features = our_features(clip, inputs["captions"])
    figures = {}
    for drop, title in ((False, "logits"), (True, "logits, null condition")):
        mine, theirs = our_logits(ours, features, inputs, drop, logits[drop])
        figures[title] = common.max_abs(mine, theirs)
    figures["largest logit"] = float(logits[False].abs().max())
    figures |= _decoding(net, ours, features, inputs, record[name])
    return figures


def _decoding(net, ours, features, inputs, record: dict, seeds=(0, 1, 2, 3, 4)) -> dict:
    """Seeded decoding: ``torch.manual_seed(s)`` then their ``generate`` against ours with
    ``seeds=[s, s]``, ``schedule=reference``, ``noise=reference``."""
    from intermask.interm.decoding import generate

    lengths = inputs["lengths"]
    tokens, equal = {}, 0
    for seed in seeds:
        torch.manual_seed(seed)
        with torch.no_grad():
            theirs = net.generate(inputs["captions"], lengths, timesteps=10, cond_scale=2,
                                  topk_filter_thres=0.9)  # fmt: skip
        tokens[seed] = theirs
        mine = generate(ours, features, lengths, iterations=10, cfg_scale=2.0,
                        top_k_ratio=0.1, seeds=[seed] * len(lengths), schedule="reference",
                        noise="reference")  # fmt: skip
        differ = (mine.flatten(1) != theirs).sum().item()
        equal += differ == 0
        if differ:
            print(f"seed {seed}: {differ} of {theirs.numel()} tokens differ")
    record["decoded_tokens"] = tokens
    return {"seeded decodings equal": f"{equal} of {len(seeds)}"}


def main() -> int:
    cli = common.parser(__doc__.splitlines()[0], marker="models/mask_transformer/transformer.py")
    cli.add_argument("--size", choices=("reduced", "paper"), default="reduced",
                     help="reduced widths (the fixture's) or the paper's (no fixture)")  # fmt: skip
    args = cli.parse_args()
    if args.size == "paper":
        if args.write_fixture:
            cli.error("the fixture is written at reduced widths only (it must stay small)")
        use_paper_size()
    _patch_cuda()
    torch.set_grad_enabled(False)
    record: dict = {"seed": SEED}
    with (
        common.reference_modules(args.reference, args.marker),
        tempfile.TemporaryDirectory() as tmp,
    ):
        for name in CASES:
            case = CASES[name]
            run = _generator_case if name in GENERATOR_CASES else _vq_case
            figures = run(name, case, Path(tmp) / name, record)
            print(f"{name}: " + "; ".join(f"{k} {_fmt(v)}" for k, v in figures.items()))
    if args.write_fixture:
        path = common.save_fixture("intermask_models", record)
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


def _fmt(value) -> str:
    return f"{value:.2e}" if isinstance(value, float) and not math.isnan(value) else str(value)


if __name__ == "__main__":
    sys.exit(main())
