# %% [markdown]
# # Automatic contact: first contact and depth of penetration
#
# With automatic contact (no `point` and no `normal` in the case) ks-jax moves the vehicles freely from their
# case positions until their outlines first touch (time t_i), lets them run on for the **penetration time**
# dt_p, and exchanges the impulse there: at the centroid of the overlap of the two outlines, across the contact
# plane through the two points where the outlines cross. This is the Virtual CRASH "auto-position" and
# "depth of penetration".
#
# The penetration time is a modelling choice, and this notebook shows how much the results move with it for
# the shipped T-bone case (`auto_tbone.json`): a pickup at 30 mph into the right side of a sedan crossing at
# 15 mph.

# %%
import dataclasses
from importlib import resources

import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import matplotlib.pyplot as plt

import ks_jax
from ks_jax import units as U
from ks_jax.plot import top_view
from ks_jax import sweep

cases = resources.files("ks_jax.cases")
tbone = ks_jax.load_case(cases / "auto_tbone.json")
print(tbone.name, "| automatic point:", tbone.auto_point, "| automatic normal:", tbone.auto_normal,
      "| penetration time in the file:", tbone.inputs.contact.penetration_time, "s")

# %% [markdown]
# One sweep over `contact.penetration_time`, from 0 (the exchange at the instant of first touch) to 0.15 s:

# %%
dtp = np.linspace(0, 0.15, 76)
outputs = ["contact.time", "contact.point[0]", "contact.point[1]", "contact.normal[0]", "contact.normal[1]",
           "contact.sliding", "contact.energy_loss",
           "vehicles[0].crush", "vehicles[1].crush", "vehicles[0].ees", "vehicles[1].ees",
           "vehicles[0].delta_v_magnitude", "vehicles[1].delta_v_magnitude"]
r = sweep(tbone, over={"contact.penetration_time": dtp}, outputs=outputs)
print(r.status_counts, f"solved in {r.seconds:.2f} s after compiling in {r.compile_seconds:.2f} s")
print(f"first contact t_i = {r['contact.time'][0]:.3f} s for every penetration time")
separating = dtp[np.array([ks_jax.status_text(c) for c in r['status']]) == "separating"]
if len(separating):
    print(f"separating (no exchange) from dt_p = {separating.min():.3f} s")

# %%
names = tbone.vehicle_names
ms = dtp * 1000
exchange = np.array([ks_jax.status_text(c) for c in r["status"]]) == "ok"
normal_azimuth = np.where(exchange, np.degrees(np.arctan2(r["contact.normal[1]"], r["contact.normal[0]"])), np.nan)
crush_sum = r["vehicles[0].crush"] + r["vehicles[1].crush"]
ees_ok = crush_sum > 1e-3                      # EES splits the energy by crush: meaningless without crush

fig, axes = plt.subplots(2, 2, figsize=(10.5, 6.8), sharex=True)
ax = axes[0, 0]
ax.plot(ms, r["contact.point[0]"] / U.FT, label="centroid x")
ax.plot(ms, r["contact.point[1]"] / U.FT, label="centroid y")
ax.set_ylabel("impulse centroid, global [ft]")
ax2 = ax.twinx()
ax2.plot(ms, normal_azimuth, "k:", label="normal azimuth")
ax2.set_ylabel("contact normal azimuth [deg]")
ax.set_ylim(-4, 9)
ax2.set_ylim(20, 100)
h1, l1 = ax.get_legend_handles_labels()
h2, l2 = ax2.get_legend_handles_labels()
ax.legend(h1 + h2, l1 + l2, loc="center left", fontsize=9)
ax.set_title("where and how the impulse acts")

ax = axes[0, 1]
for i in range(2):
    ax.plot(ms, r[f"vehicles[{i}].crush"] / U.FT, color=f"C{i}", ls="-:"[i], lw=2.5 - i, label=f"{names[i]}")
ax.set_ylabel("crush (centroid to undeformed box) [ft]")
ax.legend(fontsize=9)
ax.set_title("crush")

ax = axes[1, 0]
for i in range(2):
    ax.plot(ms, r[f"vehicles[{i}].delta_v_magnitude"] / U.MPH, color=f"C{i}", label=f"delta-V {names[i]}")
    ax.plot(ms, np.where(ees_ok, r[f"vehicles[{i}].ees"], np.nan) / U.MPH, "--", color=f"C{i}",
            label=f"EES {names[i]}")
ax.set_ylabel("delta-V, EES [mph]")
ax.set_xlabel("penetration time dt_p [ms]")
ax.legend(fontsize=9)
ax.set_title("delta-V and EES")

ax = axes[1, 1]
ax.plot(ms, r["contact.energy_loss"] / (1000 * U.FT_LBF), "k-")
ax.set_ylabel("deformation energy [1000 ft lbf]")
ax.set_xlabel("penetration time dt_p [ms]")
ax.set_title("energy loss")
ax.fill_between(ms, 0, 1, where=r["contact.sliding"], transform=ax.get_xaxis_transform(), color="orange",
                alpha=0.2, label="contact slides")
for a in axes.flat:
    a.axvline(tbone.inputs.contact.penetration_time * 1000, color="grey", lw=0.8, ls="--")
    a.fill_between(ms, 0, 1, where=~exchange, transform=a.get_xaxis_transform(), color="grey", alpha=0.25,
                   label="separating: no exchange" if a is axes[1, 1] else None)
axes[1, 1].legend(fontsize=9)
fig.tight_layout()

# %% [markdown]
# What moves, and why (the grey line is the file's 50 ms):
#
# - **First contact** does not depend on dt_p: t_i is fixed by the starting positions and speeds.
# - Up to about 78 ms the pickup's front sinks into the sedan's right side and the overlap is a rectangle that
#   deepens (30 mph is 0.53 in per ms): the centroid moves into the sedan (centroid y rises) while its x stays on
#   the pickup's centre line, the normal stays across the sedan's side (90 deg), and each vehicle's **crush**
#   (centroid to that vehicle's undeformed outline, along the normal) is half the depth: the two crush curves
#   coincide. The file's 50 ms puts the centroid about 1.1 ft into each vehicle.
# - **delta-V** and energy fall slowly over the same range: the closing speed along the normal stays 30 mph,
#   but the sedan keeps moving forward, so the pickup's front is further and further behind the sedan's CG.
#   With a longer lever arm the sedan yields more by rotating, its effective mass at the centroid drops, and the
#   impulse is smaller.
# - At about 78 ms the sedan's rear corner passes the pickup's left side (compare the top views below). The
#   outlines now cross on the sedan's rear face and on the pickup's side, each vehicle with a corner inside the
#   other: the line through the crossings is only the overlap's diagonal, so the normal is the axis the faces
#   first touched along, still across the sedan's side (90 deg; docs/model.md, "Automatic contact"). With the
#   lever arm still growing, the contact starts to slide (orange) at about 94 ms, and delta-V and energy go on
#   falling smoothly. From about 136 ms the pickup's front has gone through the sedan's whole width: the outlines
#   cross in four points, the normal falls back to the axis of least penetration, now along the sedan, and
#   the vehicles are not approaching along it: no exchange at all (grey). A staging that deep is past what the
#   footprints can say; give `contact.normal`.
# - At dt_p = 0 the exchange is at the instant of touching: the overlap has no area and there is no crush, so
#   EES (which shares the energy by crush) is not drawn there.
#
# The lesson for a reconstruction: the penetration time should put the centroid where the crush says it is
# (compare the crush curve with the measured crush depth), and results near a change of character (stick to
# slide, an exchange to none) deserve a second look at the staging.

# %% [markdown]
# ## Two penetration times side by side
#
# Top views at 20 ms and 100 ms: the outlines at first contact (dashed) and at the exchange (solid), the overlap
# (grey), the centroid, the contact plane (red) and the impulses.

# %%
shown = (0.02, 0.10)
pair = [dataclasses.replace(tbone, name=f"{tbone.vehicle_names[1]} into {tbone.vehicle_names[0]}: dt_p = {p * 1000:.0f} ms",
                            inputs=ks_jax.set_input(tbone.inputs, "contact.penetration_time", p)) for p in shown]
sols = ks_jax.solve(pair)
fig, axes = plt.subplots(1, 2, figsize=(11, 5.5))
for ax, sol in zip(axes, sols):
    top_view(sol, ax=ax)
fig.tight_layout()
for p, sol in zip(shown, sols):
    c = sol.result.contact
    print(f"dt_p = {p * 1000:3.0f} ms: centroid ({c.point[0] / U.FT:5.2f}, {c.point[1] / U.FT:5.2f}) ft,"
          f" normal azimuth {np.degrees(np.arctan2(c.normal[1], c.normal[0])):6.1f} deg, sliding {bool(c.sliding)},"
          f" delta-V {sol.result.vehicles[0].delta_v_magnitude / U.MPH:5.2f} / {sol.result.vehicles[1].delta_v_magnitude / U.MPH:5.2f} mph")
