# %% [markdown]
# # Reading Kudlich-Slibar impulse data
#
# The two Virtual CRASH manual chapters on KS impulse data, "Reading Collision Data" and "Reading
# Kudlich-Slibar Impulse Data", each stage an inline rear impact and read the auto-ees panel: impulse, deformation energy, delta-V, crush and EES. Here both are solved with ks-jax from
# the case files shipped in the package, and the impulse, energy, delta-V and EES are rebuilt by hand beside the
# manual's, step by step. (The crushes are not a check: the "Reading Collision Data" case's dimensions were chosen so that
# the box-to-centroid distances are the manual's deformations, and the hand EES below uses those crushes.)

# %%
import math
from importlib import resources

import jax
jax.config.update("jax_enable_x64", True)
import ks_jax
from ks_jax import units as U
from ks_jax.report import text_report

cases = resources.files("ks_jax.cases")
saturn_case = ks_jax.load_case(cases / "seed_000_saturn_pontiac.json")
lucid_case = ks_jax.load_case(cases / "seed_001_lucid_kia.toml")
sol0, sol1 = ks_jax.solve([saturn_case, lucid_case])

# %% [markdown]
# ## Reading Collision Data: Pontiac Grand Prix into a Saturn L300
#
# Saturn (vehicle 1) 3183.475 lbf at 5 mph; Pontiac (vehicle 2) 3496.531 lbf at 21 mph; restitution 0.1;
# centroid at CG height on the line of the CGs, so no rotation and the collision is one-dimensional:
#
# - reduced mass m = m1 m2 / (m1 + m2)
# - impulse J = (1 + eps) m |u.n|
# - energy loss E = (1 - eps^2) m (u.n)^2 / 2
# - delta-V_i = J / m_i
# - EES (Burg): EES_2 = sqrt(2 E / (m2 (1 + C1/C2))), EES_1 = EES_2 sqrt(m2 C1 / (m1 C2))

# %%
v1, v2 = saturn_case.inputs.vehicles
eps = float(saturn_case.inputs.contact.restitution)
m1, m2 = float(v1.mass), float(v2.mass)
m_red = m1 * m2 / (m1 + m2)
u = float(v2.speed - v1.speed)                      # closing speed at the centroid, m/s
J = (1 + eps) * m_red * u
E = 0.5 * (1 - eps**2) * m_red * u**2
C1, C2 = (float(v.crush) for v in sol0.result.vehicles)
ees2 = math.sqrt(2 * E / (m2 * (1 + C1 / C2)))
ees1 = ees2 * math.sqrt(m2 / m1 * C1 / C2)

rows = [
    ("reduced mass", m_red / U.SLUG, None, None, "slug"),
    ("impulse", J / U.LBF_S, sol0.result.contact.impulse_magnitude / U.LBF_S, 1336.904, "lbf s"),
    ("deformation energy", E / U.FT_LBF, sol0.result.contact.energy_loss / U.FT_LBF, 14117.71, "ft lbf"),
    ("delta-V Saturn", J / m1 / U.MPH, sol0.result.vehicles[0].delta_v_magnitude / U.MPH, 9.21, "mph"),
    ("delta-V Pontiac", J / m2 / U.MPH, sol0.result.vehicles[1].delta_v_magnitude / U.MPH, 8.39, "mph"),
    ("EES Saturn", ees1 / U.MPH, sol0.result.vehicles[0].ees / U.MPH, 11.281, "mph"),
    ("EES Pontiac", ees2 / U.MPH, sol0.result.vehicles[1].ees / U.MPH, 2.213, "mph"),
]
print(f"{'':22}{'by hand':>14}{'ks-jax':>14}{'manual':>14}")
for name, hand, ks, manual, unit in rows:
    f = lambda x: " " * 14 if x is None else f"{float(x):14.3f}"
    print(f"{name:22}{f(hand)}{f(ks)}{f(manual)}  {unit}")
assert abs(float(sol0.result.contact.impulse_magnitude) - 5946.847) < 1e-3

# %% [markdown]
# The auto-ees style panel, with the manual's panel values at the bottom:

# %%
print(text_report(sol0))

# %% [markdown]
# ## Reading Kudlich-Slibar Impulse Data: Kia K5 into a Lucid Air
#
# Lucid (vehicle 1) 155.75 slug at 5 mph; Kia (vehicle 2) 100.38 slug at 20 mph; restitution 0.1.
# The closing speed is exactly 22 ft/s (15 mph) and the reduced mass 61.04 slug to four digits, so the impulse
# is 1.1 x 61.04 x 22 = 1477.17 lbf s; the chapter prints 1477.21 lbf s, and beside it 6571.96 N s, which is
# 1477.44 lbf s. Its kinetic energies carry the same slips in the last digits (14624.38 ft lbf against
# 14623.97 by hand). The hand column here is exact arithmetic, and ks-jax agrees with it.

# %%
v1, v2 = lucid_case.inputs.vehicles
m1, m2 = float(v1.mass), float(v2.mass)
m_red = m1 * m2 / (m1 + m2)
u = float(v2.speed - v1.speed)
J = 1.1 * m_red * u
after1 = float(v1.speed) + J / m1
after2 = float(v2.speed) - J / m2
ke = lambda m, v: 0.5 * m * v**2
E = ke(m1, float(v1.speed)) + ke(m2, float(v2.speed)) - ke(m1, after1) - ke(m2, after2)
res = sol1.result
rows = [
    ("reduced mass", m_red / U.SLUG, None, 61.04, "slug"),
    ("impulse", J / U.LBF_S, res.contact.impulse_magnitude / U.LBF_S, 1477.21, "lbf s"),
    ("delta-V Lucid", J / m1 / U.MPH, res.vehicles[0].delta_v_magnitude / U.MPH, 6.47, "mph"),
    ("delta-V Kia", J / m2 / U.MPH, res.vehicles[1].delta_v_magnitude / U.MPH, 10.03, "mph"),
    ("Lucid after", after1 / U.FT, res.vehicles[0].speed_after / U.FT, 16.82, "ft/s"),
    ("Kia after", after2 / U.FT, res.vehicles[1].speed_after / U.FT, 14.62, "ft/s"),
    ("deformation energy", E / U.FT_LBF, res.contact.energy_loss / U.FT_LBF, 14624.38, "ft lbf"),
]
print(f"{'':22}{'by hand':>14}{'ks-jax':>14}{'manual':>14}")
for name, hand, ks, manual, unit in rows:
    f = lambda x: " " * 14 if x is None else f"{float(x):14.3f}"
    print(f"{name:22}{f(hand)}{f(ks)}{f(manual)}  {unit}")

# %%
print(text_report(sol1))

# %% [markdown]
# ## The picture
#
# The top view: both outlines, the centroid, the contact plane, the normal, the impulse on each vehicle, the
# friction cone and the velocities before and after.

# %%
import matplotlib.pyplot as plt
from ks_jax.plot import top_view

fig, axes = plt.subplots(1, 2, figsize=(11, 6.5))
top_view(sol0, ax=axes[0])
top_view(sol1, ax=axes[1])
fig.tight_layout()
