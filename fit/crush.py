"""Crush energy as evidence (docs/fit.md, "Crush energy"; docs/model.md, "Crush energy").

An evidence entry ``{"quantity": "vehicles[i].crush_energy"}`` is the energy vehicle i's crush absorbed: its
``value`` and ``sigma`` (energies), or, where the entry gives neither, those of the vehicle's crush profile and
stiffness (``ks_jax.solve.crush.energy_and_sigma``: the sigma from the case's sigmas). The exchange's prediction of it
is the vehicle's share of the first exchange's energy loss, the share its EES is made of (E_i = m_i EES_i^2 / 2,
shared by crush energy where both vehicles have a profile, else by the box overlap's crushes). It enters the fit
as the EES it gives, sqrt(2 E / m) with the case's mass, its sigma carried over to first order,
sigma_EES = sigma_E / sqrt(2 m E): the fit's residual is then how far momentum and crush disagree, in sigmas.
"""

from __future__ import annotations

import math
import re

from ks_jax import units as U
from ks_jax.case import Case, CaseError
from ks_jax.solve.crush import energy_and_sigma

PATH = re.compile(r"^vehicles\[(\d+)\]\.crush_energy$")


def is_crush_energy(path) -> bool:
    """Whether an evidence ``path`` is a vehicle's crush energy."""
    return isinstance(path, str) and PATH.match(path.replace(" ", "")) is not None


def as_ees(case: Case, path: str, energy: float | None, sigma: float | None, where: str) -> tuple:
    """(EES path, value m/s, sigma m/s) of crush-energy evidence at ``path`` with ``energy`` and ``sigma`` (J; both
    None: from the vehicle's crush profile). CaseError naming ``where`` for a vehicle that is not one of the first
    exchange's, a missing profile or sigma, or an energy that is not positive."""
    i = int(PATH.match(path.replace(" ", "")).group(1))
    if i >= case.vehicle_count or i not in case.between:
        raise CaseError(f"{where}: vehicles[{i}] is not a vehicle of the first exchange ({_pair(case)}); crush energy "
                        "is compared with that exchange's energy loss")
    if energy is None:
        profile = case.crush[i] if case.crush else None
        if profile is None:
            raise CaseError(f"{where}: vehicles[{i}] has no crush profile; give its stiffness and crush_profile, or "
                            "the evidence's value and sigma (energies, e.g. \"40000 ft*lbf\")")
        energy, sigma = energy_and_sigma(profile)
        if not sigma > 0:
            raise CaseError(f"{where}: vehicles[{i}]'s crush profile gives no uncertainty; give its stiffness's "
                            "A_sigma and B_sigma or its crush_profile's depth_sigma, or the evidence's sigma")
    elif not (math.isfinite(sigma) and sigma > 0):
        raise CaseError(f"{where}: sigma {sigma / U.FT_LBF:.6g} ft lbf ({sigma:.6g} J): must be positive")
    if not (math.isfinite(energy) and energy > 0):
        raise CaseError(f"{where}: value {energy / U.FT_LBF:.6g} ft lbf ({energy:.6g} J): a crush energy must be "
                        "positive")
    mass = float(case.inputs.vehicles[i].mass)
    ees = math.sqrt(2.0 * energy / mass)
    return f"vehicles[{i}].ees", ees, sigma / math.sqrt(2.0 * mass * energy)


def _pair(case: Case) -> str:
    return " and ".join(case.body_path(b) for b in case.between)
