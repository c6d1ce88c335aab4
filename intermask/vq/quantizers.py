"""Vector quantizers: an EMA codebook with dead-code reset, and MoMask's residual stack of them.

Inputs are latent grids ``(B, D, H, W)`` (D latent width, H rows, W token steps); indices come
back as ``(B, H, W)`` per layer. Codebooks are buffers updated by exponential moving averages
(van den Oord et al. 2017, appendix), never by the optimizer.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.distributed as dist
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from intermask.utils.distributed import all_reduce_sum, gather_rows, process_group


class QuantizerOutput(NamedTuple):
    quantized: torch.Tensor  # (B, D, H, W), straight-through: gradients flow to the encoder output
    indices: torch.Tensor  # (B, H, W) int64
    commit_loss: torch.Tensor  # () MSE(x, sg(q)), unweighted
    perplexity: torch.Tensor  # () exp(entropy) of this batch's code histogram
    dead_codes: torch.Tensor  # () codes re-initialised by this training step (0 in eval mode)


class ResidualQuantizerOutput(NamedTuple):
    quantized: torch.Tensor  # (B, D, H, W), sum of the kept layers, straight-through
    indices: torch.Tensor  # (B, Q, H, W) int64; -1 for layers removed by quantization dropout
    commit_loss: torch.Tensor  # () mean over kept layers (same scale as a single VQ)
    perplexity: torch.Tensor  # (Q,) per layer (0 for dropped layers)
    dead_codes: torch.Tensor  # (Q,) per layer


def _perplexity(indices: torch.Tensor, codebook_size: int) -> torch.Tensor:
    counts = torch.bincount(indices.flatten(), minlength=codebook_size).float()
    probabilities = counts / counts.sum().clamp_min(1.0)
    return torch.exp(-(probabilities * torch.log(probabilities.clamp_min(1e-10))).sum())


RESETS = ("restart", "reference", "farthest")  # dead-code rules of EMAQuantizer


class EMAQuantizer(nn.Module):
    """Nearest-code quantizer with an EMA-updated codebook.

    Args:
        codebook_size: K codes.
        dim: D, code width.
        decay: EMA decay of code counts and sums (paper: 0.99).
        reset_threshold: codes whose EMA count falls below it are re-initialised from random
            encoder outputs of the current batch (reference: 1.0).
        stochastic_temperature: when set, training picks codes by Gumbel-max sampling of
            -distance / temperature (the reference's choice, 0.5) instead of the nearest code;
            evaluation always uses the nearest code.
        eps: Laplace smoothing of the counts.
        reset: ``"restart"`` (default): a dead code restarts from a random encoder output with
            count 1, and codes are EMA sums over Laplace-smoothed counts. ``"reference"``: the
            reference code's rule: codes are EMA sums over raw counts, and a code whose count
            is below ``reset_threshold`` is overwritten by a random encoder output at every
            step while its EMA statistics are left to recover (docs/fidelity.md).
            ``"farthest"``: as ``"restart"``, but a dead code restarts from the encoder output
            that its codebook serves worst (the largest distance to the nearest code in the
            global batch), the next dead code from the next worst, and so on: the latents a
            rare pose leaves far from every code get codes of their own instead of random
            ones. On the demo it lowered the tokenizer's and its generators' FID
            (docs/decisions.md: model.net.quantizer.reset).
    """

    def __init__(
        self,
        *,
        codebook_size: int = 1024,
        dim: int = 512,
        decay: float = 0.99,
        reset_threshold: float = 1.0,
        stochastic_temperature: float | None = None,
        eps: float = 1e-5,
        reset: str = "restart",
    ) -> None:
        super().__init__()
        if not 0.0 < decay < 1.0:
            raise ValueError(f"decay must be in (0, 1), got {decay}")
        if reset not in RESETS:
            raise ValueError(f"reset must be one of {RESETS}, got {reset!r}")
        self.reset = reset
        if stochastic_temperature is not None and stochastic_temperature <= 0:
            raise ValueError(
                f"stochastic_temperature must be positive or None, got {stochastic_temperature}"
            )
        self.codebook_size, self.dim, self.decay = codebook_size, dim, decay
        self.reset_threshold, self.stochastic_temperature, self.eps = (
            reset_threshold,
            stochastic_temperature,
            eps,
        )
        self.register_buffer("codebook", torch.zeros(codebook_size, dim))
        self.register_buffer("ema_count", torch.zeros(codebook_size))
        self.register_buffer("ema_sum", torch.zeros(codebook_size, dim))
        self.register_buffer("initialized", torch.tensor(False))

    def forward(
        self, x: torch.Tensor, *, generator: torch.Generator | None = None
    ) -> QuantizerOutput:
        """(B, D, H, W) -> QuantizerOutput; updates the codebook in training mode.

        ``generator`` draws the rows that initialise and reset codes (and the Gumbel noise);
        None uses torch's global generator. Runs in float32 even under autocast: nearest-code
        search and EMA statistics in bf16 would pick wrong codes and drift.
        """
        with torch.autocast(device_type=x.device.type, enabled=False):
            return self._quantize(x.float(), generator)

    def _quantize(self, x: torch.Tensor, generator: torch.Generator | None) -> QuantizerOutput:
        batch, _, height, width = x.shape
        flat = rearrange(x, "b d h w -> (b h w) d")
        if self.training and not bool(self.initialized):
            self._initialise(flat.detach(), generator)
        indices = self._assign(flat.detach(), generator)
        dead = torch.zeros((), dtype=torch.long, device=x.device)
        if self.training:
            dead = self._ema_update(flat.detach().float(), indices, generator)
        quantized_flat = F.embedding(indices, self.codebook)
        commit_loss = F.mse_loss(flat, quantized_flat.detach())
        quantized_flat = flat + (quantized_flat - flat).detach()
        quantized = rearrange(quantized_flat, "(b h w) d -> b d h w", b=batch, h=height, w=width)
        indices = rearrange(indices, "(b h w) -> b h w", b=batch, h=height, w=width)
        return QuantizerOutput(
            quantized, indices, commit_loss, _perplexity(indices, self.codebook_size), dead
        )

    @torch.no_grad()
    def nearest(self, x: torch.Tensor) -> torch.Tensor:
        """(B, D, H, W) -> (B, H, W) nearest-code indices; never updates the codebook."""
        batch, _, height, width = x.shape
        flat = rearrange(x, "b d h w -> (b h w) d")
        return rearrange(
            self._distances(flat).argmin(dim=-1), "(b h w) -> b h w", b=batch, h=height, w=width
        )

    def lookup(self, indices: torch.Tensor) -> torch.Tensor:
        """(B, H, W) code indices -> (B, D, H, W) code vectors."""
        return rearrange(F.embedding(indices, self.codebook), "b h w d -> b d h w")

    def _distances(self, flat: torch.Tensor) -> torch.Tensor:
        """(N, D) -> (N, K) squared Euclidean distances to every code."""
        codebook = self.codebook.to(flat.dtype)
        return (
            flat.pow(2).sum(-1, keepdim=True)
            - 2 * flat @ codebook.T
            + codebook.pow(2).sum(-1)[None]
        )

    @torch.no_grad()
    def _assign(self, flat: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """(N, D) -> (N,) code indices: Gumbel-max sampling in training when configured, else nearest."""
        distances = self._distances(flat)
        if self.training and self.stochastic_temperature is not None:
            gumbel = -torch.log(
                -torch.log(
                    torch.rand(
                        distances.shape,
                        generator=generator,
                        device=distances.device,
                        dtype=distances.dtype,
                    ).clamp_min(1e-10)
                ).clamp_min(1e-10)
            )
            return torch.argmax(-distances / self.stochastic_temperature + gumbel, dim=-1)
        return torch.argmin(distances, dim=-1)

    @torch.no_grad()
    def _random_rows(self, flat: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        """One encoder output of the global batch (all ranks' rows, gathered) per code, drawn at
        random, with repetition only when the batch is small: the same rows on every rank and
        as in one process with the global batch."""
        flat, count = gather_rows(flat), self.codebook_size
        if flat.shape[0] >= count:
            order = torch.randperm(flat.shape[0], generator=generator, device=flat.device)
            rows = flat[order[:count]]
        else:
            draw = torch.randint(flat.shape[0], (count,), generator=generator, device=flat.device)
            rows = flat[draw]
        if process_group()[1] > 1:  # the ranks drew the same rows; rank 0's copy makes it exact
            dist.broadcast(rows, src=0)
        return rows

    @torch.no_grad()
    def _farthest_rows(
        self, flat: torch.Tensor, errors: torch.Tensor, dead: torch.Tensor
    ) -> torch.Tensor:
        """(K, D): the dead codes, in index order, get the global batch's encoder outputs in
        order of decreasing quantization error (``errors`` (N,), -inf for rows that count for
        nothing), cycling when there are more dead codes than such rows; live codes' rows are
        unused. The same rows on every rank: the gathered batch is sorted the same everywhere."""
        flat, errors = gather_rows(flat), gather_rows(errors)
        order = torch.argsort(errors, descending=True, stable=True)
        order = order[: max(int(torch.isfinite(errors).sum()), 1)]  # the -inf rows sort last
        slots = torch.cumsum(dead.long(), 0) - 1  # the rank of each dead code among the dead
        return flat[order[slots.clamp_min(0) % order.numel()]]

    @torch.no_grad()
    def _initialise(self, flat: torch.Tensor, generator: torch.Generator | None) -> None:
        rows = self._random_rows(flat.float(), generator)
        self.codebook.copy_(rows)
        self.ema_sum.copy_(rows)
        self.ema_count.fill_(1.0)
        self.initialized.fill_(True)

    @torch.no_grad()
    def _ema_update(
        self, flat: torch.Tensor, indices: torch.Tensor, generator: torch.Generator | None
    ) -> torch.Tensor:
        """EMA step of counts, sums and codes; returns how many dead codes were reset.

        Rows with a NaN or infinity (a corrupt batch) count for nothing: a training step that
        is then skipped (``non_finite_loss=skip``) leaves the codebook as it was, without a sync.
        """
        valid = torch.isfinite(flat).all(dim=-1)
        flat = torch.where(valid[:, None], flat, torch.zeros_like(flat))
        counts = all_reduce_sum(
            torch.bincount(indices, weights=valid.float(), minlength=self.codebook_size).float()
        )
        sums = all_reduce_sum(torch.zeros_like(self.ema_sum).index_add_(0, indices, flat))
        self.ema_count.mul_(self.decay).add_(counts, alpha=1 - self.decay)
        self.ema_sum.mul_(self.decay).add_(sums, alpha=1 - self.decay)
        if self.reset == "reference":
            return self._reference_update(flat, generator)
        dead = self.ema_count < self.reset_threshold
        revive = bool(dead.any())
        if revive and self.reset == "farthest":
            # each row's quantization error under the codebook it was assigned with (not yet
            # updated), computed only on the steps where a code dies
            errors = (flat - self.codebook[indices]).pow(2).sum(-1)
            replacement = self._farthest_rows(flat, torch.where(valid, errors, -torch.inf), dead)
        elif revive:
            replacement = self._random_rows(flat, generator)
        total = self.ema_count.sum()
        smoothed = (self.ema_count + self.eps) / (total + self.codebook_size * self.eps) * total
        self.codebook.copy_(self.ema_sum / smoothed[:, None])
        if revive:
            self.codebook[dead] = replacement[dead]
            self.ema_sum[dead] = replacement[dead]
            self.ema_count[dead] = 1.0
        return dead.sum()

    @torch.no_grad()
    def _reference_update(
        self, flat: torch.Tensor, generator: torch.Generator | None
    ) -> torch.Tensor:
        """The reference's codebook after the EMA step: sum / count where the count reaches the
        threshold, a fresh random encoder output elsewhere (statistics untouched)."""
        used = self.ema_count >= self.reset_threshold
        replacement = self._random_rows(flat, generator)
        means = self.ema_sum / self.ema_count.clamp_min(torch.finfo(flat.dtype).tiny)[:, None]
        self.codebook.copy_(torch.where(used[:, None], means, replacement))
        return (~used).sum()


class ResidualQuantizer(nn.Module):
    """MoMask residual VQ: layer q quantizes what layers 0..q-1 left; the latent is their sum.

    ``num_quantizers=1`` is the plain VQ. With probability ``dropout_prob`` a training batch keeps
    only layers 0..k for a random k (layer 0 always kept), so coarse layers learn to stand alone.
    """

    def __init__(
        self,
        *,
        num_quantizers: int = 1,
        codebook_size: int = 1024,
        dim: int = 512,
        dropout_prob: float = 0.0,
        decay: float = 0.99,
        reset_threshold: float = 1.0,
        stochastic_temperature: float | None = None,
        reset: str = "restart",
    ) -> None:
        super().__init__()
        if num_quantizers < 1:
            raise ValueError(f"num_quantizers must be >= 1, got {num_quantizers}")
        if not 0.0 <= dropout_prob <= 1.0:
            raise ValueError(f"dropout_prob must be in [0, 1], got {dropout_prob}")
        self.dropout_prob = dropout_prob
        self.layers = nn.ModuleList(
            EMAQuantizer(
                codebook_size=codebook_size,
                dim=dim,
                decay=decay,
                reset_threshold=reset_threshold,
                stochastic_temperature=stochastic_temperature,
                reset=reset,
            )
            for _ in range(num_quantizers)
        )

    @property
    def num_quantizers(self) -> int:
        return len(self.layers)

    @property
    def codebook_size(self) -> int:
        """Codes per layer (every layer has the same number)."""
        return self.layers[0].codebook_size

    def forward(
        self,
        x: torch.Tensor,
        active_layers: int | None = None,
        *,
        generator: torch.Generator | None = None,
    ) -> ResidualQuantizerOutput:
        """(B, D, H, W) -> ResidualQuantizerOutput. ``active_layers`` forces the number of layers
        used; ``generator`` draws quantization dropout and the layers' code resets."""
        kept = active_layers or self.num_quantizers
        if (
            active_layers is None
            and self.training
            and self.num_quantizers > 1
            and self.dropout_prob > 0
        ):
            if torch.rand((), generator=generator, device=x.device) < self.dropout_prob:
                kept = int(
                    torch.randint(
                        1, self.num_quantizers + 1, (), generator=generator, device=x.device
                    )
                )
        residual, quantized = x, torch.zeros_like(x)
        batch, _, height, width = x.shape
        indices = x.new_full((batch, self.num_quantizers, height, width), -1, dtype=torch.long)
        commit = x.new_zeros(())
        perplexity = x.new_zeros(self.num_quantizers)
        dead = torch.zeros(self.num_quantizers, dtype=torch.long, device=x.device)
        for layer_index, layer in enumerate(self.layers[:kept]):
            out = layer(residual, generator=generator)
            # quantize the residual, but let the straight-through gradient reach x unchanged
            quantized = quantized + out.quantized
            residual = residual - out.quantized.detach()
            indices[:, layer_index] = out.indices
            commit = commit + out.commit_loss
            perplexity[layer_index], dead[layer_index] = out.perplexity, out.dead_codes
        quantized = x + (quantized - x).detach()
        return ResidualQuantizerOutput(quantized, indices, commit / kept, perplexity, dead)

    @torch.no_grad()
    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """(B, D, H, W) -> (B, Q, H, W) nearest-code indices of every layer; no codebook update."""
        residual, indices = x, []
        for layer in self.layers:
            layer_indices = layer.nearest(residual)
            residual = residual - layer.lookup(layer_indices).to(residual.dtype)
            indices.append(layer_indices)
        return torch.stack(indices, dim=1)

    def lookup(self, indices: torch.Tensor) -> torch.Tensor:
        """(B, Q', H, W) indices of the first Q' <= Q layers (-1 = unused) -> (B, D, H, W) summed codes."""
        if indices.shape[1] > self.num_quantizers:
            raise ValueError(
                f"indices have {indices.shape[1]} layers, the quantizer has {self.num_quantizers}"
            )
        total = None
        for layer_index in range(indices.shape[1]):
            layer_indices = indices[:, layer_index]
            codes = self.layers[layer_index].lookup(layer_indices.clamp_min(0))
            codes = codes * (layer_indices >= 0)[:, None].to(codes.dtype)
            total = codes if total is None else total + codes
        return total
