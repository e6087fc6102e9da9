"""``quick_jit``: ``jax.jit`` for programs whose compile time is most of their time.

``ks_jax.solve`` solves the few cases of a file, ``fit.reconstruct`` fits a few hundred rows per call, and
a sweep of a few thousand points is one short chunk: once compiled they run in milliseconds, and compiling
them at XLA's defaults took seconds. On a CPU these programs are compiled with ``QUICK_CPU``: LLVM's
optimisation level 0 and XLA's classic CPU emitters (the settings the test suite compiles everything with). The results agree with the default-compiled programs'
to rounding (tests/test_transforms.py holds them to 1e-12). From an empty cache, ``ks-jax solve`` of the
seed chapter took 3.2-4.2 s against 5.8 s at XLA's defaults, ``ks-jax fit`` of ``fit_seed_001.json``
5.3-6.4 s against 7.0-8.5 s, ``ks-jax sweep`` of a 41 x 7 grid 3.1-3.3 s against 5.6-6.2 s
(benchmarks/RESULTS.md, 2026-11-26). The batched kernels (``jax.vmap(exchange)``, ``exchange_batch``), sweeps
of more than ``sweeps.QUICK_POINTS`` points and fits of more than ``fit.reconstruction.QUICK_ROWS`` rows per
call keep XLA's defaults: there the run time counts (a sweep's programs compiled quick ran 2.6-10x slower).
Elsewhere than a CPU (a GPU) every program keeps XLA's defaults.
"""

from __future__ import annotations

import functools

import jax

from .stored import stored_jit

# per-program XLA debug options (a program compiled with them is cached apart from one without)
QUICK_CPU = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}


def quick_jit(fun, **jit_kwargs):
    """``jax.jit(fun, **jit_kwargs)``, compiled with ``QUICK_CPU`` when JAX's default backend is a CPU.
    The returned function has both jitted forms as attributes: ``quick`` (with ``QUICK_CPU``) and
    ``plain`` (XLA's defaults), for a caller that picks one by the size of its work; ``jit_kwargs`` and
    ``__wrapped__`` (``fun``) compile it with other options. Both keep their programs between runs of the
    command line (``ks_jax.stored``)."""
    quick = stored_jit(fun, compiler_options=QUICK_CPU, **jit_kwargs)
    plain = stored_jit(fun, **jit_kwargs)

    @functools.wraps(fun)
    def call(*args, **kwargs):
        return (quick if jax.default_backend() == "cpu" else plain)(*args, **kwargs)

    call.quick, call.plain, call.jit_kwargs = quick, plain, jit_kwargs
    return call
