"""How programs are compiled and kept between processes (docs/performance.md, "Compiling").

- ``quick_jit``: ``jax.jit`` for programs whose compile time is most of their time. A file's few cases
  (``ks_jax.solve``), a fit's few hundred rows per call and a sweep of one short chunk run in
  milliseconds once compiled; on a CPU they are compiled with ``QUICK_CPU`` (LLVM's optimisation level 0
  and XLA's classic CPU emitters), which compiles about twice as fast for the same IEEE arithmetic.
  Larger work keeps XLA's defaults, where the run time counts.
- ``keep_programs``: JAX's persistent compilation cache in one folder (the command line calls it), so
  that a later process loads compiled programs instead of compiling them again; pint's parsed unit
  definitions are kept there too.
"""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path

import jax

from . import units

# per-program XLA options (a program compiled with them is cached apart from one without)
QUICK_CPU = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}
# when programs are kept, the folder is trimmed to this many bytes (least recently used programs first)
CACHE_LIMIT = 512 * 2**20
_CACHE_ENTRY = re.compile(r"[A-Za-z0-9_.-]+-[0-9a-f]{64}-(cache|atime)")  # the files JAX's cache writes


def quick_jit(fun, **jit_kwargs):
    """``jax.jit(fun, **jit_kwargs)``, compiled with ``QUICK_CPU`` where JAX's default backend is a CPU.
    The returned function has both jitted forms as attributes, ``quick`` (with ``QUICK_CPU``) and ``plain``
    (XLA's defaults), for a caller that picks one by the size of its work. Elsewhere than a CPU both are
    compiled with XLA's defaults."""
    quick = jax.jit(fun, compiler_options=QUICK_CPU, **jit_kwargs)
    plain = jax.jit(fun, **jit_kwargs)

    @functools.wraps(fun)
    def call(*args, **kwargs):
        return (quick if jax.default_backend() == "cpu" else plain)(*args, **kwargs)

    call.quick, call.plain = quick, plain
    return call


def compiler_options(quick: bool):
    """The per-program options of a program that is ``quick`` (``QUICK_CPU`` on a CPU) or not (None)."""
    return QUICK_CPU if quick and jax.default_backend() == "cpu" else None


def keep_programs(folder=None, limit=CACHE_LIMIT):
    """Keep this process's compiled programs in ``folder`` for later processes, as the command line does;
    returns the folder. Every program compiled afterwards goes to JAX's persistent compilation cache there,
    and pint's parsed unit definitions to its folder ``units``. In a notebook, call it first: after a
    restart, the same calls then load their programs instead of compiling them. ``folder``: default
    ``$XDG_CACHE_HOME/ks-jax/jax`` (``~/.cache/ks-jax/jax``). The least recently used programs are
    deleted down to ``limit`` bytes (``prune_cache``). Raises OSError where the folder cannot be made."""
    home = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    path = Path(folder) if folder is not None else home / "ks-jax" / "jax"
    path.mkdir(parents=True, exist_ok=True)
    prune_cache(path, limit)
    units.REGISTRY_CACHE = path / "units"
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    return path


def prune_cache(path, limit):
    """Delete the least recently used programs in ``path`` until the rest take at most ``limit`` bytes;
    returns the number of files deleted. Only files named as JAX's cache names its entries are counted or
    touched, so a folder holding anything else loses nothing else. (JAX's own bound,
    ``jax_compilation_cache_max_size``, needs the ``filelock`` package.)"""
    entries = []
    with os.scandir(path) as it:
        for entry in it:
            if _CACHE_ENTRY.fullmatch(entry.name) and entry.is_file(follow_symlinks=False):
                st = entry.stat(follow_symlinks=False)
                entries.append((max(st.st_atime, st.st_mtime), st.st_size, entry.path))
    total = sum(size for _, size, _ in entries)
    deleted = 0
    for _, size, file in sorted(entries):
        if total <= limit:
            break
        try:
            os.remove(file)
        except FileNotFoundError:  # another run deleted it first
            pass
        total -= size
        deleted += 1
    return deleted
