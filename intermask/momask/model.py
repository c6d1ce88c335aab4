"""MoMask's masked transformer and residual transformer (sections 3.2 and 3.3).

Both read the sequence ``[condition, (layer), token_1, ..., token_T']`` with a post-norm GELU
``nn.TransformerEncoder`` (the reference's settings) and predict codes at the token positions:

- condition: the caption's sentence feature (B, D_text) through a trainable Linear to D. A
  dropped caption (classifier-free guidance) is the zero feature, as in the reference, so the
  null condition is that Linear's bias and needs no caption.
- tokens: an embedding of width E, a Linear to D, then MDM's sinusoidal positions and dropout
  (the condition and layer tokens get no position, as in the reference).
- key padding hides the steps at or beyond each clip's length; the prefix tokens are never
  hidden.
- head: Linear -> GELU -> LayerNorm -> Linear (BERT's prediction head, the reference's).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from intermask.evaluator.interclip import PositionalEncoding
from intermask.interm.tokens import Vocabulary, step_padding_mask
from intermask.utils.layers import post_norm_gelu_encoder

CODEBOOK_SIZE = 512  # K per layer (section 4)
NUM_QUANTIZERS = 6  # Q = V + 1 (section 4)
MAX_STEPS = 1024  # positions of the sinusoidal table (4096 frames); the reference's has 5000


def sentence_features(text: Sequence[torch.Tensor]) -> torch.Tensor:
    """Per-token text features ``(features (B, L, D_text), eot_index (B,), ...)`` -> (B, D_text)
    the feature at each caption's end-of-text token.

    MoMask conditions on CLIP's sentence embedding, ``ln_final(x)[eot] @ text_projection``. The
    frozen encoder here keeps the features after ``ln_final`` without CLIP's projection; the
    end-of-text row is the sentence embedding before that fixed linear map, which the trainable
    condition Linear absorbs.
    """
    features, eot_index = text[0], text[1]
    if features.ndim != 3 or tuple(eot_index.shape) != (features.shape[0],):
        raise ValueError(
            "text must be (features (B, L, D_text), eot_index (B,)), got shapes "
            f"{tuple(features.shape)} and {tuple(eot_index.shape)}"
        )
    rows = torch.arange(features.shape[0], device=features.device)
    return features[rows, eot_index.to(features.device).long()]


def _init_weights(module: nn.Module) -> None:
    """N(0, 0.02) weights and zero biases for every Linear and Embedding (the reference's)."""
    if isinstance(module, nn.Linear | nn.Embedding):
        nn.init.normal_(module.weight, mean=0.0, std=0.02)
        if isinstance(module, nn.Linear) and module.bias is not None:
            nn.init.zeros_(module.bias)


class ConditionedEncoder(nn.Module):
    """``[condition, *prefix, tokens]`` -> transformer -> (B, T', D) outputs at the tokens.

    Args:
        input_dim: E, width of the token embeddings it is given.
        width, depth, heads, ff, dropout: the transformer encoder (D 384, 6 layers, 6 heads, FF
            1024, dropout 0.2 in MoMask).
        text_dim: D_text, width of the sentence feature.
        max_steps: longest token sequence the position table covers.
    """

    def __init__(
        self,
        *,
        input_dim: int,
        width: int,
        depth: int,
        heads: int,
        ff: int,
        dropout: float,
        text_dim: int,
        max_steps: int,
    ) -> None:
        super().__init__()
        self.text_dim = text_dim
        self.input_projection = nn.Linear(input_dim, width)
        # MDM's encoding (sin on even, cos on odd channels, then dropout): MoMask's
        self.positions = PositionalEncoding(dim=width, max_len=max_steps, dropout=dropout)
        self.condition_projection = nn.Linear(text_dim, width)
        self.encoder = post_norm_gelu_encoder(
            width=width, layers=depth, heads=heads, ff=ff, dropout=dropout
        )

    def forward(
        self,
        x: torch.Tensor,
        text: torch.Tensor,
        lengths_in_steps: torch.Tensor,
        drop_condition: torch.Tensor | None = None,
        prefix: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """x (B, T', E) token embeddings, text (B, D_text) sentence features, (B,) lengths,
        drop_condition (B,) bool (True: the null condition), prefix (B, P, D) tokens placed
        after the condition -> (B, T', D)."""
        batch, steps = x.shape[:2]
        if tuple(text.shape) != (batch, self.text_dim):
            raise ValueError(
                f"text must be (B, D_text) = {(batch, self.text_dim)} sentence features, got "
                f"{tuple(text.shape)}"
            )
        if drop_condition is not None:
            text = text.masked_fill(drop_condition.to(text.device)[:, None], 0.0)
        parts = [self.condition_projection(text)[:, None]]  # (B, 1, D)
        if prefix is not None:
            parts.append(prefix)
        parts.append(self.positions(self.input_projection(x)))
        sequence = torch.cat(parts, dim=1)  # (B, P + 1 + T', D)
        padding = step_padding_mask(lengths_in_steps.to(x.device), steps)  # (B, T')
        prefix_keys = padding.new_zeros(batch, sequence.shape[1] - steps)
        key_padding = torch.cat([prefix_keys, padding], dim=1)
        return self.encoder(sequence, src_key_padding_mask=key_padding)[:, -steps:]


class OutputHead(nn.Module):
    """(B, T', D) -> (B, T', out_features): Linear -> GELU -> LayerNorm -> Linear."""

    def __init__(self, *, width: int, out_features: int) -> None:
        super().__init__()
        self.dense = nn.Linear(width, width)
        self.activation = nn.GELU()
        self.norm = nn.LayerNorm(width, eps=1e-12)  # BERT's (and the reference's) epsilon
        self.out = nn.Linear(width, out_features)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(self.norm(self.activation(self.dense(x))))


def _check_tokens(tokens: torch.Tensor, low: int, high: int, what: str) -> None:
    if bool(((tokens < low) | (tokens > high)).any()):
        raise ValueError(
            f"{what} must lie in [{low}, {high}], got values in "
            f"[{int(tokens.min())}, {int(tokens.max())}]"
        )


class MaskedTransformer(nn.Module):
    """Text-conditioned masked-token model of the base layer (section 3.2).

    Vocabulary: the K codes, [MASK] = K, [PAD] = K + 1 (:class:`Vocabulary` ids; no [SEP]).
    Defaults are the paper's sizes (section 4), the unstated ones the reference code's.

    Args:
        codebook_size: K codes of the base layer (512).
        code_dim: E, width of the learned token embedding before its projection (512, the
            reference's: the RVQ code width).
        width, depth, heads, ff, dropout: the transformer (384, 6, 6, 1024, 0.2).
        text_dim: D_text, sentence-feature width (512 for CLIP ViT-B/32).
        max_steps: longest token sequence.
    """

    def __init__(
        self,
        *,
        codebook_size: int = CODEBOOK_SIZE,
        code_dim: int = 512,
        width: int = 384,
        depth: int = 6,
        heads: int = 6,
        ff: int = 1024,
        dropout: float = 0.2,
        text_dim: int = 512,
        max_steps: int = MAX_STEPS,
    ) -> None:
        super().__init__()
        if codebook_size < 2:
            raise ValueError(f"codebook_size must be >= 2, got {codebook_size}")
        self.vocabulary = Vocabulary(codebook_size)
        self.token_embedding = nn.Embedding(codebook_size + 2, code_dim)  # codes, [MASK], [PAD]
        self.backbone = ConditionedEncoder(
            input_dim=code_dim,
            width=width,
            depth=depth,
            heads=heads,
            ff=ff,
            dropout=dropout,
            text_dim=text_dim,
            max_steps=max_steps,
        )
        self.head = OutputHead(width=width, out_features=codebook_size)
        self.apply(_init_weights)

    @property
    def codebook_size(self) -> int:
        return self.vocabulary.codebook_size

    @property
    def text_dim(self) -> int:
        return self.backbone.text_dim

    def forward(
        self,
        tokens: torch.Tensor,
        text: torch.Tensor,
        lengths_in_steps: torch.Tensor,
        drop_condition: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(B, T') tokens (codes, [MASK], [PAD] or -1), (B, D_text) sentence features, (B,)
        lengths in steps, (B,) bool condition drops -> (B, T', K) logits.

        Steps at or beyond a length, and -1 entries, are read as [PAD].
        """
        if tokens.ndim != 2:
            raise ValueError(f"tokens must be (B, T'), got {tuple(tokens.shape)}")
        _check_tokens(tokens, -1, self.vocabulary.pad_id, "tokens (-1, codes, [MASK], [PAD])")
        padded = (tokens < 0) | step_padding_mask(lengths_in_steps, tokens.shape[1]).to(
            tokens.device
        )
        ids = tokens.long().masked_fill(padded, self.vocabulary.pad_id)
        hidden = self.backbone(self.token_embedding(ids), text, lengths_in_steps, drop_condition)
        return self.head(hidden)


class ResidualTransformer(nn.Module):
    """Predicts residual layer j in 1..Q-1 from layers 0..j-1, text and j (section 3.3).

    Input: the sum over layers i < j of ``table_i[t^i]`` (one (K, E) code table per layer; steps
    beyond a length contribute zero), projected to D; a learned layer embedding (row j - 1) is a
    token after the condition, as in the reference. Output: the head maps to E and the logits of
    layer j are the dot products with ``output_table(j)``, plus a per-layer bias.

    Weight tie (``share_weights``): the paper shares "the j-th prediction layer and the (j+1)-th
    motion token embedding layer", counting prediction layers from layer 1 and embedding layers
    from layer 0; both then belong to token layer j. So one table per layer i, ``tables[i]``,
    embeds layer i's codes as input (i = 0..Q-2) and scores them as output (i = 1..Q-1): tables
    1..Q-2 serve both, table 0 is input-only and table Q-1 output-only (the pairs the reference
    code ties). Without sharing, ``head_tables[j - 1]`` is the output table of layer j.

    Args:
        codebook_size: K codes per layer (512).
        num_quantizers: Q, layers of the residual VQ (6).
        code_dim: E, width of the code tables (512, the reference's).
        width, depth, heads, ff, dropout, text_dim, max_steps: as :class:`MaskedTransformer`.
        share_weights: tie input and output tables (the paper's model).
    """

    def __init__(
        self,
        *,
        codebook_size: int = CODEBOOK_SIZE,
        num_quantizers: int = NUM_QUANTIZERS,
        code_dim: int = 512,
        width: int = 384,
        depth: int = 6,
        heads: int = 6,
        ff: int = 1024,
        dropout: float = 0.2,
        text_dim: int = 512,
        max_steps: int = MAX_STEPS,
        share_weights: bool = True,
    ) -> None:
        super().__init__()
        if num_quantizers < 2:
            raise ValueError(
                "num_quantizers must be >= 2 (a base layer and a residual one), got "
                f"{num_quantizers}"
            )
        if codebook_size < 2:
            raise ValueError(f"codebook_size must be >= 2, got {codebook_size}")
        self.codebook_size, self.num_quantizers = codebook_size, num_quantizers
        self.share_weights = share_weights

        def table() -> nn.Parameter:
            return nn.Parameter(torch.randn(codebook_size, code_dim) * 0.02)

        self.tables = nn.ParameterList(
            table() for _ in range(num_quantizers if share_weights else num_quantizers - 1)
        )
        self.head_tables = (
            None if share_weights else nn.ParameterList(table() for _ in range(num_quantizers - 1))
        )
        self.head_bias = nn.Parameter(torch.zeros(num_quantizers - 1, codebook_size))
        self.layer_embedding = nn.Embedding(num_quantizers - 1, width)
        self.backbone = ConditionedEncoder(
            input_dim=code_dim,
            width=width,
            depth=depth,
            heads=heads,
            ff=ff,
            dropout=dropout,
            text_dim=text_dim,
            max_steps=max_steps,
        )
        self.head = OutputHead(width=width, out_features=code_dim)
        self.apply(_init_weights)

    @property
    def text_dim(self) -> int:
        return self.backbone.text_dim

    def input_table(self, layer: int) -> nn.Parameter:
        """(K, E) table embedding the codes of ``layer`` (0..Q-2) as input."""
        if not 0 <= layer <= self.num_quantizers - 2:
            raise ValueError(f"input layers are 0..{self.num_quantizers - 2}, got {layer}")
        return self.tables[layer]

    def output_table(self, layer: int) -> nn.Parameter:
        """(K, E) table scoring the codes of ``layer`` (1..Q-1) as output."""
        if not 1 <= layer <= self.num_quantizers - 1:
            raise ValueError(f"predicted layers are 1..{self.num_quantizers - 1}, got {layer}")
        return self.tables[layer] if self.head_tables is None else self.head_tables[layer - 1]

    def _layers(self, layer: torch.Tensor | int, batch: int, device: torch.device) -> torch.Tensor:
        layer = torch.as_tensor(layer, device=device).long()
        layer = layer.expand(batch) if layer.ndim == 0 else layer
        if tuple(layer.shape) != (batch,):
            raise ValueError(f"layer must be an int or (B,) = ({batch},), got {tuple(layer.shape)}")
        if bool(((layer < 1) | (layer > self.num_quantizers - 1)).any()):
            raise ValueError(
                f"layer must lie in [1, {self.num_quantizers - 1}], got {layer.tolist()}"
            )
        return layer

    def history(
        self, tokens: torch.Tensor, layer: torch.Tensor | int, lengths_in_steps: torch.Tensor
    ) -> torch.Tensor:
        """(B, Q', T') codes of layers 0..Q'-1 (-1 on padding), (B,) or int predicted layer j,
        (B,) lengths -> (B, T', E) the sum of ``input_table(i)[tokens[:, i]]`` over i < j.

        Layers at or above j are ignored; every layer below j must hold codes inside the clip.
        """
        if tokens.ndim != 3:
            raise ValueError(f"tokens must be (B, Q', T'), got {tuple(tokens.shape)}")
        batch, given, steps = tokens.shape
        layer = self._layers(layer, batch, tokens.device)
        if given < int(layer.max()):
            raise ValueError(
                f"predicting layer {int(layer.max())} needs the codes of the layers below it, "
                f"tokens hold {given} layer(s)"
            )
        _check_tokens(tokens, -1, self.codebook_size - 1, "tokens (-1 or codes)")
        used = min(given, self.num_quantizers - 1)
        inside = ~step_padding_mask(lengths_in_steps.to(tokens.device), steps)  # (B, T')
        below = torch.arange(used, device=tokens.device)[None, :] < layer[:, None]  # (B, Q'')
        needed = below[:, :, None] & inside[:, None, :]  # (B, Q'', T')
        codes = tokens[:, :used].long()
        if bool((needed & (codes < 0)).any()):
            raise ValueError(
                "tokens of the layers below the predicted one must be codes inside each clip's "
                "length, got -1 there"
            )
        embedded = torch.stack(
            [
                nn.functional.embedding(codes[:, i].clamp_min(0), self.input_table(i))
                for i in range(used)
            ],
            dim=1,
        )  # (B, Q'', T', E)
        return (embedded * needed[..., None].to(embedded.dtype)).sum(dim=1)

    def forward(
        self,
        tokens: torch.Tensor,
        text: torch.Tensor,
        lengths_in_steps: torch.Tensor,
        drop_condition: torch.Tensor | None = None,
        *,
        layer: torch.Tensor | int,
    ) -> torch.Tensor:
        """(B, Q', T') codes (layers 0..j-1 at least), (B, D_text) sentence features, (B,)
        lengths, (B,) bool condition drops, (B,) or int layer j -> (B, T', K) logits of
        layer j."""
        layer = self._layers(layer, tokens.shape[0], tokens.device)
        x = self.history(tokens, layer, lengths_in_steps)
        prefix = self.layer_embedding(layer - 1)[:, None]  # (B, 1, D)
        hidden = self.head(self.backbone(x, text, lengths_in_steps, drop_condition, prefix))
        tables = torch.stack([self.output_table(j) for j in range(1, self.num_quantizers)])
        weights = tables[layer - 1]  # (B, K, E)
        return torch.einsum("bte,bke->btk", hidden, weights) + self.head_bias[layer - 1][:, None]
