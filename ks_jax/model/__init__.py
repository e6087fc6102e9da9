"""The physics: pure, unbatched, backend-agnostic functions of one collision (docs/model.md).

In the order a collision is computed:

- ``types``: the inputs (``Vehicle``, ``State``, ``Contact``) and results (``ExchangeResult``) as
  pytrees of SI arrays, and the status codes;
- ``checks``: the rules the inputs must keep, as a status code per row;
- ``matrix``: the collision matrix K and the world-frame inverse inertias;
- ``cone``: the friction cone;
- ``collision``: the exchange, a pipeline of three stages (prepare, impulse, results);
- ``results``: what the exchange derives from its impulse: delta-V, PDOF, crush, EES, energy;
- ``contact``: automatic contact, a subpackage (free motion to the first touch, the centroid and
  plane of the footprints' overlap, the exchange there; its interface is in its docstring);
- ``linalg``: closed-form 3-vector and 3x3 algebra and trigonometry, safe to differentiate.

Callers jit and vmap these functions (``ks_jax.batch`` batches them fast on a CPU). Nothing here
imports the case files, the command line, plotting or ``fit``.
"""
