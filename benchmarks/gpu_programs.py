"""ks-jax's programs compiled for an NVIDIA GPU on a machine that has none: how long XLA takes to compile each for
the GPU, with its defaults and with ``QUICK_GPU``, and how many kernels each launches, per call and per iteration of
its loops. Not a test.

    .venv/bin/pip install "jax-cuda12-plugin[with-cuda]==V" "jax-cuda12-pjrt==V"   # V: the installed jax's version
    .venv/bin/python benchmarks/gpu_programs.py [--rounds 1] [--only NAME] [--hlo DIR] [--phases]

JAX's CUDA plugin compiles for a GPU from a description of it (``TARGET``: an H200's) without the GPU itself
(XLA's deviceless compile): the program XLA would run there, fused, scheduled, its kernels generated (LLVM to PTX)
and assembled (ptxas), all on this machine's CPU. What it cannot do without the device is time anything on it, or
autotune. So compile seconds here are those of this machine's cores, where a GPU's host has its own; the kernels
are the GPU's.

The programs, each traced on the accelerator's path (``plan="accelerator"``, as a GPU chooses it):

- the kernel, ``jax.jit(jax.vmap(ks_jax.exchange))``, float64 and float32, 2^22 rows (``bench_kernel.random_batch``);
- the programs of ``bench_compile.captured_calls``: ``ks_jax.solve`` of the seed case, of ``auto_seed_000.json``
  and of ``rest_seed_000.json`` (motion to rest), the solver of ``fit.reconstruct`` of ``fit_seed_001.json``, and
  the solver's 8000 rows of ``fit.reconstruct_batch`` of 1000 of ``bench_fit.py``'s cases x 8 starts;
- the Jacobians of a fit that sticks (``fit.rows._edge_jacobians``): ``auto_tbone.json``'s speed and friction
  fitted to its own delta-Vs.

For each: the compile's seconds under XLA's defaults and under ``QUICK_GPU`` (medians of --rounds, the order
alternating); the kernels its call launches outside loops, in one iteration of each loop (XLA's while loops: a fit's
solver, a motion to rest) and in each branch of each conditional (one branch runs each time), counted in the
compiled program (``launches``). --hlo DIR writes each compiled
program's text there. --phases also reads XLA's own timers from its log (its first compile with XLA's defaults):
the seconds of its HLO passes (and of these, the fusion pass), of LLVM's PTX, and of ptxas, with the number of
modules ptxas assembled.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import math
import os
import platform
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")  # JAX's devices are this machine's CPU; the GPU is only a target
os.environ.setdefault("JAX_SKIP_CUDA_CONSTRAINTS_CHECK", "1")  # the plugin's check of the CUDA driver, absent here
if "--phases" in sys.argv:  # XLA logs its timers at these levels, read when XLA loads
    os.environ["TF_CPP_MIN_LOG_LEVEL"] = "0"
    os.environ["TF_CPP_VMODULE"] = "gpu_compiler=2,nvptx_compiler=2,hlo_pass_pipeline=1"

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import topologies

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_compile import CASES, captured_calls
from bench_kernel import random_batch

import fit
import fit.rows
import ks_jax
from ks_jax.case import get_output
from ks_jax.compilation import QUICK_GPU

# An NVIDIA H200 as XLA's GPU compiler sees it (its ``GpuTargetConfig``): Hopper (compute capability 9.0), 132
# multiprocessors, 50 MB of L2, 141 GB at 4.8 TB/s
TARGET = """
gpu_device_info {
  threads_per_block_limit: 1024 threads_per_warp: 32 shared_memory_per_block: 49152
  shared_memory_per_core: 233472 threads_per_core_limit: 2048 core_count: 132 fpus_per_core: 128
  block_dim_limit_x: 2147483647 block_dim_limit_y: 65535 block_dim_limit_z: 65535
  memory_bandwidth: 4800000000000 l2_cache_size: 52428800 clock_rate_ghz: 1.98 device_memory_size: 141000000000
  shared_memory_per_block_optin: 232448 cuda_compute_capability { major: 9 minor: 0 }
  registers_per_core_limit: 65536 registers_per_block_limit: 65536
}
platform_name: "CUDA"
dnn_version_info { major: 9 minor: 8 }
runtime_version { major: 12 minor: 9 }
device_description_str: "NVIDIA H200"
"""

# instructions of a compiled program's entry or loop body that launch nothing: arguments, constants, tuples,
# views, and the control flow whose bodies are counted on their own
NOT_LAUNCHED = {"parameter", "constant", "get-tuple-element", "tuple", "bitcast", "while", "conditional", "call",
                "after-all", "partition-id", "replica-id"}
ITEM_BYTES = {"pred": 1, "s8": 1, "u8": 1, "f16": 2, "bf16": 2, "s32": 4, "u32": 4, "f32": 4, "s64": 8, "u64": 8,
              "f64": 8}
ARRAY = re.compile(r"\b(" + "|".join(ITEM_BYTES) + r")\[([\d,]*)\]")
INSTRUCTION = re.compile(r"\s*(?:ROOT )?%(\S+) = (.*?) ([\w\-]+)\((.*)$")


def array_bytes(shape: str) -> int:
    """Bytes of the arrays an HLO type names (``f32[8,3]{1,0}``, or a tuple of them)."""
    return sum(ITEM_BYTES[kind] * math.prod(int(d) for d in dims.split(",") if d)
               for kind, dims in ARRAY.findall(shape))


def launches(text: str) -> dict:
    """Kernels of a compiled GPU program (its text) and the bytes they move: {"entry": (kernels, bytes), "loops":
    [(kernels, bytes), ...], "branches": [...]}, the entry's; those of one run of each computation that a while loop
    (its body: once per iteration) or a call runs, largest first; and those of each branch of a conditional (one of
    them runs each time), largest first. A kernel's bytes are those of its operands
    and results, each read or written once (an update in place: its update, read and written): more than a kernel
    that reads part of an operand moves, the traffic of memory where the kernels are too small to keep their
    operands in cache. Fused computations are inside the kernels and not counted."""
    computations, current, entry = {}, None, None
    for line in text.splitlines():
        head = re.match(r"^(ENTRY )?%(\S+) .*\{$", line)
        if head:
            current = head.group(2)
            computations[current] = {}
            entry = current if head.group(1) else entry
        elif current and (instruction := INSTRUCTION.match(line)):
            name, shape, op, rest = instruction.groups()
            computations[current][name] = (shape, op, rest)
    counts, todo, branches = {}, [entry], set()
    while todo:
        name = todo.pop()
        if name in counts or name not in computations:
            continue
        kernels = moved = 0
        for instruction_name, (shape, op, rest) in computations[name].items():
            if op in ("while", "call", "conditional"):
                todo += re.findall(r"(?:body|condition|to_apply)=%([\w.\-]+)", rest)
                # a conditional's branches: an index's list, or a predicate's two
                arms = re.findall(r"(?:true|false)_computation=%([\w.\-]+)", rest)
                for group in re.findall(r"branch_computations=\{([^}]*)\}", rest):
                    arms += [b.strip().lstrip("%") for b in group.split(",")]
                todo += arms
                branches.update(arms)
            if op not in NOT_LAUNCHED:
                operands = [computations[name].get(o, ("",))[0]
                            for o in re.findall(r"%([\w.\-]+)", rest.split(")", 1)[0])]
                kernels += 1
                if op == "dynamic-update-slice" or (op == "fusion" and "dynamic_update_slice" in instruction_name):
                    # in place: the buffer (the operand shaped as the result) is not read or written whole, the
                    # update is read and written into it
                    moved += 2 * sum(array_bytes(o) for o in operands if o.split("{")[0] != shape.split("{")[0])
                else:
                    moved += array_bytes(shape) + sum(array_bytes(o) for o in operands)
        counts[name] = (kernels, moved)
    return {"entry": counts.pop(entry), "loops": sorted((c for n, c in counts.items() if c[0] and n not in branches),
                                                        reverse=True),
            "branches": sorted((c for n, c in counts.items() if n in branches), reverse=True)}


TIMER = re.compile(r"(HLO pass: (\S+)|CompileToPtx for \S+|PtxToCubin for \S+) time: ([\d.]+) (us|ms|s) ")
SECONDS = {"us": 1e-6, "ms": 1e-3, "s": 1.0}


def logged(fun):
    """(fun(), what was written to this process's standard error meanwhile: XLA's log)."""
    with tempfile.TemporaryFile(mode="w+") as log:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(log.fileno(), 2)
        try:
            out = fun()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        log.seek(0)
        return out, log.read()


def phases(log: str) -> dict:
    """Seconds of a GPU compile's phases from XLA's log of it: its HLO passes, the fusion pass among them, LLVM's
    PTX, ptxas; and the modules ptxas assembled."""
    out = {"passes": 0.0, "fusion": 0.0, "ptx": 0.0, "ptxas": 0.0, "modules": 0}
    for timer in TIMER.finditer(log):
        seconds = float(timer.group(3)) * SECONDS[timer.group(4)]
        if timer.group(2):
            out["passes"] += seconds
            out["fusion"] += seconds if timer.group(2) == "priority-fusion" else 0.0
        elif timer.group(1).startswith("CompileToPtx"):
            out["ptx"] += seconds
        else:
            out["ptxas"] += seconds
            out["modules"] += 1
    return out


def size(nbytes: float) -> str:
    """Bytes in the unit that reads best (3 significant digits)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes:.0f} B"


def programs():
    """{name: (jitted function, args)}: every program above, traced on the accelerator's path."""
    out = {}
    _, batch = random_batch(1 << 22)
    kernel = jax.jit(jax.vmap(functools.partial(ks_jax.exchange, plan="accelerator")))
    for dtype in (jnp.float64, jnp.float32):
        out[f"kernel {np.dtype(dtype).name}"] = (kernel, jax.tree_util.tree_map(lambda x: x.astype(dtype), batch))
    for name, (fun, args) in captured_calls(large=True, plan="accelerator").items():
        out[name] = (fun.plain.jitted, args)
    edge = fit.rows._edge_jacobians

    def recording(*args):
        out["edge Jacobians"] = (edge.plain.jitted, args)
        return edge(*args)

    fit.rows._edge_jacobians = recording
    case = ks_jax.load_case(CASES / "auto_tbone.json")  # it sticks: evidence from its own exchange
    result = ks_jax.solve(case).result
    evidence = [{"quantity": q, "value": float(get_output(result, q)), "sigma": 0.5}
                for q in ("vehicles[0].delta_v_magnitude", "vehicles[1].delta_v_magnitude")]
    unknowns = {"vehicles[1].speed": {"bounds": ["0 mph", "60 mph"]}, "contact.friction": {"bounds": [0.1, 1.0]}}
    try:
        fit.reconstruct(case, unknowns, evidence, plan="accelerator")
    finally:
        fit.rows._edge_jacobians = edge
    return out


def for_target(args, device):
    """``args`` with each array replaced by its shape and dtype on ``device`` (a device of the target)."""
    sharding = jax.sharding.SingleDeviceSharding(device)

    def abstract(a):
        return jax.ShapeDtypeStruct(a.shape, a.dtype, sharding=sharding) if isinstance(a, (jax.Array, np.ndarray)) \
            else a

    return jax.tree_util.tree_map(abstract, args)


def compiled(jitted, args, options):
    """(seconds of XLA's compile, the compiled program) of ``jitted`` at ``args`` (for the target) with ``options``."""
    lowered = jitted.lower(*args)
    start = time.perf_counter()
    program = lowered.compile(compiler_options=options)
    return time.perf_counter() - start, program


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--only", default="", help="the programs whose name holds this")
    parser.add_argument("--hlo", default="", help="write each compiled program's text to this folder")
    parser.add_argument("--phases", action="store_true", help="the phases of each compile, from XLA's log")
    a = parser.parse_args()
    if a.hlo:
        Path(a.hlo).mkdir(parents=True, exist_ok=True)
    try:
        device = topologies.get_topology_desc(platform="cuda", target_config=TARGET, topology="1x1x1").devices[0]
    except (NotImplementedError, RuntimeError, ValueError) as e:  # no plugin, or one of another jax
        sys.exit(f"gpu_programs.py: no deviceless CUDA compiler ({type(e).__name__}: {e}); install "
                 f"jax-cuda12-plugin[with-cuda] and jax-cuda12-pjrt of jax's version, {jax.__version__}")
    print(f"gpu_programs.py --rounds {a.rounds}" + (f" --only {a.only!r}" if a.only else ""))
    print(f"  date     {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC")
    print(f"  machine  {platform.processor() or platform.machine()}, {os.cpu_count()} cores; jax {jax.__version__}")
    print(f"  target   {device.device_kind or 'NVIDIA H200'} (deviceless); QUICK_GPU {QUICK_GPU}")
    print("| program | compile, XLA's defaults | compile, QUICK_GPU | a call outside loops: kernels, bytes moved | "
          "an iteration of its loops: kernels, bytes moved | each branch of its conditionals |\n"
          "|---|---|---|---|---|---|")
    timed = []
    for name, (jitted, args) in programs().items():
        if a.only not in name:
            continue
        args = for_target(args, device)
        ways = {"defaults": None, "quick": QUICK_GPU}
        seconds = {way: [] for way in ways}
        for k in range(a.rounds):
            for way in (list(ways) if k % 2 == 0 else list(ways)[::-1]):
                jax.clear_caches()
                options = ways[way]
                if a.phases:  # every compile's log kept off the terminal; the first with XLA's defaults read
                    (s, program), log = logged(lambda: compiled(jitted, args, options))
                    if k == 0 and way == "defaults":
                        timed.append((name, s, phases(log)))
                else:
                    s, program = compiled(jitted, args, options)
                seconds[way].append(s)
                if a.hlo:
                    stem = re.sub(r"\W+", "_", name)
                    Path(a.hlo, f"{stem}_{way}.hlo.txt").write_text(program.as_text())
        counted = launches(program.as_text())
        loops = "; ".join(f"{n}, {size(b)}" for n, b in counted["loops"]) or "(no loop)"
        arms = "; ".join(f"{n}, {size(b)}" for n, b in counted["branches"]) or "(none)"
        print(f"| {name} | {statistics.median(seconds['defaults']):.1f} s | {statistics.median(seconds['quick']):.1f} s"
              f" | {counted['entry'][0]}, {size(counted['entry'][1])} | {loops} | {arms} |", flush=True)
    if timed:
        print("\n| program (XLA's defaults) | compile | HLO passes (the fusion pass) | LLVM to PTX | ptxas (modules) "
              "|\n|---|---|---|---|---|")
        for name, s, p in timed:
            print(f"| {name} | {s:.1f} s | {p['passes']:.1f} s ({p['fusion']:.1f} s) | {p['ptx']:.1f} s | "
                  f"{p['ptxas']:.1f} s ({p['modules']}) |")


if __name__ == "__main__":
    main()
