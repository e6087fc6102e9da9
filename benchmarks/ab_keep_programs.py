"""A new Python process (a notebook after a restart) with and without ``ks_jax.keep_programs``.

    python benchmarks/ab_keep_programs.py fit FOLDER|none [compiled]
    python benchmarks/ab_keep_programs.py batch FOLDER|none [compiled]

``fit``: seconds from ``import jax`` to the end of ``fit.reconstruct`` of ``fit_seed_001.json``, then of
``ks_jax.solve`` of ``auto_seed_000.json``. ``batch``: from ``import jax`` to the end of ``ks_jax.exchange_batch``
over 2^16 rows of the seed chapter (the bullet car's speed varied), then that call alone. ``none``: nothing
kept; FOLDER: ``keep_programs(FOLDER)``; ``compiled``: then ``stored.FOLDER = None`` (JAX's compiled programs
kept, not the traced ones). Run each once to fill its folder, then alternate, e.g.

    a=$(mktemp -d); b=$(mktemp -d); python benchmarks/ab_keep_programs.py batch $a; python benchmarks/ab_keep_programs.py batch $b compiled
    for r in 1 2 3; do for m in "none" "$b compiled" "$a"; do python benchmarks/ab_keep_programs.py batch $m; done; done
"""

import sys
import time

start = time.perf_counter()
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import ks_jax  # noqa: E402

what, where = sys.argv[1], sys.argv[2]
if where != "none":
    ks_jax.keep_programs(where)
if len(sys.argv) > 3 and sys.argv[3] == "compiled":
    ks_jax.stored.FOLDER = None
if what == "fit":
    import fit

    fit.reconstruct(ks_jax.load_cases("ks_jax/cases/fit_seed_001.json")[0])
    middle = time.perf_counter()
    ks_jax.solve(ks_jax.load_case("ks_jax/cases/auto_seed_000.json"))
else:
    case = ks_jax.load_case("ks_jax/cases/seed_000_saturn_pontiac.json")
    rows = jax.tree_util.tree_map(lambda x: np.repeat(np.asarray(x)[None], 1 << 16, axis=0),
                                  ks_jax.case.to_pytrees(case.inputs))
    rows[3].velocity[:, 0] = np.linspace(5.0, 25.0, 1 << 16)
    middle = time.perf_counter()
    ks_jax.exchange_batch(*rows)
end = time.perf_counter()
print(f"{what} {' '.join(sys.argv[2:])}: {middle - start:.2f} {end - middle:.2f}" if what == "fit" else
      f"{what} {' '.join(sys.argv[2:])}: {end - start:.2f} {end - middle:.2f}")
