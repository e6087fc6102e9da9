# %% [markdown]
# # Reconstruction: from evidence to pre-impact speeds
#
# The reverse problem. An intersection collision: an SUV strikes the right front of a crossing sedan at an angle.
# The scene and the vehicles give
#
# - the sedan's **EDR** (airbag control module) longitudinal and lateral delta-V,
# - the sedan's **crush** depth, which places the impulse centroid,
# - the **post-impact speeds** and **departure angles** of both vehicles (from their rest positions, the
#   post-impact trajectories and drag factors).
#
# `fit.reconstruct` finds the pre-impact speeds, the restitution, the friction limit and the centroid depth
# that reproduce this evidence, by weighted least squares through the model's gradients, with standard errors,
# a Monte Carlo check, and a plain statement of anything the evidence cannot determine.
#
# Here the evidence is synthetic: the case is solved with "true" inputs, and the results are measured with
# stated random errors, so that the fit can be compared with the truth.

# %%
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import matplotlib.pyplot as plt

import ks_jax
import fit
from ks_jax import units as U
from ks_jax.case import case_from_dict
from ks_jax.plot import top_view

# %% [markdown]
# ## The case, in the units of the trade
#
# Vehicle 1 is the sedan heading east (yaw 0) at 28 mph; vehicle 2 is the SUV on a heading of 115 deg at 38 mph.
# The user contact puts the impulse centroid 2.5 ft ahead of the sedan's CG, 1.05 ft inside its right side,
# with the contact plane along that side (normal azimuth 90 deg, from the SUV into the sedan).
# These are the "true" values the fit will have to find.

# %%
case_dict = {
    "name": "Intersection: SUV into the right front of a crossing sedan",
    "vehicles": [
        {"name": "Sedan", "weight": "3300 lbf",
         "inertia": ["370 lbf*ft*s^2", "1770 lbf*ft*s^2", "1920 lbf*ft*s^2"],
         "length": "16 ft", "width": "6.1 ft", "height": "4.8 ft", "cg_to_front": "6.6 ft", "cg_height": "1.8 ft",
         "position": ["0 ft", "0 ft"], "yaw": 0, "speed": "28 mph"},
        {"name": "SUV", "weight": "4700 lbf",
         "inertia": ["600 lbf*ft*s^2", "2900 lbf*ft*s^2", "3100 lbf*ft*s^2"],
         "length": "16.5 ft", "width": "6.7 ft", "height": "5.8 ft", "cg_to_front": "7.4 ft", "cg_height": "2.3 ft",
         "position": ["5.2 ft", "-7.8 ft"], "yaw": 115, "speed": "38 mph"},
    ],
    "contact": {"point": ["2.5 ft", "-2.0 ft", "2.0 ft"], "normal": 90, "restitution": 0.15, "friction": 0.4},
}
case = case_from_dict(case_dict)
truth = ks_jax.solve(case)
res = truth.result
print("status:", truth.status, "| sliding:", bool(res.contact.sliding))
for i, name in enumerate(case.vehicle_names):
    v = res.vehicles[i]
    print(f"{name:6} delta-V {float(v.delta_v_magnitude) / U.MPH:5.1f} mph (long {float(v.delta_v_body[0]) / U.MPH:6.1f},"
          f" lat {float(v.delta_v_body[1]) / U.MPH:6.1f}), PDOF {float(v.pdof):5.1f} deg,"
          f" after {float(v.speed_after) / U.MPH:5.1f} mph on {float(v.course_after):5.1f} deg,"
          f" crush {float(v.crush) / U.FT:4.2f} ft")
ax = top_view(truth)
ax.figure.set_size_inches(7, 6)

# %% [markdown]
# The top view: the sedan (blue) and the SUV (orange) at the exchange, the centroid, the contact plane (red line)
# and normal, the friction cone, the impulse, and each vehicle's velocity before (dotted) and after (solid).
# The contact **slides** (the impulse lies on the edge of the friction cone), so the friction limit matters.
#
# ## The evidence
#
# Each measurement is the true result plus a random error drawn with the stated sigma (a fixed seed, so the
# notebook is reproducible): EDR delta-V to 1 mph, crush to 0.15 ft, post-impact speeds to 2 mph, departure
# angles to 4 deg.

# %%
rng = np.random.default_rng(7)
# path: (sigma in SI / degrees, display unit, unit name)
measured = {
    "vehicles[0].delta_v_body[0]": (1.0 * U.MPH, U.MPH, "mph"),   # EDR longitudinal
    "vehicles[0].delta_v_body[1]": (1.0 * U.MPH, U.MPH, "mph"),   # EDR lateral
    "vehicles[0].crush": (0.15 * U.FT, U.FT, "ft"),
    "vehicles[0].speed_after": (2.0 * U.MPH, U.MPH, "mph"),
    "vehicles[1].speed_after": (2.0 * U.MPH, U.MPH, "mph"),
    "vehicles[0].course_after": (4.0, 1.0, "deg"),
    "vehicles[1].course_after": (4.0, 1.0, "deg"),
}
evidence = []
print(f"{'evidence':30}{'true':>10}{'measured':>10}{'sigma':>8}")
for path, (sigma, unit, uname) in measured.items():
    true = float(ks_jax.get_output(res, path))
    value = true + sigma * rng.standard_normal()
    evidence.append(fit.Evidence(path, value, sigma))   # SI (degrees for course_after)
    print(f"{path:30}{true / unit:10.2f}{value / unit:10.2f}{sigma / unit:8.2f}  {uname}")

# %% [markdown]
# ## The fit
#
# Five unknowns with their plausible ranges, written as in a case file: both pre-impact speeds, the
# restitution, the friction limit, and the centroid's lateral position `contact.point[1]` (how deep into the
# sedan's side it lies; the sedan's right side is at y = -3.05 ft). The fit runs eight starts spread over
# these ranges and keeps the best; `monte_carlo=200` then refits 200 copies of the evidence, each perturbed by
# its sigmas.

# %%
unknowns = {
    "vehicles[0].speed": {"bounds": ["0 mph", "70 mph"]},
    "vehicles[1].speed": {"bounds": ["0 mph", "70 mph"]},
    "contact.restitution": {"bounds": [0, 0.5]},
    "contact.friction": {"bounds": [0, 1.2]},
    "contact.point[1]": {"bounds": ["-3.05 ft", "0 ft"]},
}
fr = fit.reconstruct(case, unknowns, evidence, monte_carlo=200, seed=1)
print("converged:", fr.converged, f"| chi^2 = {fr.chi2:.2f} for {len(evidence)} evidence and {len(unknowns)} unknowns",
      f"| starts at the best fit: {fr.starts_at_best}/{fr.starts}")
print("unidentified:", fr.unidentified, "| at a bound:", fr.at_bound, "| notes:", fr.notes)

show = {"vehicles[0].speed": (U.MPH, "mph"), "vehicles[1].speed": (U.MPH, "mph"),
        "contact.restitution": (1.0, ""), "contact.friction": (1.0, ""), "contact.point[1]": (U.FT, "ft")}
true_value = {p: float(ks_jax.get_input(case.inputs, p)) for p in show}
print(f"\n{'unknown':22}{'estimate':>10}{'+-':>3}{'std':>7}{'true':>9}  {'(est - true) / std':>20}")
for p, (unit, uname) in show.items():
    est, sd = fr.estimate[p], fr.std[p]
    print(f"{p:22}{est / unit:10.2f}{'+-':>3}{sd / unit:7.2f}{true_value[p] / unit:9.2f}"
          f"  {(est - true_value[p]) / sd:20.2f}  {uname}")

# %% [markdown]
# The speeds come back within about one standard error of the truth, to about +-2 mph (1 sigma). The last column
# is how many standard errors each estimate is from the truth: with honest error bars it should rarely exceed 2.
#
# Correlations tell which unknowns trade off against each other:

# %%
names = list(show)
print(" " * 22 + "".join(f"{n.split('.')[-1][:11]:>12}" for n in names))
for a in names:
    print(f"{a:22}" + "".join(f"{fr.correlation[a][b]:12.2f}" for b in names))

# %% [markdown]
# ## Residuals
#
# How far the fitted model is from each measurement, in units of its sigma. Values within +-2 are what random
# error produces; a larger one would point at a bad measurement or a wrong assumption in the case (a
# centroid in the wrong place, a wrong mass).

# %%
keys = list(fr.residuals)
fig, ax = plt.subplots(figsize=(7, 3.4))
ax.barh(range(len(keys)), [fr.residuals[k] for k in keys], color="tab:blue")
ax.set_yticks(range(len(keys)), keys, fontsize=9)
ax.invert_yaxis()
for x in (-2, -1, 1, 2):
    ax.axvline(x, color="grey", ls=":" if abs(x) == 1 else "--", lw=1)
ax.axvline(0, color="black", lw=0.8)
ax.set_xlim(-3, 3)
ax.set_xlabel("residual (fitted - measured) / sigma [-]")
ax.set_title("residuals at the estimate")
fig.tight_layout()
for ev in evidence:
    sigma, unit, uname = measured[ev.path]
    print(f"{ev.path:30} measured {ev.value / unit:8.2f}  fitted {fr.fitted[ev.path] / unit:8.2f} {uname:4}"
          f" residual {fr.residuals[ev.path]:+.2f} sigma")

# %% [markdown]
# ## Monte Carlo against the Laplace standard errors
#
# The standard errors above come from the curvature of the least-squares cost at the optimum (the Laplace, or
# Gauss-Newton, approximation). The Monte Carlo refits show the actual spread of the estimates when the evidence
# is perturbed by its sigmas. The histograms are the 200 refits; the curve is the normal distribution with the
# Laplace standard error about the estimate; the dashed line is the truth.

# %%
mc = fr.monte_carlo
xs = mc["x"][mc["converged"]]          # (refits, unknowns), SI, columns in the order of the unknowns
print(f"{mc['samples']} refits, {mc['converged_fraction']:.0%} converged")
fig, axes = plt.subplots(1, len(names), figsize=(13, 3.2))
for k, (ax, p) in enumerate(zip(axes, names)):
    unit, uname = show[p]
    x = xs[:, k] / unit
    est, sd = fr.estimate[p] / unit, fr.std[p] / unit
    counts, edges, _ = ax.hist(x, bins=20, color="tab:blue", alpha=0.6, label="Monte Carlo refits")
    g = np.linspace(edges[0] - sd, edges[-1] + sd, 200)
    width = edges[1] - edges[0]
    ax.plot(g, len(x) * width * np.exp(-0.5 * ((g - est) / sd) ** 2) / (sd * np.sqrt(2 * np.pi)),
            "k-", label="Laplace: estimate +- std")
    ax.axvline(true_value[p] / unit, color="red", ls="--", label="true value")
    ax.set_xlabel(f"{p} [{uname or '-'}]")
    ax.set_title(f"MC std {x.std():.3g}, Laplace {sd:.3g}", fontsize=9)
axes[0].set_ylabel("refits [count]")
axes[0].legend(fontsize=8.5, loc="upper left")
fig.tight_layout()

# %% [markdown]
# Here the histograms and the curves agree (the titles compare the two standard deviations): the model is close
# to linear over the uncertainty, and the Laplace standard errors can be quoted as they are. Where a histogram is
# skewed or cut off at a bound (a restitution near 0, say, or a contact on the edge of sticking), the 5/50/95
# percentiles in `fr.monte_carlo["percentiles"]` are the better summary:

# %%
for q in ("5", "50", "95"):
    row = fr.monte_carlo["percentiles"][q]
    print(f"{q:>3}%: " + ", ".join(f"{p.split('.')[-1]} {row[p] / show[p][0]:.2f} {show[p][1]}" for p in names))

# %% [markdown]
# ## When the evidence cannot determine a speed
#
# Now suppose only the EDR is available: the sedan's longitudinal and lateral delta-V, and nothing from the scene
# after the impact. The unknowns are both speeds and the restitution (friction and centroid taken as known).
#
# First a picture: the SUV's speed against the restitution, coloured by the sedan's lateral delta-V. The red line
# is every pair that reproduces the measured lateral delta-V.

# %%
from ks_jax import sweep

speeds = np.linspace(20, 60, 81) * U.MPH
eps = np.linspace(0, 0.5, 51)
sw = sweep(case, over={"vehicles[1].speed": speeds, "contact.restitution": eps},
           outputs=["vehicles[0].delta_v_body[1]"])
S, E = np.meshgrid(speeds / U.MPH, eps, indexing="ij")
Z = sw["vehicles[0].delta_v_body[1]"] / U.MPH
fig, ax = plt.subplots(figsize=(7, 4.2))
mesh = ax.pcolormesh(S, E, Z, shading="auto", cmap="viridis")
fig.colorbar(mesh, ax=ax, label="sedan lateral delta-V [mph]")
ax.contour(S, E, Z, levels=[evidence[1].value / U.MPH], colors="red", linewidths=2)
ax.plot(true_value["vehicles[1].speed"] / U.MPH, true_value["contact.restitution"], "w*", ms=14, label="truth")
ax.set_xlabel("SUV speed before impact [mph]")
ax.set_ylabel("restitution eps [-]")
ax.set_title("every point on the red line gives the measured lateral delta-V")
ax.legend(loc="upper right")
fig.tight_layout()

# %%
edr_only = evidence[:2]                  # EDR longitudinal and lateral delta-V of the sedan
unknowns_edr = {k: unknowns[k] for k in ("vehicles[0].speed", "vehicles[1].speed", "contact.restitution")}
fu = fit.reconstruct(case, unknowns_edr, edr_only)
for p in unknowns_edr:
    unit, uname = show[p]
    print(f"{p:22} estimate {fu.estimate[p] / unit:8.2f} {uname:4} std {fu.std[p] / unit:10.3g}")
print("\nunidentified:")
for line in fu.unidentified:
    print(" -", line)

# %% [markdown]
# The fit still returns numbers (any point of the valley reproduces the evidence), but it gives them no usable
# error bar: the standard errors of the SUV's speed and of the restitution are infinite, the sedan's is hundreds
# of mph, and `unidentified` says why, in words:
#
# - **SUV speed and restitution**: the contact slides, so the impulse is set by the normal closing speed times
#   (1 + eps); the SUV's speed and the restitution trade off along the red line above. The delta-V fixes only
#   their combination.
# - **Sedan speed** (which even ends at its bound of 0 mph, and `fu.at_bound` says so; the restitution ends
#   wherever the starts led along the red line, here about 0.27): the sedan moves along the contact plane. In a sliding contact the
#   tangential impulse is mu times the normal one whatever the sliding speed, so its speed hardly changes the
#   delta-V at all: the evidence leaves it practically free ("poorly determined").
#
# This is why the first fit needed the post-impact speeds and directions: they measure where the momentum went,
# which fixes the closing speed and the restitution separately. Without them, the restitution (or a speed) has to
# be given, and the report should say it was assumed.
