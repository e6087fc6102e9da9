"""Implementation checks, run on demand (not tests: they count what XLA and JAX make of the code, which changes
with their versions, not what the library computes).

    .venv/bin/python benchmarks/checks.py

Prints one line per check, PASS or FAIL with the numbers, and exits 1 if any failed:

- no library routine (LAPACK) in the batched programs: ``jax.jit(jax.vmap(exchange))`` in chunks, its
  gradient, ``exchange_batch``'s chunk program, ``sum_over_rows``'s chunked gradient (and the check sees the
  LAPACK calls of a batched 3x3 solve, so that it can fail);
- a batch of one or two rows compiles to about the program of one unbatched row (``jax.vmap`` adds a batch
  axis, not work): at most 1.5x its instructions;
- the input rules are stored once per row (``model.checks.input_status``): the gradient of a batched loss
  compiles to at most 3x the instructions of its forward (XLA copies them into every loop that reads an input
  otherwise);
- automatic contact in one program (``solve_inputs``: its input rules fenced off) compiles to at most 1.5x
  the instructions of its three stages compiled apart;
- a chunked batch traces each stage of the exchange a bounded number of times (tracing is the first call's
  cost in a notebook).
"""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import ks_jax
from ks_jax.backend import Plan
from ks_jax.case import as_arrays, to_pytrees
from ks_jax.solve import solve_inputs, stages

CHUNKS = importlib.import_module("ks_jax.batch.chunks")
COLLISION = importlib.import_module("ks_jax.model.collision")
CASES = Path(ks_jax.__file__).parent / "cases"
RESULTS = []


def check(name, ok, detail):
    RESULTS.append(ok)
    print(f"{'PASS' if ok else 'FAIL'}  {name}: {detail}")


def rows(n, seed=0):
    """n rows around the manual's crash, every input varied by a few percent (inertia as (3, 3) tensors)."""
    rng = np.random.default_rng(seed)
    v1, s1, v2, s2, c = to_pytrees(as_arrays(ks_jax.load_case(CASES / "seed_000_saturn_pontiac.json").inputs))

    def spread(tree, rel):
        return jax.tree_util.tree_map(
            lambda x: jnp.asarray(np.asarray(x)[None] * (1 + rel * rng.standard_normal((n,) + np.shape(x)))), tree)

    return spread(v1, 0.02), spread(s1, 0.05), spread(v2, 0.02), spread(s2, 0.05), spread(c, 0.02)


def library_calls(text):
    return set(re.findall(r"custom_call @(\w+)", text))


def instructions(fn, *args):
    return len(re.findall(r"^\s+\S+ = ", jax.jit(fn).lower(*args).compile().as_text(), re.M))


def loss(args):
    r = jax.vmap(ks_jax.exchange)(*args)
    return jnp.sum(jnp.where(r.contact.status == 0, r.vehicles[0].pdof + r.vehicles[1].ees, 0.0))


def check_no_library_routines():
    CHUNKS.CHUNK_ROWS = 64
    try:
        args = rows(150)  # three chunks of 64 rows
        texts = {"jit(vmap(exchange))": jax.jit(jax.vmap(ks_jax.exchange)).lower(*args).as_text(),
                 "its gradient": jax.jit(jax.value_and_grad(loss)).lower(args).as_text()}
    finally:
        CHUNKS.CHUNK_ROWS = 1 << 14
    program = importlib.import_module("ks_jax.batch.kernel")._chunk_program(64, 0.0, True, Plan("cpu"))
    texts["exchange_batch's chunk"] = program.lower(args, 0).as_text()
    summed = ks_jax.sum_over_rows(lambda *r: ks_jax.exchange(*r).vehicles[0].delta_v_magnitude, chunk=64)
    texts["sum_over_rows' gradient"] = jax.jit(jax.grad(lambda a: summed(*a))).lower(args).as_text()
    found = {name: library_calls(text) for name, text in texts.items()}
    solve = jax.jit(jax.vmap(jnp.linalg.solve)).lower(jnp.eye(3)[None].repeat(8, 0), jnp.ones((8, 3))).as_text()
    check("no LAPACK call in the batched programs", not any(found.values()) and bool(library_calls(solve)),
          f"{found}; a batched 3x3 solve calls {sorted(library_calls(solve))}")


def check_batch_of_one_row():
    args = rows(2)
    one = tuple(jax.tree_util.tree_map(lambda x: x[0], args))
    unbatched = instructions(ks_jax.exchange, *one)
    counts = {n: instructions(jax.vmap(ks_jax.exchange), *jax.tree_util.tree_map(lambda x: x[:n], args))
              for n in (1, 2)}
    check("a batch of 1 or 2 rows is about one row's program", max(counts.values()) <= 1.5 * unbatched,
          f"unbatched {unbatched} instructions, 1 row {counts[1]}, 2 rows {counts[2]}")


def check_rules_stored_once():
    args = rows(96)
    forward = instructions(loss, args)
    gradient = instructions(jax.value_and_grad(loss), args)
    check("the input rules are stored once per row", gradient <= 3 * forward,
          f"forward {forward} instructions, value and gradient {gradient} ({gradient / forward:.2f}x)")


def check_automatic_contact_in_one_program():
    inputs = as_arrays(ks_jax.load_case(CASES / "auto_tbone.json").inputs)
    two = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), inputs)
    rules, contact, exchange = stages(True, True)
    status = jax.vmap(rules)(two)
    auto = jax.vmap(contact)(two, status)
    apart = (instructions(jax.vmap(rules), two) + instructions(jax.vmap(contact), two, status)
             + instructions(jax.vmap(exchange), two, status, auto))
    together = instructions(jax.vmap(lambda x: solve_inputs(x, True, True)), two)
    check("automatic contact in one program is about its stages apart", together <= 1.5 * apart,
          f"one program {together} instructions, three stages {apart}")


def check_traces():
    counts = {}
    originals = {name: getattr(COLLISION, name) for name in ("prepare", "impulse", "results")}

    def counted(name):
        def traced(*a, **k):
            counts[name] = counts.get(name, 0) + 1
            return originals[name](*a, **k)
        return traced

    for name in originals:
        setattr(COLLISION, name, counted(name))
    kernel = importlib.import_module("ks_jax.batch.kernel")
    kernel.exchange_stages.cache_clear()
    kernel._batched.cache_clear()
    CHUNKS._row_shapes.cache_clear()
    CHUNKS.CHUNK_ROWS = 64
    try:
        jax.jit(jax.vmap(ks_jax.exchange)).trace(*rows(150))
    finally:
        CHUNKS.CHUNK_ROWS = 1 << 14
        for name, fn in originals.items():
            setattr(COLLISION, name, fn)
        kernel.exchange_stages.cache_clear()
        kernel._batched.cache_clear()
    check("a chunked batch traces each stage at most 3 times", counts and max(counts.values()) <= 3, f"{counts}")


if __name__ == "__main__":
    print(f"jax {jax.__version__}, {jax.default_backend()}")
    for fn in (check_no_library_routines, check_batch_of_one_row, check_rules_stored_once,
               check_automatic_contact_in_one_program, check_traces):
        fn()
    sys.exit(0 if all(RESULTS) else 1)
