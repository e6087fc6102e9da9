"""The speed layer: how many rows are computed at once (docs/performance.md).

The physics (``ks_jax.model``) is one collision, unbatched; ``jax.vmap`` of it is correct everywhere.
On a CPU, large batches are faster computed in cache-sized chunks, each through the exchange's stages
fenced apart. That is all here, and it reaches the physics in one place (``kernel``):

- ``stages``: the one runner of a pipeline of stages over rows (used by every batched caller: the vmap
  rule, ``exchange_batch``, ``ks_jax.solve``, ``ks_jax.sweep``, ``fit``);
- ``chunks``: chunks of rows in a loop, and the vmap rule built from it;
- ``kernel``: ``exchange`` (the physics function with that vmap rule) and ``exchange_batch``;
- ``loss``: ``sum_over_rows``, a batched loss whose gradient is computed chunk by chunk.
"""

from .chunks import CHUNK_ROWS
from .kernel import exchange, exchange_batch
from .loss import sum_over_rows

__all__ = ["CHUNK_ROWS", "exchange", "exchange_batch", "sum_over_rows"]
