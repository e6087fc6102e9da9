"""Where the time of a chunked gradient goes: ``jax.value_and_grad`` of a batched loss through
``jax.vmap(exchange)``, profiled. Not a test.

    .venv/bin/python benchmarks/profile_gradient.py [--rows 262144] [--loss residuals|delta-V] [--top N] [--forward]

Runs the gradient of one of bench_kernel.py's losses twice under ``jax.profiler`` (a Perfetto
trace) with XLA's optimized program dumped beside it, and prints, per row and summed over both
cores (thread time, so it adds up to more than the wall time):
- each XLA thunk's own time (its children's taken out), grouped by phase: the forward pass, the
  forward computed again in the reverse pass (``rematted``), and the transposed derivative; and by
  the kind of operation its fusion is named after (moving data: concatenates, slices, dynamic
  slices and updates, copies, pads, transposes; arithmetic: the rest);
- the bytes per row that leave each fenced stage (an XLA conditional): in the reverse pass these
  are the residuals that the transposed stage reads back.
``--forward``: profile ``jax.jit(jax.vmap(exchange))`` instead (batch-first, every result, as
bench_kernel.py times it); all of its thunks are then in the forward pass or outside the loops.
The profile itself slows the program down; read the shares, not the absolute times.
"""

from __future__ import annotations

import argparse
import collections
import gzip
import json
import math
import os
import re
import sys
import tempfile
from pathlib import Path

BYTES = {"f64": 8, "f32": 4, "s64": 8, "s32": 4, "pred": 1, "u8": 1}
MOVES = ("concatenate", "slice", "copy", "pad", "transpose")  # dynamic-slice, dynamic-update-slice too


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=1 << 18)
    ap.add_argument("--loss", choices=("residuals", "delta-V"), default="residuals")
    ap.add_argument("--top", type=int, default=0,
                    help="also list the N heaviest groups of thunks (phase, kind of fusion, shape)")
    ap.add_argument("--forward", action="store_true", help="profile jax.jit(jax.vmap(exchange)) instead")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="ks_profile_"))
    # XLA reads its flags when JAX starts its backend: set before jax is imported
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} --xla_dump_to={work / 'hlo'} --xla_dump_hlo_as_text"

    import jax
    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_kernel as bk
    from ks_jax.exchange import CHUNK_ROWS

    n = args.rows
    _, last = bk.random_batch(n)
    first = bk.batch_first(last)
    if args.forward:
        grad = jax.jit(lambda a: jax.vmap(bk.exchange)(*a))
    else:
        loss = bk.batched_loss(bk.residuals if args.loss == "residuals" else bk.delta_v, 0, chunked=True)
        grad = jax.jit(jax.value_and_grad(lambda a: loss(a, None)))
    jax.block_until_ready(grad(first))
    with jax.profiler.trace(str(work / "trace"), create_perfetto_trace=True):
        for _ in range(2):
            jax.block_until_ready(grad(first))

    hlo_file = max((work / "hlo").glob("*jit__lambda*.cpu_after_optimizations.txt"), key=lambda p: p.stat().st_size)
    computation, op_name, conds, shapes = {}, {}, [], {}
    current = None
    for line in hlo_file.read_text().splitlines():
        head = re.match(r"^(?:ENTRY )?%?([\w.\-]+) .*\{$", line)
        if head:
            current = head.group(1)
        inst = re.match(r"\s*(?:ROOT )?%([\w.\-]+) = (\(.*?\)|\S+) ([\w\-]+)\(", line)
        if not inst:
            continue
        name, shape, op = inst.groups()
        computation[name] = current
        shapes[name] = shape
        found = re.search(r'op_name="([^"]*)"', line)
        op_name[name] = found.group(1) if found else ""
        if op == "conditional":
            size = 0
            for dtype, dims in re.findall(r"(f64|f32|s64|s32|pred|u8)\[([\d,]*)\]", shape):
                size += BYTES[dtype] * math.prod(int(d) for d in dims.split(",") if d)
            conds.append((shape.count("["), size, op_name[name]))

    trace = json.load(gzip.open(next((work / "trace").rglob("perfetto_trace.json.gz"))))
    events = [e for e in (trace["traceEvents"] if isinstance(trace, dict) else trace)
              if e.get("ph") == "X" and "dur" in e]
    by_thread = collections.defaultdict(list)
    for e in events:
        by_thread[e.get("tid")].append(e)
    for es in by_thread.values():  # own time: an event's duration less that of the events nested in it
        es.sort(key=lambda e: (e["ts"], -e["dur"]))
        stack = []
        for e in es:
            while stack and stack[-1]["ts"] + stack[-1]["dur"] <= e["ts"]:
                stack.pop()
            e["own"] = e["dur"]
            if stack:
                stack[-1]["own"] -= e["dur"]
            stack.append(e)

    def phase(op):  # from the op name XLA keeps of the JAX transformations
        if "transpose(" not in op:
            return "forward pass" if op else "outside the loops (no op name)"
        return "forward again (reverse pass)" if "rematted" in op else "transposed derivative"

    def kind(name):
        return "moving data" if any(m in name.split(".")[0] for m in MOVES) else "arithmetic"

    per_kind = collections.Counter()
    for e in events:
        if e["name"] in computation:
            per_kind[(phase(op_name[e["name"]]), kind(e["name"]))] += e["own"]
    per_phase = collections.Counter()
    for (p, _), t in per_kind.items():
        per_phase[p] += t
    total = sum(per_phase.values())
    ns = 1e3 / (2 * n)  # us of trace time over two calls -> ns per row
    what = "jax.jit(jax.vmap(exchange))" if args.forward else f"value_and_grad of the {args.loss} loss through jax.vmap(exchange)"
    print(f"{what}, {n} rows, jax {jax.__version__}")
    print(f"thread time per row (both cores), from the profile: {total * ns:.0f} ns")
    for p, t in per_phase.most_common():
        parts = ", ".join(f"{k} {per_kind[(p, k)] * ns:.0f}" for k in ("arithmetic", "moving data"))
        print(f"  {p:32s} {t * ns:6.0f} ns ({100 * t / total:4.1f}%): {parts}")
    print("bytes per row leaving each fenced stage (XLA conditional):")
    for count, size, o in conds:
        where = {"forward again (reverse pass)": "reverse pass, forward again",
                 "transposed derivative": "reverse pass"}.get(phase(o), "forward pass")
        print(f"  {count:4d} arrays {size / CHUNK_ROWS:7.0f} B/row  {where}")
    if args.top:
        groups, counts = collections.Counter(), collections.Counter()
        for e in events:
            if e["name"] in computation:
                key = (phase(op_name[e["name"]]), e["name"].split(".")[0], shapes[e["name"]][:48])
                groups[key] += e["own"]
        for e in {e["name"] for e in events if e["name"] in computation}:
            counts[(phase(op_name[e]), e.split(".")[0], shapes[e][:48])] += 1
        print("heaviest groups of thunks (phase, fusion kind, output shape; count): ns per row")
        for key, t in groups.most_common(args.top):
            print(f"  {t * ns:7.0f}  {key[0]:30s} {key[1]:32s} {key[2]:48s} x{counts[key]}")
    print(f"(trace and HLO in {work})")


if __name__ == "__main__":
    main()
