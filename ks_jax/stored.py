"""``stored_jit``: ``jax.jit`` whose traced and lowered programs the command line keeps between runs.

JAX's compilation cache (``keep_programs``) saves XLA's compile in a later run of a command, not the tracing of the
program in Python and its lowering, which JAX does again in every process: with a warm cache they were 1.5 s of
the 1.8 s of ``ks-jax fit fit_seed_001.json`` and 2.3 s of the 3.1 s of a 41 x 7 sweep of the automatic-contact
T-bone (benchmarks/RESULTS.md). Where ``FOLDER`` is set (``keep_programs``: the command line calls it), a
``stored_jit`` function exports its program on its first call for given static arguments and shapes
(``jax.export``) and writes it there; a later process reads it back and compiles it (from JAX's cache), without
tracing. The program is the one ``jax.jit`` traces: its values are the jitted function's (tests/test_cli.py
compares a command's results with and without the cache).

A program is found by a key that holds everything it was traced from: the function (module, name and first
line), the values of its static arguments and of ``context`` (what the function closes over), the tree, shapes
and dtypes of its other arguments, the digest of the source files of ``ks_jax`` and ``fit``, the versions of JAX
and jaxlib, whether 64-bit floats are on, the platform and the compiler options. A static value without a
faithful ``repr`` (an object printed with its address), more than one device, no ``flatbuffers`` (JAX writes
exported programs with it: the ``cache`` extra), or a program that cannot be exported or read back: then the
call is ``jax.jit``'s, as without ``FOLDER``. Not in the key: a module's setting changed while the program runs
(a constant such as ``exchange.CHUNK_ROWS`` set from outside); the command line changes none, and a process
that does should leave ``FOLDER`` unset.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import inspect
import os
import pickle
import re
import tempfile
from pathlib import Path

import jax

FOLDER = None  # where programs are kept (``keep_programs``); None: every call is jax.jit's
SUFFIX = "-export"  # a stored program's file name: <function>-<64 hex digits of its key>-export
# when programs are kept, the folder is trimmed to this many bytes (least recently used programs first)
CACHE_LIMIT = 512 * 2**20
_CACHE_ENTRY = re.compile(r"[A-Za-z0-9_.-]+-[0-9a-f]{64}-(cache|atime|export)")  # JAX's files and the exports


def keep_programs(folder=None, limit=CACHE_LIMIT):
    """Keep the programs of this process in ``folder`` for later processes, as the command line does; returns
    the folder. JAX's compiled programs (its compilation cache, for every jitted function of the process), the
    traced ones of ``ks_jax.solve``, ``ks_jax.sweep``, ``ks_jax.exchange_batch`` and ``fit.reconstruct``
    (``stored_jit``; with the ``cache`` extra) and pint's parsed unit definitions (the folder ``units``; from
    the first unit string read after this call). In a notebook, call it first: after a restart, the same calls
    then skip tracing and compiling. ``folder``: default ``$XDG_CACHE_HOME/ks-jax/jax`` (``~/.cache/ks-jax/jax``).
    The least recently used programs are deleted down to ``limit`` bytes (``prune_cache``); each grid shape of a
    sweep of several chunks is a program of its own. Raises OSError where the folder cannot be made."""
    from . import units

    global FOLDER
    home = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    path = Path(folder) if folder is not None else home / "ks-jax" / "jax"
    path.mkdir(parents=True, exist_ok=True)
    prune_cache(path, limit)
    units.REGISTRY_CACHE = path / "units"
    FOLDER = path
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    return path


def prune_cache(path, limit):
    """Delete the least recently used programs in ``path`` until the rest take at most ``limit`` bytes;
    returns the number of files deleted. Only files named as JAX and ``stored_jit`` name theirs are counted or
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


def stored_jit(fun, context=(), compiler_options=None, **jit_kwargs):
    """``jax.jit(fun, compiler_options=compiler_options, **jit_kwargs)``, kept in ``FOLDER`` (module docstring).
    ``context``: a tuple of the values ``fun`` closes over that the key would not otherwise see. Attributes of
    the jitted function (``lower``, ``trace``, ...) are those of ``jax.jit``'s."""
    return _Stored(fun, tuple(context), compiler_options, jit_kwargs)


class _Stored:
    def __init__(self, fun, context, options, jit_kwargs):
        self.jitted = jax.jit(fun, compiler_options=options, **jit_kwargs)
        self.fun, self.context, self.options, self.jit_kwargs = fun, context, options, jit_kwargs
        self.programs = {}  # (folder, key) -> (jitted call of the exported program, output tree)
        self.seen = {}  # (folder, statics, tree, kinds of the leaves) -> the same: no key to compute again
        self.refused = set()  # keys of programs that could not be exported
        try:
            self.signature = inspect.signature(fun)
        except (TypeError, ValueError):
            self.signature = None
        params = list(self.signature.parameters.values()) if self.signature is not None else []
        if any(p.kind not in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) for p in params):
            self.signature = None  # *args, **kwargs, positional-only: not handled here
        nums = jit_kwargs.get("static_argnums", ())
        nums = (nums,) if isinstance(nums, int) else tuple(nums)
        self.static_names = set(jit_kwargs.get("static_argnames", ())) | {params[i].name for i in nums if params}
        functools.update_wrapper(self, fun)

    def __getattr__(self, name):  # lower, trace, eval_shape, _cache_size, ...
        if name == "jitted":  # not set yet (a copy being made)
            raise AttributeError(name)
        return getattr(self.jitted, name)

    def __call__(self, *args, **kwargs):
        if FOLDER is None or jax.device_count() != 1 or not _can_serialize():
            return self.jitted(*args, **kwargs)
        split = self._split(args, kwargs)
        if split is None:
            return self.jitted(*args, **kwargs)
        static, names, dynamic = split
        leaves, in_tree = jax.tree_util.tree_flatten(dynamic)
        try:  # the calls of a sweep's chunks: one dictionary lookup (a key costs about 0.15 ms)
            seen = (FOLDER, tuple(static.items()), in_tree, tuple(map(_kind, leaves)))
            program = self.seen.get(seen)
        except TypeError:  # a static value that cannot be hashed: jax.jit refuses it too
            return self.jitted(*args, **kwargs)
        if program is None:
            key = self._key(static, in_tree, leaves)
            if key is None or key in self.refused:
                return self.jitted(*args, **kwargs)
            program = (self.programs.get((FOLDER, key)) or self._load(key)
                       or self._export(key, static, names, in_tree, leaves))
            if program is None:
                return self.jitted(*args, **kwargs)
            self.seen[seen] = program
        call, out_tree = program
        return jax.tree_util.tree_unflatten(out_tree, call(*leaves))

    def _split(self, args, kwargs):
        """(static arguments by name, names of the others, their values), or None for a signature this does
        not handle (``*args``, ``**kwargs``, positional-only parameters)."""
        if self.signature is None:
            return None
        try:
            bound = self.signature.bind(*args, **kwargs)
        except TypeError:
            return None
        bound.apply_defaults()
        static = {k: v for k, v in bound.arguments.items() if k in self.static_names}
        names = [k for k in bound.arguments if k not in self.static_names]
        return static, names, tuple(bound.arguments[k] for k in names)

    def _key(self, static, in_tree, leaves):
        described = repr((sorted(static.items()), self.context))
        if " at 0x" in described:  # an object's default repr: not its value
            return None
        try:
            avals = [str(jax.typeof(x)) for x in leaves]
        except TypeError:
            return None
        code = getattr(self.fun, "__code__", None)
        if code is None:  # not a Python function (a functools.partial): no name and line to key it by
            return None
        text = repr((self.fun.__module__, self.fun.__qualname__, code.co_firstlineno, described, str(in_tree), avals,
                     _environment(), repr(self.options), repr(sorted(self.jit_kwargs.items()))))
        return hashlib.sha256(text.encode()).hexdigest()

    def _path(self, key):
        name = "".join(c if c.isalnum() or c in "_." else "_" for c in self.fun.__qualname__)[-60:]
        return Path(FOLDER) / f"ks_jax_{name}-{key}{SUFFIX}"

    def _ready(self, key, out_tree, exported):
        program = (jax.jit(exported.call, compiler_options=self.options), out_tree)
        self.programs[FOLDER, key] = program
        return program

    def _load(self, key):
        path = self._path(key)
        try:
            out_tree, data = pickle.loads(path.read_bytes())
            exported = jax.export.deserialize(bytearray(data))
        except Exception:  # noqa: BLE001 - missing, unreadable or from another JAX: export it again
            return None
        try:
            os.utime(path)  # recently used: the folder is trimmed least recently used first (``prune_cache``)
        except OSError:
            pass
        return self._ready(key, out_tree, exported)

    def _export(self, key, static, names, in_tree, leaves):
        out_trees = []

        def flat(*leaves):
            outputs, out_tree = jax.tree_util.tree_flatten(
                self.fun(**static, **dict(zip(names, jax.tree_util.tree_unflatten(in_tree, leaves)))))
            out_trees.append(out_tree)
            return outputs

        try:
            exported = jax.export.export(jax.jit(flat, compiler_options=self.options))(*leaves)
            data = pickle.dumps((out_trees[-1], exported.serialize()))
        except Exception:  # noqa: BLE001 - a program jax.export cannot take: jax.jit's call from now on
            self.refused.add(key)
            return None
        path, written = self._path(key), None
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, delete=False, suffix=".tmp") as f:
                written = f.name
                f.write(data)
            os.replace(written, path)  # whole or not at all, for a process that reads it at the same time
            written = None
        except OSError:
            pass  # not kept; this run still uses it
        finally:  # a file left half-written (a full disk, Ctrl-C): removed
            if written is not None:
                with contextlib.suppress(OSError):
                    os.remove(written)
        return self._ready(key, out_trees[-1], exported)


def _kind(x):
    """What decides a leaf's abstract value (shape, dtype, weak type), cheaply: a Python number's type, an
    array's shape and dtype, a JAX array's weak type."""
    return type(x), getattr(x, "shape", None), getattr(x, "dtype", None), getattr(x, "weak_type", None)


@functools.lru_cache(maxsize=1)
def _can_serialize():
    """Whether ``jax.export`` can write a program: it needs ``flatbuffers`` (the ``cache`` extra)."""
    try:
        import flatbuffers  # noqa: F401
    except ImportError:
        return False
    return True


@functools.lru_cache(maxsize=1)
def _sources():
    """The digest of the source files of ``ks_jax`` and ``fit``: a program traced from other code is another."""
    digest = hashlib.sha256()
    for package in ("ks_jax", "fit"):
        folder = Path(__file__).resolve().parent.parent / package
        for path in sorted(folder.rglob("*.py")):
            digest.update(str(path.relative_to(folder.parent)).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _environment():
    import jaxlib

    return (_sources(), jax.__version__, jaxlib.__version__, bool(jax.config.jax_enable_x64), jax.default_backend(),
            jax.devices()[0].device_kind)
