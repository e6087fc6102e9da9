# %% [markdown]
# # From measured rest positions to pre-impact speeds
#
# Where two vehicles came to rest is often the best evidence a scene keeps. With a `road` in the case, ks-jax
# carries each vehicle on from the collision to rest (tyre forces on each wheel, braked or free, on a road of a
# given friction), so a rest position is a result like any other, and `fit.reconstruct` can work back from it to
# the speeds at impact.
#
# The shipped case `fit_rest_positions.json` is a T-bone: a sedan (vehicle 1) crosses heading +x, a pickup
# (vehicle 2) heading +y strikes its right side. After the impact the sedan's driver has the front brakes half on,
# the pickup's driver locks all four wheels; the road's friction is 0.75. Both speeds are unknown. The evidence
# is the two rest positions (measured to a foot) and the crush of each vehicle. The rest positions were made from
# speeds of 25 mph (sedan) and 35 mph (pickup), so the fit can be checked against them.
#
# After the first exchange the two do not simply part: the pickup's front stays inside the sedan's side as both
# turn, and it pushes again. ks-jax watches the pair as they move and makes each later exchange where they meet
# (docs/model.md, "Contact interactions"): here some two dozen small ones in the first 0.4 s after the impact, which
# the top view marks as dots. They move where the vehicles stop by tens of feet, so a fit from rest positions needs
# them.
#
# The notebook fits the speeds, draws the collision and both paths to rest at the estimate, and then shows what
# rest positions alone cannot tell apart: the road's friction and the speeds.

# %%
from importlib import resources

import jax
jax.config.update("jax_enable_x64", True)
import numpy as np

import ks_jax
import fit
from ks_jax import units as U
from ks_jax.case import output_kind
from ks_jax.plot import top_view

case = ks_jax.load_case(resources.files("ks_jax.cases") / "fit_rest_positions.json")
names = case.vehicle_names
print(case.name)
print("road friction:", float(case.inputs.road.friction))
for name, raw in zip(names, case.raw["vehicles"]):
    print(f"  {name:7} {raw['weight']:>9}, speed in the file {raw['speed']:>7}, after the impact: wheels {raw['after']['wheels']}")
print("unknowns:")
for path, spec in case.raw["unknowns"].items():
    print(f"  {path:20} bounds {spec['bounds']}")
print("evidence:")
for e in case.raw["evidence"]:
    print(f"  {e['quantity']:30} {e['value']:>8} +- {e['sigma']}")

# the evidence in SI (path -> value, path -> sigma), for the pictures
measured = {e["quantity"]: U.parse_quantity(e["value"], output_kind(e["quantity"])) for e in case.raw["evidence"]}
sigma = {e["quantity"]: U.parse_quantity(e["sigma"], output_kind(e["quantity"])) for e in case.raw["evidence"]}


# %% [markdown]
# ## The case at its start values
#
# Before fitting, the case is solved as written: the speeds in the file (20 and 30 mph) are only where the fit
# starts. The top view shows the collision (outlines at the exchange, centroid, contact plane, impulse, velocities)
# and each vehicle's path to rest: its CG's path, faded outlines at equal steps of time (they bunch up where it
# slows), and its outline at rest. The measured rest positions are the x marks, each in a dashed circle of one
# sigma (1 ft).

# %%
def report_rest(sol):
    for i, r in enumerate(sol.result.rest):
        found = np.array([measured[f"vehicles[{i}].rest_position[{k}]"] for k in (0, 1)])
        miss = np.hypot(*(np.asarray(r.rest_position) - found))
        print(f"{names[i]:7} at rest at ({r.rest_position[0] / U.FT:5.1f}, {r.rest_position[1] / U.FT:5.1f}) ft"
              f" after {r.distance_to_rest / U.FT:5.1f} ft and {r.time_to_rest:.2f} s, turned {r.rotation_to_rest:+6.1f} deg;"
              f" {miss / U.FT:4.1f} ft from where it was found")

start = ks_jax.solve(case)
report_rest(start)
ax = top_view(start, evidence=measured, sigma=sigma)
ax.figure.set_size_inches(7, 7.5)

# %% [markdown]
# At 20 and 30 mph both vehicles come to rest well away from the marks (the sedan about 24 ft, the pickup about
# 7 ft).
#
# ## The fit
#
# `fit.reconstruct` reads the unknowns and the evidence from the case file, starts from eight points spread over
# the bounds (5 to 60 mph for each speed) and moves both speeds until the solved rest positions and crush match
# the measured ones as closely as their sigmas ask, by weighted least squares.

# %%
res = fit.reconstruct(case)
print("converged:", res.converged, f"| chi^2 = {res.chi2:.4f} for {len(res.evidence)} evidence and",
      f"{len(res.unknowns)} unknowns | unidentified: {res.unidentified}")
print(f"\n{'unknown':20}{'estimate':>10}{'+-':>4}{'std':>6}   true")
for path, true in (("vehicles[0].speed", 25.0), ("vehicles[1].speed", 35.0)):
    print(f"{path:20}{res.estimate[path] / U.MPH:10.2f}{'+-':>4}{res.std[path] / U.MPH:6.2f}  {true:5.1f} mph")
print(f"correlation of the two speeds: {res.correlation['vehicles[0].speed']['vehicles[1].speed']:+.2f}")
print()
for path, r in res.residuals.items():
    print(f"{path:30} measured {measured[path] / U.FT:6.2f} ft, fitted {res.fitted[path] / U.FT:6.2f} ft,"
          f" residual {r:+.2f} sigma")


# %% [markdown]
# Both speeds come back at the speeds the rest positions were made from, with standard errors under 1 mph: a
# foot of uncertainty in where a vehicle stopped is worth well under a mile an hour here, because the pickup
# slides to rest over some 25 ft and the sedan over some 76 ft.
#
# The case at the estimate: its unknowns set to the fitted speeds (`fit.case_at`) and solved again. Its rest
# outlines now sit on the measured marks. (`ks-jax fit fit_rest_positions.json --plot fit.png` draws the same
# picture from the command line.)

# %%
best = ks_jax.solve(fit.case_at(case, res.estimate, f"{case.name}\nat the estimate: "
                                + ", ".join(f"{res.estimate[p] / U.MPH:.1f} mph" for p in res.estimate)))
report_rest(best)
ax = top_view(best, evidence=measured, sigma=sigma)
ax.figure.set_size_inches(7, 7.5)

# %% [markdown]
# ## What rest positions cannot tell apart: speed and drag
#
# The fit above took the road's friction as known (0.75). In practice it is measured, looked up, or argued over.
# How much do the rest positions say about it? Make it a third unknown, between 0.4 and 1.0, and fit again
# with the same evidence:

# %%
unknowns = dict(case.raw["unknowns"])
unknowns["road.friction"] = {"bounds": [0.4, 1.0]}
three = fit.reconstruct(case, unknowns)
paths = list(unknowns)
unit = {"vehicles[0].speed": (U.MPH, "mph"), "vehicles[1].speed": (U.MPH, "mph"), "road.friction": (1.0, "")}
print("converged:", three.converged, f"| chi^2 = {three.chi2:.4f}")
for p in paths:
    u, name = unit[p]
    print(f"{p:20}{three.estimate[p] / u:10.3f} +- {three.std[p] / u:.3f} {name}")
print("\nunidentified:", three.unidentified)
print("\ncorrelation:")
print(" " * 20 + "".join(f"{p:>20}" for p in paths))
for a in paths:
    print(f"{a:20}" + "".join(f"{three.correlation[a][b]:20.3f}" for b in paths))

# %% [markdown]
# The fit still lands near the truth (it reports `converged: False`: along the valley of equally good
# explanations it stops short of its tolerance), but look at the numbers around it. The standard error of the
# friction is about 0.27, wider than knowing nothing beyond "somewhere between 0.4 and 1.0", and the fit says so in
# `unidentified` ("poorly determined"). The speeds' standard errors grow from under 1 mph to 5 and 7 mph. The
# correlations close to +1 say why: a higher friction with higher speeds puts the vehicles in nearly the same
# places. A vehicle sliding to rest covers about v^2 / (2 mu g): the rest position fixes v^2 / mu much better
# than v or mu. The two do not trade exactly, because the tyres' rolling resistance and cornering forces do not
# scale with the friction, and that small difference is all the evidence has to go on.
#
# The same trade seen directly: fix the friction at 0.6, 0.75 and 0.9 in turn and fit only the speeds. Each
# friction gets its own speeds, and each matches the rest positions:

# %%
frictions = (0.6, 0.75, 0.9)
fixed = [fit.reconstruct(fit.case_at(case, {"road.friction": mu})) for mu in frictions]
for mu, r in zip(frictions, fixed):
    worst = max(abs(r.residuals[p]) for p in r.residuals)
    print(f"friction {mu:4.2f}: sedan {r.estimate['vehicles[0].speed'] / U.MPH:5.1f} +- {r.std['vehicles[0].speed'] / U.MPH:4.2f} mph,"
          f" pickup {r.estimate['vehicles[1].speed'] / U.MPH:5.1f} +- {r.std['vehicles[1].speed'] / U.MPH:4.2f} mph;"
          f" chi^2 {r.chi2:5.2f}, largest residual {worst:.2f} sigma")

# %% [markdown]
# A friction of 0.6 or 0.9 is no worse an explanation of the scene than 0.75, judged by the rest positions
# alone, and each gives speeds several mph apart. Each fit's own standard errors (under 1 mph) hold only for
# its friction: the friction's own uncertainty comes on top.
#
# ## What to do about it
#
# For the reconstructionist, the friction belongs with the evidence, not with the unknowns fitted blind: a drag
# factor from test skids at the scene, or a documented range for the surface, given as a prior (a mean and a
# sigma). With a prior of 0.75 +- 0.05 the fit carries that uncertainty into the speeds honestly:

# %%
with_prior = dict(unknowns)
with_prior["road.friction"] = {"bounds": [0.4, 1.0], "prior": {"mean": 0.75, "sigma": 0.05}}
known = fit.reconstruct(case, with_prior)
for p in paths:
    u, name = unit[p]
    print(f"{p:20}{known.estimate[p] / u:10.3f} +- {known.std[p] / u:.3f} {name}")
print("unidentified:", known.unidentified)

# %% [markdown]
# The speeds are back within about 1 mph, and now that figure includes the uncertainty of the friction: 0.05 of
# friction is worth about 1 mph here. In plain words:
#
# - Rest positions measure how much speed the road took away, which is speed and drag together. They pin the
#   speeds tightly only where the drag is known.
# - A fit that leaves the friction free says so: a friction standard error as wide as its range, a note in
#   `unidentified`, and correlations near 1 between the friction and the speeds.
# - Other evidence that does not go through the road (an EDR's delta-V or pre-crash speed, crush energy) breaks
#   the trade; without it, state the friction you assumed and carry its uncertainty, as the prior does.
