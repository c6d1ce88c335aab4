"""The reference implementation's VQ-VAE weights in this framework's layout.

The authors' release stores the tokenizer as an ``RVQVAE`` state dict (``vq_model`` or ``net``
in its checkpoint). Its encoder and decoder are nested ``Sequential``s (a strided convolution and
a ``Resnet`` of ``ResConvBlock``s per stage; a ``Resnet``, an upsampling and a convolution per
decoder stage); ours are flat ``Sequential``s of the same layers in the same order, so the
conversion renames indices. The reference quantizer keeps only its codebook; the EMA statistics
this framework also stores are derived from it (sums = codes, counts = 1), so a converted
tokenizer can be fine-tuned.

The InterHuman release replaces the encoder's first and the decoder's last convolution with two
graph layers each (``gcn_layer*``, torch_geometric's ``SAGEConv``); they map onto
:class:`~intermask.vq.convolutions.SkeletonGraphLayer` (``ends: graph_first_frame``), and its
encoder's ``Sequential`` then starts one index earlier.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping

import torch

from intermask.utils.state_conversion import Conversion, compare_with_target

_Rule = tuple[re.Pattern[str], Callable[[re.Match[str]], str]]


def _block(prefix: str, stack: int) -> Callable[[re.Match[str]], str]:
    layer = {"conv1": 1, "conv2": 3}  # ReLU, conv1, ReLU, conv2 in our residual block's body
    return lambda m: f"{prefix}.net.{stack}.{m['block']}.body.{layer[m['conv']]}.{m['kind']}"


_RES = r"model\.(?P<block>\d+)\.(?P<conv>conv[12])\.(?P<kind>weight|bias)"
_KIND = r"(?P<kind>weight|bias)"
_GRAPH = r"(?P<part>lin|lin_l|lin_r)\.(?P<kind>weight|bias)"


def _kind(target: str) -> Callable[[re.Match[str]], str]:
    return lambda m: f"{target}.{m['kind']}"


def _graph(target: str) -> Callable[[re.Match[str]], str]:
    return lambda m: f"{target}.{m['part']}.{m['kind']}"


def _rules(graph_ends: bool) -> list[_Rule]:
    """Reference key patterns -> ours. Encoder: [first layer, ReLU,] [strided conv, Resnet] x 2,
    out conv; with graph ends the first conv and ReLU are not in ``model``, so its stages start
    at index 0. Decoder: in conv, ReLU, [Resnet, upsample, conv] x 2, conv, ReLU, out conv (or
    graph layers outside ``model``)."""
    first = 0 if graph_ends else 2  # the reference encoder's index of its first stage
    rules = [
        (rf"encoder\.model\.{first}\.0\.{_KIND}", _kind("encoder.net.2")),
        (rf"encoder\.model\.{first}\.1\.{_RES}", _block("encoder", 3)),
        (rf"encoder\.model\.{first + 1}\.0\.{_KIND}", _kind("encoder.net.4")),
        (rf"encoder\.model\.{first + 1}\.1\.{_RES}", _block("encoder", 5)),
        (rf"encoder\.model\.{first + 2}\.{_KIND}", _kind("encoder.net.6")),
        (rf"decoder\.model\.0\.{_KIND}", _kind("decoder.net.0")),
        (rf"decoder\.model\.2\.0\.{_RES}", _block("decoder", 2)),
        (rf"decoder\.model\.2\.2\.{_KIND}", _kind("decoder.net.4")),
        (rf"decoder\.model\.3\.0\.{_RES}", _block("decoder", 5)),
        (rf"decoder\.model\.3\.2\.{_KIND}", _kind("decoder.net.7")),
        (rf"decoder\.model\.4\.{_KIND}", _kind("decoder.net.8")),
    ]
    if graph_ends:
        rules += [
            (rf"{end}\.gcn_layer{layer}\.{_GRAPH}", _graph(f"{end}.net.{index}.{sub}"))
            for end, index in (("encoder", 0), ("decoder", 10))
            for layer, sub in ((1, 0), (2, 2))
        ]
    else:
        rules += [
            (rf"encoder\.model\.0\.{_KIND}", _kind("encoder.net.0")),
            (rf"decoder\.model\.6\.{_KIND}", _kind("decoder.net.10")),
        ]
    return [(re.compile(pattern), target) for pattern, target in rules]


_CODEBOOK = re.compile(r"quantizer\.layers\.(?P<layer>\d+)\.codebook")


def has_graph_ends(reference: Mapping[str, torch.Tensor]) -> bool:
    """True for the InterHuman release's layout (graph layers at both ends)."""
    return any(".gcn_layer" in key for key in reference)


def convert_reference_vq(
    reference: Mapping[str, torch.Tensor], target: Mapping[str, torch.Tensor] | None = None
) -> Conversion:
    """The reference ``RVQVAE`` state dict -> ours (see the module docstring); ``target`` (our
    model's state dict) adds the missing and mis-shaped keys to the report."""
    out: dict[str, torch.Tensor] = {}
    unmapped, computed = [], []
    sources: dict[str, str] = {}  # ours -> the release key it came from
    rules = _rules(has_graph_ends(reference))
    for key, value in reference.items():
        placed = len(out)
        _place(key, value, rules, out, computed, unmapped)
        sources |= dict.fromkeys(list(out)[placed:], key)
    missing, extra, mismatched = compare_with_target(out, target, sources)
    return Conversion(out, [], computed, unmapped + extra, missing, mismatched, WHY)


WHY = (
    "computed: each codebook's EMA statistics (sums = the codes, counts = 1; the release keeps "
    "only the codebook), so a converted tokenizer can be fine-tuned",
)


def _place(
    key: str,
    value: torch.Tensor,
    rules: list[_Rule],
    out: dict[str, torch.Tensor],
    computed: list[str],
    unmapped: list[str],
) -> None:
    """Put one release key where it belongs (``out``) or in ``unmapped``."""
    codebook = _CODEBOOK.fullmatch(key)
    if codebook is not None:
        layer = f"quantizer.layers.{codebook['layer']}"
        out[f"{layer}.codebook"] = value
        out[f"{layer}.ema_sum"] = value.clone()
        out[f"{layer}.ema_count"] = torch.ones(value.shape[0], dtype=value.dtype)
        out[f"{layer}.initialized"] = torch.tensor(True)
        computed += [f"{layer}.ema_sum", f"{layer}.ema_count", f"{layer}.initialized"]
        return
    for pattern, target_key in rules:
        match = pattern.fullmatch(key)
        if match is not None:
            out[target_key(match)] = value
            return
    unmapped.append(key)
