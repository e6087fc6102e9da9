"""A solved case's crush-energy results (docs/model.md, "Crush energy"): for each vehicle with a measured crush
profile, the energy its crush absorbed, that energy's one-sigma uncertainty from the case's, its energy-equivalent
speed, and the CRASH3 delta-V of the first exchange's vehicles. They follow from the case's inputs alone (the
profile, the stiffness and the masses), not from the exchange: set beside the exchange's delta-V and energy loss,
they are the crush's independent account of the crash."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..case import Case
from ..model import crush as C

FIELDS = ("crush_energy", "crush_energy_sigma", "crush_ees", "crush_delta_v")


def energy_and_sigma(profile) -> tuple:
    """(E, its sigma) in J of a ``case.crush.CrushProfile``: the sigma to first order from those of the width, each
    depth, A and B, taken as independent (the root sum of squares of each derivative times its sigma)."""
    args = (jnp.asarray(profile.width), jnp.asarray(profile.depths), jnp.asarray(profile.a), jnp.asarray(profile.b))
    energy, grads = jax.value_and_grad(lambda *a: C.crush_energy(*a, profile.alpha), argnums=(0, 1, 2, 3))(*args)
    d_width, d_depths, d_a, d_b = (np.asarray(g, float) for g in grads)
    variance = ((d_width * profile.width_sigma) ** 2 + np.sum((d_depths * profile.depth_sigma) ** 2)
                + (d_a * profile.a_sigma) ** 2 + (d_b * profile.b_sigma) ** 2)
    return float(energy), math.sqrt(float(variance))


def crush_results(case: Case) -> list:
    """For each of the case's vehicles, {"crush_energy", "crush_energy_sigma", "crush_ees", "crush_delta_v"} (J, J,
    m/s, m/s), each None where undefined: all four for a vehicle without a crush profile; ``crush_delta_v`` unless
    the vehicle is one of the first exchange's bodies and the other has a profile too (or is a fixed object, which
    takes no energy and no delta-V: the vehicle's is then its EES)."""
    n = case.vehicle_count
    out = [dict.fromkeys(FIELDS) for _ in range(n)]
    if not case.crush:
        return out
    masses = [float(case.inputs.vehicles[i].mass) for i in range(n)]
    energies = [None] * n
    for i, profile in enumerate(case.crush):
        if profile is None:
            continue
        energy, sigma = energy_and_sigma(profile)
        energies[i] = energy
        out[i].update(crush_energy=energy, crush_energy_sigma=sigma,
                      crush_ees=float(C.crush_ees(jnp.asarray(energy), masses[i])))
    i, j = case.between
    if i < n and energies[i] is not None and j >= n:
        out[i]["crush_delta_v"] = out[i]["crush_ees"]
    elif i < n and j < n and energies[i] is not None and energies[j] is not None:
        dv_i, dv_j = C.crush_delta_v(jnp.asarray(energies[i]), jnp.asarray(energies[j]), masses[i], masses[j])
        out[i]["crush_delta_v"], out[j]["crush_delta_v"] = float(dv_i), float(dv_j)
    return out
