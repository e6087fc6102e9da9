# %% [markdown]
# # Parameter sweeps
#
# A reconstruction rarely has one set of inputs: speeds, restitution, friction and the impulse centroid are known
# only within ranges. `ks_jax.sweep` solves one case at every point of a grid of some of its inputs in one
# compiled, vectorised call and hands back only the results asked for. This notebook shows
#
# 1. delta-V and deformation energy over the bullet vehicle's speed and the restitution (the Virtual CRASH
#    manual's "Reading Kudlich-Slibar Impulse Data": Kia K5 into the rear of a Lucid Air), as maps;
# 2. where an oblique contact sticks and where it slides, over friction and the position of the impulse centroid;
# 3. a million-point sweep, timed.
#
# Sweep values are SI (m/s, m, rad); the plots convert to mph and ft.

# %%
import time
from importlib import resources

import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import matplotlib.pyplot as plt
from matplotlib.colors import ListedColormap

import ks_jax
from ks_jax import units as U
from ks_jax.case import case_from_dict
from ks_jax import sweep

cases = resources.files("ks_jax.cases")
lucid_case = ks_jax.load_case(cases / "seed_001_lucid_kia.toml")

# %% [markdown]
# ## 1. Delta-V and energy over bullet speed x restitution
#
# The Lucid Air (vehicle 1) is struck at 5 mph; the Kia's speed runs from 6 to 60 mph and the restitution
# from 0 to 0.5. The grid is 109 x 51 points.

# %%
kia_speed = np.linspace(6, 60, 109) * U.MPH          # m/s
restitution = np.linspace(0, 0.5, 51)
r = sweep(lucid_case,
          over={"vehicles[1].speed": kia_speed, "contact.restitution": restitution},
          outputs=["vehicles[0].delta_v_magnitude", "vehicles[1].delta_v_magnitude", "contact.energy_loss"])
print(r.shape, r.status_counts, f"solved in {r.seconds:.2f} s after compiling in {r.compile_seconds:.2f} s")

# %%
X, Y = np.meshgrid(kia_speed / U.MPH, restitution, indexing="ij")   # result axes: (speed, restitution)
panels = [("vehicles[0].delta_v_magnitude", U.MPH, "delta-V Lucid Air (vehicle 1) [mph]"),
          ("vehicles[1].delta_v_magnitude", U.MPH, "delta-V Kia K5 (vehicle 2) [mph]"),
          ("contact.energy_loss", 1000 * U.FT_LBF, "deformation energy [1000 ft lbf]")]
fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharey=True)
for ax, (path, unit, label) in zip(axes, panels):
    Z = r[path] / unit
    mesh = ax.pcolormesh(X, Y, Z, shading="auto", cmap="viridis")
    cs = ax.contour(X, Y, Z, levels=6, colors="white", linewidths=0.6)
    ax.clabel(cs, fontsize=7, fmt="%.0f")
    fig.colorbar(mesh, ax=ax, label=label)
    ax.plot(20, 0.1, "r*", ms=12, label="manual: 20 mph, eps = 0.1")
    ax.set_xlabel("Kia K5 speed before impact [mph]")
    ax.set_title(label.split(" [")[0])
axes[0].set_ylabel("restitution eps [-]")
# the line of (speed, restitution) pairs that give the manual's 6.47 mph delta-V of the Lucid
axes[0].contour(X, Y, r["vehicles[0].delta_v_magnitude"] / U.MPH, levels=[6.47], colors="red", linewidths=1.5)
axes[0].plot([], [], "r-", label="delta-V Lucid = 6.47 mph (manual)")
axes[0].legend(loc="upper right", fontsize=9)
fig.tight_layout()

# %% [markdown]
# What the maps say:
#
# - **delta-V** grows linearly with the closing speed (Kia speed minus the Lucid's 5 mph) and with (1 + eps):
#   delta-V_i = (1 + eps) m_red (v_2 - v_1) / m_i. The lighter Kia always gets the larger delta-V
#   (m_1 / m_2 = 1.55 times the Lucid's).
# - The red line in the first map holds every (speed, restitution) pair that gives the manual's 6.47 mph
#   delta-V of the Lucid: 20 mph at eps = 0.1, but also about 18.8 mph at eps = 0.2 or 21.5 mph at eps = 0. A delta-V alone
#   fixes only (1 + eps) times the closing speed; the restitution has to come from elsewhere (crash tests,
#   post-impact separation). Notebook 03 shows the fit saying exactly this.
# - **Deformation energy** E = (1 - eps^2) m_red u^2 / 2 grows with the square of the closing speed and
#   *falls* with restitution: the more elastic the contact, the less energy goes into crush.

# %% [markdown]
# ## 2. Stick or slide: friction x centroid position on an oblique contact
#
# An angled side impact: a sedan (vehicle 1) crossing at 15 mph is struck on its right side by a pickup
# (vehicle 2) travelling at 30 mph on a heading of 110 deg, so the pickup also moves against the sedan's
# direction. The contact plane is the sedan's right side (normal azimuth 90 deg, from the pickup into the
# sedan). The impulse centroid is moved along that side, from 8 ft behind to 6 ft ahead of the sedan's CG
# (`contact.point[0]`), and the friction limit mu from 0 to 1.
#
# The KS model first computes the stick impulse (the one that brings the relative velocity at the centroid
# to zero) with tangential part |T_c| and normal part N_c. If mu >= |T_c| / N_c the friction can supply it and
# the contact **sticks**; otherwise the contact **slides**: the tangential impulse is capped at mu times the
# normal one (`contact.sliding` is True).

# %%
angled = {
    "name": "Angled side impact: pickup into the right side of a sedan",
    "vehicles": [
        {"name": "Sedan", "weight": "3300 lbf", "inertia": ["500 kg*m^2", "2400 kg*m^2", "2600 kg*m^2"],
         "length": "15.5 ft", "width": "6 ft", "height": "4.7 ft", "cg_to_front": "6.9 ft", "cg_height": "1.8 ft",
         "position": ["0 ft", "0 ft"], "yaw": 0, "speed": "15 mph"},
        {"name": "Pickup", "weight": "4800 lbf", "inertia": ["800 kg*m^2", "4200 kg*m^2", "4500 kg*m^2"],
         "length": "19 ft", "width": "6.7 ft", "height": "6.2 ft", "cg_to_front": "8 ft", "cg_height": "2.2 ft",
         "position": ["2.74 ft", "-10.52 ft"], "yaw": 110, "speed": "30 mph"}],
    "contact": {"point": ["0 ft", "-2.5 ft", "2 ft"], "normal": 90, "restitution": 0.1, "friction": 0.5},
}
angled_case = case_from_dict(angled)

friction = np.linspace(0, 1.0, 101)
offset = np.linspace(-8, 6, 141) * U.FT                        # contact.point[0], m
outputs = ["contact.sliding", "contact.impulse_tangential", "contact.impulse_normal",
           "vehicles[0].delta_v_magnitude", "vehicles[0].delta_yaw_rate"]
s = sweep(angled_case, over={"contact.friction": friction, "contact.point[0]": offset}, outputs=outputs)
# the friction each centroid position needs to stick: |T_c| / N_c, from the same sweep with friction 100
stick = sweep(angled_case, over={"contact.point[0]": offset, "contact.friction": [100.0]},
              outputs=["contact.impulse_tangential", "contact.impulse_normal"])
mu_needed = (stick["contact.impulse_tangential"] / stick["contact.impulse_normal"])[:, 0]
print(s.status_counts, f"sliding at {s['contact.sliding'].mean():.0%} of the points")

# %%
F, O = np.meshgrid(friction, offset / U.FT, indexing="ij")      # result axes: (friction, offset)
fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)

ax = axes[0]
mesh = ax.pcolormesh(O, F, s["contact.sliding"].astype(float), shading="auto",
                     cmap=ListedColormap(["#9ecae1", "#fdae6b"]), vmin=0, vmax=1)
cb = fig.colorbar(mesh, ax=ax, ticks=[0.25, 0.75])
cb.ax.set_yticklabels(["stick", "slide"])
cb.set_label("contact.sliding")
ax.plot(offset / U.FT, mu_needed, "k-", lw=2, label="|T_c| / N_c: friction needed to stick")
ax.set_ylim(0, 1)
ax.set_xlabel("impulse centroid along the sedan's side, x from its CG [ft]")
ax.set_ylabel("friction limit mu [-]")
ax.set_title("contact.sliding")
ax.legend(loc="upper center", fontsize=9)

ax = axes[1]
Z = s["vehicles[0].delta_v_magnitude"] / U.MPH
mesh = ax.pcolormesh(O, F, Z, shading="auto", cmap="viridis")
cs = ax.contour(O, F, Z, levels=12, colors="white", linewidths=0.6)
ax.clabel(cs, fontsize=7, fmt="%.1f")
ax.plot(offset / U.FT, mu_needed, "k--", lw=1.5)
fig.colorbar(mesh, ax=ax, label="delta-V sedan [mph]")
ax.set_ylim(0, 1)
ax.set_xlabel("impulse centroid along the sedan's side, x from its CG [ft]")
ax.set_title("delta-V of the sedan (vehicle 1)")
fig.tight_layout()

# %% [markdown]
# Reading the maps:
#
# - Below the black line the friction cannot supply the stick impulse: the vehicles **slide** along the contact
#   plane through the exchange, and the tangential impulse is exactly mu times the normal one. Above it they
#   reach a common velocity at the centroid (**stick**, full "common velocity" KS exchange).
# - The friction needed to stick is least (about 0.49) with the centroid about 1.5 ft ahead of the sedan's CG,
#   and rises towards the ends of the side: an off-centre impulse also spins the vehicles, the point of contact
#   then keeps moving along the plane, and more tangential impulse is needed to stop it there. Behind about
#   -4.5 ft even mu = 1 is not enough: those contacts always slide.
# - In the stick region the delta-V contours are vertical: friction no longer matters, only where the centroid is.
#   In the slide region they bend: the delta-V depends on the friction value chosen. So where the
#   reconstruction sits relative to the black line decides whether the friction is worth arguing about (and a fit
#   cannot determine friction from a contact that sticks).

# %% [markdown]
# ## 3. A million points, timed
#
# The same rear impact over a 1000 x 1000 grid of Kia speed and restitution: 10^6 exchanges. Compilation happens
# once per combination of swept paths, outputs, grid shape and chunk size, so the warm-up solves only the first
# 65536 points (four chunks of 16384) of the same grid; the timed call then runs without compiling.

# %%
big = {"vehicles[1].speed": np.linspace(6, 60, 1000) * U.MPH, "contact.restitution": np.linspace(0, 0.5, 1000)}
outs = ["vehicles[0].delta_v_magnitude", "contact.energy_loss"]

t0 = time.perf_counter()
sweep(lucid_case, over=big, outputs=outs, index_range=(0, 65536), progress=False)   # warm-up: compiles
t_compile = time.perf_counter() - t0

t0 = time.perf_counter()
rb = sweep(lucid_case, over=big, outputs=outs, progress=False)
t_run = time.perf_counter() - t0

print(f"warm-up (compile + 65536 points): {t_compile:.2f} s")
print(f"{rb.points:,} points in {t_run:.2f} s: {rb.points / t_run:,.0f} points/s on {jax.devices()[0].platform}"
      f" ({len(jax.devices())} device(s)), float64")
print("status:", rb.status_counts)
print(f"largest delta-V of the Lucid: {np.nanmax(rb['vehicles[0].delta_v_magnitude']) / U.MPH:.2f} mph")

# %% [markdown]
# Each point is a full three-dimensional KS exchange with all the section-4 results; only the two requested
# outputs (and a status byte per point) come back to the host. For sweeps much larger than memory, pass
# `on_chunk=` and `keep=False` (docs/sweeps.md).
#
# For a first look without writing the plotting by hand, `ks_jax.plot.sweep_view` draws any output of a sweep in
# the units asked for (`units="si"` or `"us"`, here US), with the vehicles' names beside the paths: a map over two
# swept inputs (as here), a line over one, a histogram of `mode="zip"` samples.
# From the shell, `ks-jax sweep ... --plot grid.png` draws the same pictures beside the results file.

# %%
from ks_jax import plot

fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
for ax, path in zip(axes, outs):
    plot.sweep_view(rb, path, ax, units="us")
fig.tight_layout()
