"""Crush energy from a measured crush profile and the damaged side's stiffness (CRASH3; docs/model.md, "Crush
energy").

The stiffness model: across the damage, each unit of width resists crushing with a force per unit width
A + B C that grows linearly with the crush depth C, from a threshold A (below which the structure springs back
without damage). The energy absorbed per unit width is then A C + B C^2 / 2 + G, where G = A^2 / (2 B) is the
energy absorbed without residual crush. Over a profile of n equally spaced depths C_1 .. C_n across the damage
width L, the depth is taken as linear between neighbouring points, and each of the n - 1 strips of width
L / (n - 1) contributes

    L / (n - 1) [ A (C_k + C_k+1) / 2 + B (C_k^2 + C_k C_k+1 + C_k+1^2) / 6 + G ],

the exact integral of the linear depth over the strip: for n = 6 this is CRASH3's six-point formula. A principal
force alpha off the damaged surface's normal multiplies the energy by 1 + tan^2 alpha (the force's component
along the normal did the crushing).

Every function here is pure and elementwise in its scalar arguments (vmaps and differentiates as any JAX
function): the depths' last axis is the profile.
"""

from __future__ import annotations

import jax.numpy as jnp

from . import linalg as la


def threshold_energy(a, b):
    """G = A^2 / (2 B): the energy per unit width absorbed without residual crush (J/m)."""
    return a * a / (2.0 * b)


def crush_energy(width, depths, a, b, alpha=0.0):
    """The energy (J) absorbed by crushing a damage ``width`` (m) to ``depths`` (..., n) (m, n >= 2, equally spaced
    across the width) against a stiffness ``a`` (N/m) and ``b`` (N/m^2), with the principal force ``alpha`` (rad)
    off the damaged surface's normal."""
    depths, a, b = jnp.asarray(depths), jnp.asarray(a), jnp.asarray(b)
    near, far = depths[..., :-1], depths[..., 1:]
    strips = a[..., None] * (near + far) / 2.0 + b[..., None] * (near * near + near * far + far * far) / 6.0
    per_width = jnp.mean(strips, axis=-1) + threshold_energy(a, b)  # the n - 1 strips' mean over the width
    return width * per_width * (1.0 + jnp.tan(alpha) ** 2)


def crush_ees(energy, mass):
    """The energy-equivalent speed (m/s) of a vehicle of ``mass`` (kg) that absorbed ``energy`` (J): the speed at
    which its kinetic energy is that energy, sqrt(2 E / m)."""
    return la.safe_sqrt(2.0 * energy / mass)


def crush_delta_v(energy1, energy2, mass1, mass2):
    """CRASH3's delta-V (m/s) of each of two vehicles, (vehicle 1's, vehicle 2's), from both crush energies (J) and
    masses (kg), for a central impact that ends at a common velocity: the energy a plastic impact of closing speed
    u loses is m1 m2 u^2 / (2 (m1 + m2)), and each vehicle's delta-V is its share of u,
    dV1 = sqrt(2 (E1 + E2) m2 / (m1 (m1 + m2)))."""
    total = energy1 + energy2
    both = mass1 + mass2
    return (la.safe_sqrt(2.0 * total * mass2 / (mass1 * both)), la.safe_sqrt(2.0 * total * mass1 / (mass2 * both)))
