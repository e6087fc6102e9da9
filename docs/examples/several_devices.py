"""A sweep and a batch of reconstructions spread over several devices, and over several hosts (docs/devices.md).

Every device of this host, in one process (on a machine with one device, that one):

    python docs/examples/several_devices.py

Forced CPU devices, to try the sharded programs anywhere (``--compare`` also runs both on one device and prints
the largest differences):

    JAX_NUM_CPU_DEVICES=4 JAX_PLATFORMS=cpu python docs/examples/several_devices.py --compare

Several hosts: one process per host, started alike with its own ``--process-id`` (here two on one machine).
Each solves its share (a range of the sweep's points, every ``processes``-th reconstruction) on its own
devices and writes it to ``--out``; joining the parts is the caller's:

    python docs/examples/several_devices.py --coordinator 127.0.0.1:12355 --processes 2 --process-id 0 --out p0.json &
    python docs/examples/several_devices.py --coordinator 127.0.0.1:12355 --processes 2 --process-id 1 --out p1.json

The output is JSON: the devices, the sweep's range and impulses, and each reconstruction's estimate (mph).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import fit
import ks_jax

CASES = Path(ks_jax.__file__).parent / "cases"
SPEEDS = np.linspace(2.0, 30.0, 40)  # vehicles[1].speed, m/s
RESTITUTIONS = np.linspace(0.0, 0.5, 25)
FITS = 8  # reconstructions of the shipped fit case, each with its own evidence


def evidence(k):
    """The k-th reconstruction's evidence: the shipped case's delta-Vs, moved by a seeded draw of their sigma."""
    rng = np.random.default_rng(k)
    return [{"quantity": q, "value": f"{v + 0.3 * rng.standard_normal():.4f} mph", "sigma": "0.3 mph"}
            for q, v in (("vehicles[0].delta_v_magnitude", 6.47), ("vehicles[1].delta_v_magnitude", 10.03))]


def solve(devices, process=0, processes=1):
    """This process's share on ``devices``: points lo..hi of the sweep, and reconstructions process,
    process + processes, ..."""
    case = ks_jax.load_case(CASES / "seed_000_saturn_pontiac.json")
    total = len(SPEEDS) * len(RESTITUTIONS)
    lo, hi = total * process // processes, total * (process + 1) // processes
    swept = ks_jax.sweep(case, {"vehicles[1].speed": SPEEDS, "contact.restitution": RESTITUTIONS},
                         outputs=["contact.impulse_magnitude"], index_range=(lo, hi), devices=devices, progress=False)
    fit_case = ks_jax.load_case(CASES / "fit_seed_001.json")
    mine = list(range(process, FITS, processes))
    results = fit.reconstruct_batch([fit_case] * len(mine), evidence=[evidence(k) for k in mine], starts=4,
                                    devices=devices)
    speed = {k: r.estimate["vehicles[1].speed"] / ks_jax.units.MPH for k, r in zip(mine, results)}
    return {"devices": [str(d) for d in devices], "range": [lo, hi],
            "impulse": swept["contact.impulse_magnitude"].tolist(), "speed_mph": speed}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--coordinator", help="host:port of process 0, for several processes (jax.distributed)")
    ap.add_argument("--processes", type=int, default=1)
    ap.add_argument("--process-id", type=int, default=0)
    ap.add_argument("--out", help="write the JSON here instead of printing it")
    ap.add_argument("--compare", action="store_true", help="also solve on one device; print the largest differences")
    args = ap.parse_args(argv)
    if args.coordinator:
        jax.distributed.initialize(args.coordinator, num_processes=args.processes, process_id=args.process_id)
    # this process's devices: a computation on them needs nothing from the other processes
    devices = jax.local_devices()
    out = solve(devices, jax.process_index(), jax.process_count())
    if args.compare:
        one = solve(devices[:1])
        out["largest_difference"] = {
            "impulse": float(np.max(np.abs(np.subtract(out["impulse"], one["impulse"])))),
            "speed_mph": max(abs(out["speed_mph"][k] - one["speed_mph"][k]) for k in out["speed_mph"])}
    text = json.dumps(out)
    if args.out:
        Path(args.out).write_text(text)
    else:
        print(text)


if __name__ == "__main__":
    main()
