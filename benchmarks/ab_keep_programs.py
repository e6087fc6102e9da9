"""A new Python process (a notebook after a restart) with and without ``ks_jax.keep_programs``: seconds from
``import jax`` to the end of ``fit.reconstruct`` of ``fit_seed_001.json``, then of ``ks_jax.solve`` of
``auto_seed_000.json``.

    d=$(mktemp -d); python benchmarks/ab_keep_programs.py $d > /dev/null     # fills the folder
    for r in 1 2 3; do echo "none $(python benchmarks/ab_keep_programs.py none)  kept $(python benchmarks/ab_keep_programs.py $d)"; done
"""
import sys, time
t = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import ks_jax, fit
if sys.argv[1] != "none":
    ks_jax.keep_programs(sys.argv[1])
case = ks_jax.load_cases("ks_jax/cases/fit_seed_001.json")[0]
fit.reconstruct(case)
a = time.perf_counter()
ks_jax.solve(ks_jax.load_case("ks_jax/cases/auto_seed_000.json"))
print(f"{a - t:.2f} {time.perf_counter() - a:.2f}")
