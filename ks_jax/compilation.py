"""How programs are compiled and kept between processes (docs/performance.md, "Compiling").

- ``quick_jit``: ``jax.jit`` for programs whose compile time is most of their time. A file's few cases
  (``ks_jax.solve``), a fit's few hundred rows per call and a sweep of one short chunk run in
  milliseconds once compiled; on a CPU they are compiled with ``QUICK_CPU`` (LLVM's optimisation level 0
  and XLA's classic CPU emitters, where the installed XLA has them), which compiles about twice as fast for the
  same IEEE arithmetic; on a GPU with ``QUICK_GPU`` (``quick_options``). Larger work keeps XLA's defaults,
  where the run time counts.
- ``keep_programs``: JAX's persistent compilation cache in one folder (the command line calls it), so
  that a later process loads compiled programs instead of compiling them again; pint's parsed unit
  definitions are kept there too.
- Traced programs: JAX's cache saves XLA's compile, not the tracing of the program in Python and its
  lowering, which JAX does again in every process and which are most of a warm ``ks-jax fit``. Where
  programs are kept and the ``cache`` extra (``flatbuffers``) is installed, a ``quick_jit`` function
  exports its program on its first call for given static arguments and shapes (``jax.export``) and writes
  it beside JAX's; a later process reads it back and compiles it from JAX's cache, without tracing. The
  program is the one ``jax.jit`` traces, so its values are the jitted function's.

A traced program is found by a key that holds everything it was traced from: the function (module, name
and first line), the values of its static arguments, the tree, shapes and dtypes of its other arguments,
the digest of the source files of its package and of ``ks_jax``, the versions of JAX and jaxlib, whether
64-bit floats are on, the platform and the compiler options. A static value without a faithful ``repr`` (an
object printed with its address), more than one device, or a program that cannot be exported or read back
is called as ``jax.jit``'s. Not in the key: a module's setting changed while the program runs (a constant
set from outside); a process that changes one should not keep programs.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import inspect
import os
import pickle
import re
import sys
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp

from . import units

# per-program XLA options (a program compiled with them is cached apart from one without); an option the installed
# XLA does not know is left out (``known_options``)
QUICK_CPU = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}
# On a GPU, where compiling is most of a small program's time (several times its compile for a CPU): LLVM's costly
# passes off (NVIDIA's assembler optimises the PTX it is given again) and XLA's autotuning off (it times candidate
# kernels and algorithms on the device, for products of 3-vectors and 3x3 matrices that any of them computes at once)
QUICK_GPU = {"xla_llvm_disable_expensive_passes": True, "xla_gpu_autotune_level": 0}
GPU_PLATFORMS = ("gpu", "cuda", "rocm")  # JAX's names of a GPU's platform
# when programs are kept, the folder is trimmed to this many bytes (least recently used programs first)
CACHE_LIMIT = 512 * 2**20
_SUFFIX = "-export"  # a traced program's file name: <function>-<64 hex digits of its key>-export
_CACHE_ENTRY = re.compile(r"[A-Za-z0-9_.-]+-[0-9a-f]{64}-(cache|atime|export)")  # JAX's files and the exports
_FOLDER = None  # where programs are kept (``keep_programs``); None: every call is jax.jit's


def quick_jit(fun, **jit_kwargs):
    """``jax.jit(fun, **jit_kwargs)`` compiled with the quick options of the platform it compiles for
    (``quick_options``: JAX's default backend's), its traced program kept where ``keep_programs`` was called.
    The returned function has the jitted forms as attributes, ``quick`` (the default backend's quick options),
    ``plain`` (XLA's defaults) and ``on(platform)`` (a platform's quick options), for a caller that picks one by
    the size of its work and the devices it runs on."""
    return _Quick(fun, jit_kwargs)


class _Quick:
    """``quick_jit``'s function: a ``_Stored`` form per platform's quick options, made at its first use, and one
    with XLA's defaults."""

    def __init__(self, fun, jit_kwargs):
        self.fun, self.jit_kwargs, self.forms = fun, jit_kwargs, {}
        self.plain = _Stored(fun, None, jit_kwargs)
        functools.update_wrapper(self, fun)

    def on(self, platform=None):
        """The form compiled with ``platform``'s quick options (default: JAX's default backend)."""
        name = _platform_name(platform)
        if name not in self.forms:
            self.forms[name] = _Stored(self.fun, quick_options(name, known=False), self.jit_kwargs)
        return self.forms[name]

    @property
    def quick(self):
        return self.on()

    def __call__(self, *args, **kwargs):
        return self.on()(*args, **kwargs)


def _platform_name(platform=None) -> str:
    platform = platform or jax.default_backend()
    return "gpu" if platform in GPU_PLATFORMS else platform


def quick_options(platform=None, known=True):
    """The per-program options of a quick program compiled for ``platform`` ("cpu", "gpu", ...; default: JAX's
    default backend): ``QUICK_CPU`` on a CPU, ``QUICK_GPU`` on a GPU, None (XLA's defaults) elsewhere; ``known``:
    less those the installed XLA does not know (``known_options``)."""
    name = _platform_name(platform)
    options = QUICK_CPU if name == "cpu" else QUICK_GPU if name == "gpu" else None
    return known_options(options) if known else options


def compiler_options(quick: bool, platform=None):
    """The per-program options of a program that is ``quick`` (``quick_options`` of ``platform``, default JAX's
    default backend) or not (None: XLA's defaults)."""
    return quick_options(platform) if quick else None


def known_options(options):
    """``options`` less those that the installed XLA does not know. XLA's options come and go between jaxlib
    versions (``xla_cpu_use_fusion_emitters`` is gone from later ones), and a compile that names an unknown option
    fails: such an option only changes how fast a program compiles, so it is dropped. (XLA's options are one set
    for every platform: each is tried on the CPU, which every JAX has.)"""
    if not options:
        return options
    return {name: value for name, value in options.items() if _known_option(name, value)}


@functools.lru_cache(maxsize=None)
def _known_option(name, value) -> bool:
    """Whether XLA's CPU compiler takes the option ``name`` (a scalar program compiled with it, once a process)."""
    try:
        cpu = jax.devices("cpu")[0]
    except RuntimeError:  # no CPU backend in this process (JAX_PLATFORMS without it): nothing compiled there
        return True
    scalar = jax.ShapeDtypeStruct((), jnp.float32, sharding=jax.sharding.SingleDeviceSharding(cpu))
    try:
        jax.jit(lambda x: x + 1, compiler_options={name: value}).lower(scalar).compile()
    except jax.errors.JaxRuntimeError as error:
        if "No such compile option" in str(error):
            return False
        raise
    return True


@functools.lru_cache(maxsize=32)
def _executable(jitted, tree, avals):
    return jitted.lower(*jax.tree_util.tree_unflatten(tree, avals)).compile()


def compiled(jitted, *args):
    """The executable of ``jitted`` (a ``jax.jit`` function) for arguments shaped as ``args``, compiled
    here rather than inside its first call, so that a caller can say how long compiling took apart from
    running (a sweep's rate counts running only). Kept per function and argument shapes: a later call with
    the same shapes returns the same executable at once."""
    leaves, tree = jax.tree_util.tree_flatten(args)
    avals = tuple(jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x),
                                       weak_type=getattr(x, "weak_type", False)) for x in leaves)
    return _executable(jitted, tree, avals)


def free_programs():
    """Free every compiled program this process holds: JAX's caches (``jax.clear_caches``) and the executables
    that ``compiled`` keeps, which ``jax.clear_caches`` does not reach. A later call traces and compiles its
    program again (or loads it, where programs are kept: ``keep_programs``)."""
    _executable.cache_clear()
    jax.clear_caches()


def keep_programs(folder=None, limit=CACHE_LIMIT):
    """Keep this process's programs in ``folder`` for later processes, as the command line does; returns the
    folder. Every program compiled afterwards goes to JAX's persistent compilation cache there; the traced
    programs of ``ks_jax.solve`` and ``fit.reconstruct`` too (with the ``cache`` extra), and pint's parsed
    unit definitions to its folder ``units``. In a notebook, call it first: after a restart, the same calls
    then load their programs instead of tracing and compiling them. ``folder``: default
    ``$XDG_CACHE_HOME/ks-jax/jax`` (``~/.cache/ks-jax/jax``). The least recently used programs are deleted
    down to ``limit`` bytes (``prune_cache``). Raises OSError where the folder cannot be made."""
    global _FOLDER
    home = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    path = Path(folder) if folder is not None else home / "ks-jax" / "jax"
    path.mkdir(parents=True, exist_ok=True)
    prune_cache(path, limit)
    units.REGISTRY_CACHE = path / "units"
    _FOLDER = path
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    return path


def prune_cache(path, limit):
    """Delete the least recently used programs in ``path`` until the rest take at most ``limit`` bytes;
    returns the number of files deleted. Only files named as JAX's cache and the traced programs name
    theirs are counted or touched, so a folder holding anything else loses nothing else. (JAX's own bound,
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


class _Stored:
    """``jax.jit(fun, compiler_options=options, **jit_kwargs)`` whose traced program is kept in the folder of
    ``keep_programs`` (module docstring). Attributes of the jitted function (``lower``, ``trace``, ...) are
    those of ``jax.jit``'s."""

    def __init__(self, fun, options, jit_kwargs):
        self.fun, self.given, self.jit_kwargs = fun, options, jit_kwargs
        self._jitted = None
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

    @property
    def options(self):
        """The options its programs are compiled with: those given that XLA knows (``known_options``), found at
        the first use, not when a module defines the function."""
        return known_options(self.given)

    @property
    def jitted(self):
        if self._jitted is None:
            self._jitted = jax.jit(self.fun, compiler_options=self.options, **self.jit_kwargs)
        return self._jitted

    def __getattr__(self, name):  # lower, trace, eval_shape, _cache_size, ...
        if name in ("jitted", "_jitted", "fun", "given", "jit_kwargs"):  # not set yet (a copy being made)
            raise AttributeError(name)
        return getattr(self.jitted, name)

    def __call__(self, *args, **kwargs):
        if _FOLDER is None or jax.device_count() != 1 or not _can_serialize():
            return self.jitted(*args, **kwargs)
        split = self._split(args, kwargs)
        if split is None:
            return self.jitted(*args, **kwargs)
        static, names, dynamic = split
        leaves, in_tree = jax.tree_util.tree_flatten(dynamic)
        try:  # a call seen before: one dictionary lookup, not the key's hashing of the sources and signature
            seen = (_FOLDER, tuple(static.items()), in_tree, tuple(map(_kind, leaves)))
            program = self.seen.get(seen)
        except TypeError:  # a static value that cannot be hashed: jax.jit refuses it too
            return self.jitted(*args, **kwargs)
        if program is None:
            key = self._key(static, in_tree, leaves)
            if key is None or key in self.refused:
                return self.jitted(*args, **kwargs)
            program = (self.programs.get((_FOLDER, key)) or self._load(key)
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
        described = repr(sorted(static.items()))
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
                     _environment(self.fun.__module__), repr(self.options), repr(sorted(self.jit_kwargs.items()))))
        return hashlib.sha256(text.encode()).hexdigest()

    def _path(self, key):
        name = "".join(c if c.isalnum() or c in "_." else "_" for c in self.fun.__qualname__)[-60:]
        return Path(_FOLDER) / f"ks_jax_{name}-{key}{_SUFFIX}"

    def _ready(self, key, out_tree, exported):
        program = (jax.jit(exported.call, compiler_options=self.options), out_tree)
        self.programs[_FOLDER, key] = program
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


@functools.lru_cache(maxsize=None)
def _sources(package):
    """The digest of the source files of ``package`` (a top-level package's name): a program traced from
    other code is another program."""
    folder = Path(sys.modules[package].__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(folder.rglob("*.py")):
        digest.update(str(path.relative_to(folder.parent)).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _environment(module):
    """What a traced program depends on beyond its function: the sources of the function's package and of
    ks_jax, JAX's version, x64, the platform and the device."""
    import jaxlib

    packages = sorted({module.split(".")[0], __name__.split(".")[0]})
    return (tuple(_sources(p) for p in packages), jax.__version__, jaxlib.__version__,
            bool(jax.config.jax_enable_x64), jax.default_backend(), jax.devices()[0].device_kind)
