"""Per-seed random streams drawn on the device with no host state: Philox-4x32-10 in torch integer ops.

A counter-based generator turns (key, counter) into four 32-bit words by a fixed function, so a stream
is nothing but its key and how many blocks it has used. `PhiloxStreams(seeds, purpose, device)` keeps
N streams, stream i keyed by (seed i, purpose), and its counters as one [N] int64 device tensor that
every draw advances in place. Hence:

* seed i draws exactly what seed i alone draws, whatever the other seeds of the stack are and however
  many there are (a draw for N seeds is N independent evaluations of the same function);
* the same numbers on every device (integer arithmetic only, no device generator);
* a draw reads and writes only device tensors (no `.item()`, no host-built tensors), so it can sit
  inside a captured CUDA graph: a replay draws the next numbers, because the counters moved in place.

`active` ([N] bool) draws for all seeds but advances only the active seeds' counters, so a seed that
sits a step out finds its stream where it left it.

The words are those of Random123's `philox4x32_10` (its published known-answer vectors are tested).
Few, whole-tensor operations per round: on a CPU a draw costs its operations' dispatch, not arithmetic.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

MASK32 = 0xFFFFFFFF
MULTIPLIERS = (0xD2511F53, 0xCD9E8D57)
KEY_BUMPS = (0x9E3779B9, 0xBB67AE85)
ROUNDS = 10


def round_keys(k0: torch.Tensor, k1: torch.Tensor) -> torch.Tensor:
    """The ten rounds' key words [..., ROUNDS, 2] of key (k0, k1) (Philox's Weyl sequence)."""
    bumps = torch.arange(ROUNDS, device=k0.device, dtype=torch.int64)
    return torch.stack(
        (
            (k0.unsqueeze(-1) + bumps * KEY_BUMPS[0]) & MASK32,
            (k1.unsqueeze(-1) + bumps * KEY_BUMPS[1]) & MASK32,
        ),
        dim=-1,
    )


def philox_rounds(
    even: torch.Tensor, odd: torch.Tensor, keys: Sequence[torch.Tensor], multipliers: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Philox-4x32-10 of counters held as words (c0, c2) `even` and (c1, c3) `odd` ([..., 2] each),
    under the ten `round_keys` `keys` (each [..., 2], broadcast against the counters); `multipliers` is
    `MULTIPLIERS` as a tensor. Returns the output's (even, odd) words.

    Both multiplications of a round are one operation. Their 64-bit products are taken modulo 2**64
    (int64 multiplication wraps on torch's devices; the known-answer tests check it), and the high and
    low words read from their bits, which the wrap leaves intact."""
    for key in keys:
        product = even * multipliers  # (c0 * M0, c2 * M1)
        low, high = product & MASK32, (product >> 32) & MASK32
        # The new counter: (hi1 ^ c1 ^ k0, hi0 ^ c3 ^ k1) even, (lo1, lo0) odd.
        even, odd = high.flip(-1) ^ odd ^ key, low.flip(-1)
    return even, odd


def philox4x32(counter: Sequence[torch.Tensor], key: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """Philox-4x32-10 of four counter words and two key words (int64 tensors holding 32-bit values,
    broadcast together): the four output words."""
    c0, c1, c2, c3, k0, k1 = torch.broadcast_tensors(*counter, *key)
    keys = round_keys(k0, k1).unbind(-2)
    multipliers = torch.tensor(MULTIPLIERS, device=c0.device)
    even, odd = philox_rounds(torch.stack((c0, c2), -1), torch.stack((c1, c3), -1), keys, multipliers)
    return [even[..., 0], odd[..., 0], even[..., 1], odd[..., 1]]


def _seed_words(seed: int) -> tuple[int, int]:
    seed = int(seed)
    if not 0 <= seed < 2**64:
        raise ValueError(f"a stream's seed must be in [0, 2**64), got {seed}")
    return seed & MASK32, seed >> 32


class PhiloxStreams:
    """N counter-based random streams, stream i keyed by (seeds[i], purpose) (module docstring).

    Args:
        seeds: one per stream (ints in [0, 2**64)).
        purpose: what the streams are for (an int in [0, 2**32)); streams of one seed with different
            purposes are unrelated.
        device: where the counters live and the numbers are made.
    """

    def __init__(self, seeds: Sequence[int], purpose: int, device: torch.device | str = "cpu"):
        if not seeds:
            raise ValueError("PhiloxStreams needs at least one seed")
        if not 0 <= int(purpose) <= MASK32:
            raise ValueError(f"purpose must be in [0, 2**32), got {purpose}")
        self.device = torch.device(device)
        self.seeds = [int(s) for s in seeds]
        self.purpose = int(purpose)
        words = np.array([_seed_words(s) for s in self.seeds], dtype=np.int64)
        self._seed_low = torch.as_tensor(words[:, 0], device=self.device).unsqueeze(1)
        self._seed_high = torch.as_tensor(words[:, 1], device=self.device).unsqueeze(1)
        # Key word 1 mixes the purpose into the seed's high word (a seed below 2**32 has 0 there).
        keys = round_keys(self._seed_low, self._seed_high ^ self.purpose)  # [N, 1, ROUNDS, 2]
        self._keys = keys.unbind(-2)  # sliced once: a round reads its key without an operation
        self._multipliers = torch.tensor(MULTIPLIERS, dtype=torch.int64, device=self.device)
        self.counters = torch.zeros(len(self.seeds), dtype=torch.int64, device=self.device)

    @property
    def num_streams(self) -> int:
        return len(self.seeds)

    def stream(self, i: int) -> PhiloxStreams:
        """Stream i alone, sharing its counter with these streams (a draw from either moves both)."""
        one = object.__new__(PhiloxStreams)
        one.device, one.seeds, one.purpose = self.device, [self.seeds[i]], self.purpose
        one._seed_low, one._seed_high = self._seed_low[i : i + 1], self._seed_high[i : i + 1]
        one._keys = tuple(key[i : i + 1] for key in self._keys)
        one._multipliers = self._multipliers
        one.counters = self.counters[i : i + 1]
        return one

    def blocks(self, num_blocks: int, active: torch.Tensor | None = None) -> torch.Tensor:
        """The next `num_blocks` blocks of every stream as [N, num_blocks, 4] 32-bit words (int64), and
        the counters of the `active` streams (default all) moved past them."""
        index = self.counters.unsqueeze(1) + torch.arange(num_blocks, device=self.device)
        # Counter words (index low, index high, 0, 0): (c0, c2) = (low, 0), (c1, c3) = (high, 0).
        zeros = torch.zeros_like(index)
        even, odd = philox_rounds(
            torch.stack((index & MASK32, zeros), -1),
            torch.stack((index >> 32, zeros), -1),
            self._keys,
            self._multipliers,
        )
        words = torch.stack((even, odd), dim=-1).flatten(-2)  # (c0, c1, c2, c3)
        if active is None:
            self.counters.add_(num_blocks)
        else:
            self.counters.add_(active.to(torch.int64) * num_blocks)
        return words

    def words(self, n: int, active: torch.Tensor | None = None) -> torch.Tensor:
        """The next `n` 32-bit words of every stream, [N, n] (int64); a stream always uses whole blocks."""
        num_blocks = -(-int(n) // 4)
        return self.blocks(num_blocks, active).reshape(self.num_streams, 4 * num_blocks)[:, : int(n)]

    def uniform(
        self, shape: int | Sequence[int], active: torch.Tensor | None = None, dtype=torch.float32
    ) -> torch.Tensor:
        """Uniforms [N, *shape]: float32 in (0, 1) from 24 bits a word (centred on its cell), or float64
        in [0, 1) from 53 bits of two words."""
        shape = (int(shape),) if isinstance(shape, int) else tuple(int(s) for s in shape)
        n = int(np.prod(shape))
        if dtype == torch.float32:
            u = ((self.words(n, active) >> 8).to(torch.float32) + 0.5) * 2.0**-24
        elif dtype == torch.float64:
            w = self.words(2 * n, active).view(self.num_streams, n, 2)
            u = ((w[..., 0] >> 6) * 2**27 + (w[..., 1] >> 5)).to(torch.float64) * 2.0**-53
        else:
            raise ValueError(f"uniforms are float32 or float64, got {dtype}")
        return u.view(self.num_streams, *shape)

    def normal(self, shape: int | Sequence[int], active: torch.Tensor | None = None) -> torch.Tensor:
        """Standard normals [N, *shape] (float32, Box-Muller on pairs of float32 uniforms)."""
        shape = (int(shape),) if isinstance(shape, int) else tuple(int(s) for s in shape)
        n = int(np.prod(shape))
        pairs = -(-n // 2)
        u = self.uniform(2 * pairs, active).view(self.num_streams, pairs, 2)
        radius = torch.sqrt(-2.0 * torch.log(u[..., 0]))
        # (radius cos, radius sin) as the real and imaginary parts of one complex tensor: fewer operations.
        z = torch.view_as_real(torch.polar(radius, (2.0 * np.pi) * u[..., 1]))
        return z.reshape(self.num_streams, 2 * pairs)[:, :n].reshape(self.num_streams, *shape)

    # ------------------------------------------------------------------ checkpoints
    def get_state(self) -> dict[str, Any]:
        """The seeds, the purpose and every stream's counter (numpy)."""
        return {
            "seeds": list(self.seeds),
            "purpose": self.purpose,
            "counters": self.counters.cpu().numpy().copy(),
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restores `get_state`'s counters in place (a captured graph keeps reading them); refuses the
        state of other streams."""
        if list(state["seeds"]) != self.seeds or int(state["purpose"]) != self.purpose:
            raise ValueError(
                f"Philox state of seeds {list(state['seeds'])}, purpose {state['purpose']} does not fit "
                f"these streams (seeds {self.seeds}, purpose {self.purpose})"
            )
        self.counters.copy_(torch.as_tensor(np.asarray(state["counters"], np.int64)))
