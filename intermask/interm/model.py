"""The Inter-M Transformer: two persons' token maps + text -> logits over the codebook.

Input process (section 3.2.2): learned token embedding (K + 3 entries, width 512) -> Linear to
the model width D -> 2D sinusoidal encoding per person -> dropout. Then ``depth`` Inter-M
blocks conditioned on ``c`` through AdaLN-Zero, and the output process (section 3.2.3): Linear
-> GELU -> LayerNorm -> AdaLN shift/scale -> Linear to the K code logits.

Text: frozen CLIP ViT-L/14@336px per-token features (computed outside this module) pass a
trainable 2-layer TransformerEncoder and a LayerNorm; the feature at the end-of-text token,
projected to D, is ``c``. It enters the network only through AdaLN.

Modeling (Table 3, appendix E): ``collaborative`` (the paper's model) runs both persons through
every block together; ``alternative`` (the ablation) predicts one person at a time from its own
stream, conditioned on the other person's input embeddings through cross attention only.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from einops import rearrange
from torch import nn
from torch.nn import functional as F

from intermask.interm.attention import MultiHeadAttention
from intermask.interm.blocks import AdaLNModulation, InterMBlock, adaptive_norm, modulate
from intermask.interm.position import add_grid_encoding
from intermask.interm.tokens import Vocabulary, build_sequence, sequence_padding_mask, split_persons
from intermask.text.clip_encoder import TextFeatures
from intermask.utils.layers import post_norm_gelu_encoder

MODELINGS = ("collaborative", "alternative")  # Table 3: ours vs the appendix E ablation


class InterMOutput(NamedTuple):
    logits_a: torch.Tensor  # (B, rows, T', K)
    logits_b: torch.Tensor  # (B, rows, T', K)


class OutputHead(nn.Module):
    """(B, S, D) -> (B, S, K): Linear -> GELU -> LayerNorm -> AdaLN shift/scale -> Linear."""

    def __init__(self, *, width: int, codebook_size: int) -> None:
        super().__init__()
        self.dense = nn.Linear(width, width)
        self.activation = nn.GELU()
        self.norm = adaptive_norm(width)
        self.modulation = AdaLNModulation(width=width, chunks=2)
        self.logits = nn.Linear(width, codebook_size)

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        shift, scale = self.modulation(c)
        return self.logits(modulate(self.norm(self.activation(self.dense(x))), shift, scale))


def _normal_init(module: nn.Module) -> None:
    if isinstance(module, nn.Linear | nn.Embedding):
        nn.init.normal_(module.weight, mean=0.0, std=0.02)
        if isinstance(module, nn.Linear) and module.bias is not None:
            nn.init.zeros_(module.bias)


def _check_architecture(
    *, modeling: str, width: int, use_cross_attention: bool, cross_context_quirk: bool
) -> None:
    """Reject the :class:`InterMTransformer` settings that do not make a model: an unknown
    modeling, alternative modeling without cross attention or with the cross-context quirk, a
    width the 2D positional encoding cannot split."""
    if modeling not in MODELINGS:
        raise ValueError(f"modeling must be one of {MODELINGS}, got {modeling!r}")
    if modeling == "alternative" and not use_cross_attention:
        raise ValueError(
            "modeling='alternative' conditions the predicted person on the other person only "
            "through cross attention; it cannot be combined with use_cross_attention=False"
        )
    if modeling == "alternative" and cross_context_quirk:
        raise ValueError(
            "cross_context_quirk has no effect with modeling='alternative' (the context is "
            "always the other person's input embeddings); leave it False"
        )
    if width % 4:
        raise ValueError(
            f"width must be divisible by 4 for the 2D positional encoding, got {width}"
        )


class InterMTransformer(nn.Module):
    """Collaborative masked-token model of two persons (InterMask section 3.2).

    Defaults are the paper configuration (appendix C.1; the unstated sizes from the reference).

    Args:
        codebook_size: K motion codes; the vocabulary adds [MASK], [PAD], [SEP].
        width: D, transformer width (384).
        heads: attention heads (6).
        depth: Inter-M blocks (6).
        ff: FFN hidden width (1024).
        dropout: dropout in blocks and after the input process (0.2).
        token_embed_dim: width of the learned token embedding before its projection (512).
        text_dim: CLIP token feature width (768 for ViT-L/14@336px).
        text_layers, text_heads, text_ff, text_dropout: the trainable text encoder (2, 8, 2048,
            0.1). Post-norm (``norm_first=False``) with GELU as in the reference, followed by
            its final LayerNorm.
        rows: body-part rows of the token map (5; 1 for the 1D-token ablation).
        use_self_attention, use_spatio_temporal_attention, use_cross_attention: Table 3
            ablations.
        double_residual_quirk, cross_context_quirk: reproduce reference-code behaviour, see
            :class:`~intermask.interm.blocks.InterMBlock`.
        text_attends_padding: the text layers attend to all L CLIP positions, the padding after
            end-of-text included, as the reference does (default: padding is masked out).
        code_dim: None (the paper: a code enters only through its learned embedding) or the
            width of the VQ-VAE's code vectors: each motion code's input then also carries its
            codebook vector, through a learned projection (:meth:`set_code_vectors`;
            docs/decisions.md: model.code_vectors). The vectors are a buffer, saved with the
            weights.
        modeling: ``"collaborative"`` (section 3.2) or ``"alternative"`` (appendix E, Table 3).
            Alternative modeling builds the same layers (same parameter count) but updates only
            the predicted person's embeddings in the blocks; the other person's input
            embeddings condition it through cross attention, so it needs
            ``use_cross_attention`` and has no use for ``cross_context_quirk``.
    """

    def __init__(
        self,
        *,
        codebook_size: int = 1024,
        width: int = 384,
        heads: int = 6,
        depth: int = 6,
        ff: int = 1024,
        dropout: float = 0.2,
        token_embed_dim: int = 512,
        text_dim: int = 768,
        text_layers: int = 2,
        text_heads: int = 8,
        text_ff: int = 2048,
        text_dropout: float = 0.1,
        rows: int = 5,
        use_self_attention: bool = True,
        use_spatio_temporal_attention: bool = True,
        use_cross_attention: bool = True,
        double_residual_quirk: bool = False,
        cross_context_quirk: bool = False,
        text_attends_padding: bool = False,
        modeling: str = "collaborative",
        code_dim: int | None = None,
    ) -> None:
        super().__init__()
        _check_architecture(
            modeling=modeling,
            width=width,
            use_cross_attention=use_cross_attention,
            cross_context_quirk=cross_context_quirk,
        )
        self.vocabulary = Vocabulary(codebook_size)
        self.codebook_size, self.rows, self.text_dim = codebook_size, rows, text_dim
        self.modeling, self.text_attends_padding = modeling, text_attends_padding

        self.token_embedding = nn.Embedding(self.vocabulary.size, token_embed_dim)
        self.token_projection = nn.Linear(token_embed_dim, width)
        self.code_dim = code_dim
        self.code_projection: nn.Linear | None = None
        if code_dim is not None:
            if code_dim < 1:
                raise ValueError(f"code_dim must be None or positive, got {code_dim}")
            # rows of [MASK], [PAD] and [SEP] stay zero: those carry their learned embedding only
            self.register_buffer("code_vectors", torch.zeros(self.vocabulary.size, code_dim))
            self.code_projection = nn.Linear(code_dim, width)
        self.input_dropout = nn.Dropout(dropout)

        self.text_encoder = post_norm_gelu_encoder(
            width=text_dim, layers=text_layers, heads=text_heads, ff=text_ff, dropout=text_dropout
        )
        self.text_norm = nn.LayerNorm(text_dim)
        # A dropped condition is the projection of a zero text feature, i.e. this layer's
        # learned bias: a learned null condition without an extra parameter (the reference
        # zeroes the CLIP feature the same way).
        self.condition_projection = nn.Linear(text_dim, width)

        self.blocks = nn.ModuleList(
            InterMBlock(
                width=width,
                heads=heads,
                ff=ff,
                dropout=dropout,
                use_self_attention=use_self_attention,
                use_spatio_temporal_attention=use_spatio_temporal_attention,
                use_cross_attention=use_cross_attention,
                double_residual_quirk=double_residual_quirk,
                cross_context_quirk=cross_context_quirk,
            )
            for _ in range(depth)
        )
        self.head = OutputHead(width=width, codebook_size=codebook_size)
        self._init_weights()

    def _init_weights(self) -> None:
        # Reference: N(0, 0.02) for every Linear/Embedding outside the text encoder (which keeps
        # PyTorch's defaults), attention in-projections Xavier, AdaLN regressors zero.
        for part in (self.token_embedding, self.token_projection, self.condition_projection):
            part.apply(_normal_init)
        if self.code_projection is not None:
            self.code_projection.apply(_normal_init)
        self.blocks.apply(_normal_init)
        self.head.apply(_normal_init)
        for module in self.modules():
            if isinstance(module, AdaLNModulation | MultiHeadAttention):
                module.reset_parameters()

    @torch.no_grad()
    def set_code_vectors(self, codebook: torch.Tensor) -> None:
        """Copy the VQ-VAE's ``(K, code_dim)`` codebook into the code-vector buffer, scaled to
        unit RMS (the codebook's own scale depends on its training; the projection's does not)."""
        if self.code_dim is None:
            raise ValueError("set_code_vectors needs a network built with code_dim")
        expected = (self.codebook_size, self.code_dim)
        if tuple(codebook.shape) != expected:
            raise ValueError(
                f"the codebook must be {expected} (codes x code_dim), got {tuple(codebook.shape)}"
            )
        rms = codebook.float().pow(2).mean().sqrt()
        if not bool(torch.isfinite(rms)) or float(rms) == 0.0:
            raise ValueError(f"the codebook has no usable scale (RMS {float(rms)})")
        self.code_vectors.zero_()
        self.code_vectors[: self.codebook_size] = (codebook.float() / rms).to(self.code_vectors)

    def encode_condition(
        self, text: TextFeatures | tuple, drop_condition: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Text features -> (B, D) condition ``c``; rows with ``drop_condition`` (B,) bool True
        get the null condition (classifier-free guidance)."""
        text = TextFeatures(*text)
        features, eot_index = text.features, text.eot_index
        if features.ndim != 3 or features.shape[-1] != self.text_dim:
            raise ValueError(
                f"text features must be (B, L, {self.text_dim}), got {tuple(features.shape)}"
            )
        batch = features.shape[0]
        if eot_index.shape != (batch,):
            raise ValueError(f"eot_index must be ({batch},), got {tuple(eot_index.shape)}")
        # the reference's text layers attend to all L positions, the padding after [EOT] too
        padding = None if self.text_attends_padding else text.padding_mask
        hidden = self.text_norm(self.text_encoder(features, src_key_padding_mask=padding))
        eot = hidden[torch.arange(batch, device=hidden.device), eot_index]  # (B, text_dim)
        if drop_condition is not None:
            if drop_condition.shape != (batch,):
                raise ValueError(
                    f"drop_condition must be ({batch},), got {tuple(drop_condition.shape)}"
                )
            eot = eot.masked_fill(drop_condition.bool()[:, None], 0.0)
        return self.condition_projection(eot)

    def _embed(
        self, tokens_a: torch.Tensor, tokens_b: torch.Tensor, lengths_in_steps: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Input process -> (B, 2N + 1, D) embeddings of ``[A, SEP, B]`` and their (B, 2N + 1)
        key padding mask."""
        if tokens_a.ndim != 3 or tokens_a.shape[1] != self.rows:
            raise ValueError(f"tokens must be (B, {self.rows}, T'), got {tuple(tokens_a.shape)}")
        sequence = build_sequence(
            tokens_a,
            tokens_b,
            codebook_size=self.codebook_size,
            lengths_in_steps=lengths_in_steps,
        )  # (B, 2N + 1)
        padding = sequence_padding_mask(sequence, codebook_size=self.codebook_size)
        x = self.token_projection(self.token_embedding(sequence))  # (B, 2N + 1, D)
        if self.code_projection is not None:  # project the vocabulary's table once, then look up
            x = x + F.embedding(sequence, self.code_projection(self.code_vectors))
        steps = tokens_a.shape[-1]
        return self.input_dropout(add_grid_encoding(x, rows=self.rows, steps=steps)), padding

    def _predict_one_person(
        self,
        x: torch.Tensor,
        context: torch.Tensor,
        condition: torch.Tensor,
        padding: torch.Tensor,
        context_padding: torch.Tensor,
        steps: int,
    ) -> torch.Tensor:
        """Alternative modeling: (G, N, D) predicted stream, (G, N, D) fixed context -> (G, rows,
        T', K) logits of the predicted person."""
        for block in self.blocks:
            x = block.forward_alternative(
                x, context, condition, padding, context_padding, rows=self.rows
            )
        return rearrange(self.head(x, condition), "g (r t) k -> g r t k", t=steps)

    def forward_with_condition(
        self,
        tokens_a: torch.Tensor,
        tokens_b: torch.Tensor,
        condition: torch.Tensor,
        lengths_in_steps: torch.Tensor,
    ) -> InterMOutput:
        """Like :meth:`forward` with a precomputed (B, D) condition (e.g. conditional and null
        conditions stacked for guidance)."""
        steps = tokens_a.shape[-1]
        x, padding = self._embed(tokens_a, tokens_b, lengths_in_steps)
        if self.modeling == "alternative":
            # both directions in one batch: A's stream reads B's embeddings and vice versa
            n = self.rows * steps
            a, _, b = x.split([n, 1, n], dim=1)
            pad_a, _, pad_b = padding.split([n, 1, n], dim=1)
            logits = self._predict_one_person(
                torch.cat([a, b]),
                torch.cat([b, a]),
                torch.cat([condition, condition]),
                torch.cat([pad_a, pad_b]),
                torch.cat([pad_b, pad_a]),
                steps,
            )  # (2B, rows, T', K)
            return InterMOutput(*logits.chunk(2))
        for block in self.blocks:
            x = block(x, condition, padding, rows=self.rows)
        logits = self.head(x, condition)  # (B, 2N + 1, K)
        return InterMOutput(*split_persons(logits, rows=self.rows, steps=steps))

    def forward_person(
        self,
        tokens: torch.Tensor,
        partner_tokens: torch.Tensor,
        condition: torch.Tensor,
        lengths_in_steps: torch.Tensor,
    ) -> torch.Tensor:
        """Alternative modeling only: (B, rows, T') tokens of the predicted person and of its
        partner, (B, D) condition -> (B, rows, T', K) logits of the predicted person.

        One direction of :meth:`forward_with_condition` at half its cost (alternative
        decoding predicts one person per iteration).
        """
        if self.modeling != "alternative":
            raise ValueError(
                "forward_person predicts one person (alternative modeling); this model is "
                f"{self.modeling!r}: use forward / forward_with_condition"
            )
        steps, n = tokens.shape[-1], self.rows * tokens.shape[-1]
        x, padding = self._embed(tokens, partner_tokens, lengths_in_steps)
        own, _, partner = x.split([n, 1, n], dim=1)
        own_padding, _, partner_padding = padding.split([n, 1, n], dim=1)
        return self._predict_one_person(
            own, partner, condition, own_padding, partner_padding, steps
        )

    def forward(
        self,
        tokens_a: torch.Tensor,
        tokens_b: torch.Tensor,
        text: TextFeatures | tuple,
        lengths_in_steps: torch.Tensor,
        drop_condition: torch.Tensor | None = None,
    ) -> InterMOutput:
        """Token maps (B, rows, T') of each person -> code logits (B, rows, T', K) of each.

        Tokens are codes, [MASK], [PAD] or -1; steps at or beyond ``lengths_in_steps`` (B,) are
        padding whatever they hold. ``text`` is :class:`TextFeatures` or ``(features,
        eot_index)``; ``drop_condition`` (B,) bool replaces ``c`` by the null condition.
        With ``modeling="alternative"`` each person's logits come from its own stream
        conditioned on the other person's input embeddings (both directions in one batch).
        """
        condition = self.encode_condition(text, drop_condition)
        return self.forward_with_condition(tokens_a, tokens_b, condition, lengths_in_steps)


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())
