# %% [markdown]
# # Before the impact: a skid, an event data recorder, and the speeds that fit them all
#
# Much of the evidence of a crash is about the seconds before it: the skid marks that end where the vehicles met,
# and the event data recorder's pre-crash table (the speed every 0.5 s for the last few seconds). ks-jax works a
# vehicle's `approach` back from its state at the impact (docs/model.md, "The approach"), so that its speed, time
# and place at the start of each phase, and its speed at any time before the impact, are results like any other,
# and evidence for a fit.
#
# The case is `docs/examples/tbone_skids_before_impact.json`: a pickup (vehicle 2) strikes the right side of a
# crossing sedan (vehicle 1); both slide to rest on a dry road (friction 0.75). The sedan, without ABS, left 48 ft of
# locked skid marks up to the impact. The pickup's recorder kept its speed every 0.5 s: its driver braked hard (ABS,
# no marks) for the last 0.6 s. Both impact speeds are unknown. The evidence, made here from a run at 25 mph (sedan)
# and 35 mph (pickup) and rounded as measurements are:
# - the pickup's pre-crash speeds at -2.5, -2.0, .. -0.5 s (to 1 mph, as recorders report them);
# - the pickup's recorded delta-V (to 2 mph);
# - where both came to rest (to 1 ft).
#
# The notebook fits both speeds from everything, draws the posterior, says what the sedan's skid gives (the speed
# where its marks begin) and then fits again with each piece of evidence left out.

# %%
import dataclasses
import json

import jax
jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt
import numpy as np

import ks_jax
import fit
from ks_jax import units as U
from ks_jax.case import case_from_dict
from ks_jax.plot import top_view

raw = json.loads(open("../docs/examples/tbone_skids_before_impact.json").read())
raw["vehicles"][0]["approach"] = [{"wheels": "free", "duration": "1 s"}, {"wheels": "locked", "distance": "48 ft"}]
raw["vehicles"][1]["approach"] = [{"wheels": "free", "duration": "2.5 s"},
                                  {"wheels": [0.9, 0.9, 0.9, 0.9], "duration": "0.6 s"}]
truth = case_from_dict(raw)
names = truth.vehicle_names
for name, v in zip(names, raw["vehicles"]):
    print(f"{name:7} at the impact {v['speed']:>7}; before it: {v['approach']}")

# %% [markdown]
# ## The evidence
#
# The pickup's speeds at the recorder's times are outputs at a time (`vehicles[1].speed@-2.5`), here taken from a
# sweep of one point at the true speeds; its delta-V and both rest positions from `ks_jax.solve`.

# %%
EDR_TIMES = [-2.5, -2.0, -1.5, -1.0, -0.5]
at_times = [f"vehicles[1].speed@{t}" for t in EDR_TIMES]
swept = ks_jax.sweep(truth, {"vehicles[1].speed": [35 * U.MPH]}, outputs=at_times)
edr = [round(float(swept.outputs[p][0]) / U.MPH) for p in at_times]
sol = ks_jax.solve(truth)
pickup_dv = round(float(sol.result.vehicles[1].delta_v_magnitude) / U.MPH)
rests = {f"vehicles[{i}].rest_position[{k}]": round(float(r.rest_position[k]) / U.FT)
         for i, r in enumerate(sol.result.rest) for k in (0, 1)}
print("pickup's recorder, mph:", dict(zip(EDR_TIMES, edr)))
print("pickup's delta-V:", pickup_dv, "mph")
print("rest positions, ft:", rests)

EVIDENCE = {
    "recorder": [{"quantity": "vehicles[1].speed", "time": [f"{t} s" for t in EDR_TIMES],
                  "value": [f"{s} mph" for s in edr], "sigma": "1 mph"}],
    "delta-V": [{"quantity": "vehicles[1].delta_v_magnitude", "value": f"{pickup_dv} mph", "sigma": "2 mph"}],
    "rest positions": [{"quantity": p, "value": f"{v} ft", "sigma": "1 ft"} for p, v in rests.items()],
}
UNKNOWNS = {"vehicles[0].speed": {"bounds": ["5 mph", "60 mph"], "start": "20 mph"},
            "vehicles[1].speed": {"bounds": ["5 mph", "60 mph"], "start": "30 mph"}}


def with_evidence(ignored=()):
    """The case with both speeds unknown and all the evidence, that of the kinds in ``ignored`` with a sigma a
    billion times its own: it then weighs nothing, and the fit keeps its unknowns and evidence paths, so that it
    reuses the program compiled for the fit from everything (new paths compile a new one, a minute or more here)."""
    def ignore(e):
        value, unit = e["sigma"].split()
        return dict(e, sigma=f"{float(value) * 1e9:g} {unit}")
    evidence = [ignore(e) if k in ignored else e for k in EVIDENCE for e in EVIDENCE[k]]
    return case_from_dict(dict(raw, unknowns=UNKNOWNS, evidence=evidence))


# %% [markdown]
# ## The fit from everything
#
# `fit.reconstruct` moves both impact speeds until the recorder's speeds, the delta-V and the rest positions match
# as closely as their sigmas ask. With `posterior=` it then draws from the posterior by NUTS (flat priors within
# the bounds), which says how far the speeds may be from the estimate when the evidence is not linear in them.

# %%
everything = with_evidence()
res = fit.reconstruct(everything, starts=4, posterior=100, chains=2, seed=1)
print("converged:", res.converged, f"| chi^2 = {res.chi2:.2f} for {len(res.evidence)} evidence")
print(f"{'unknown':20}{'estimate':>10}{'std':>8}   posterior 5-95%     true")
post = res.posterior
draws = {}
for path, true in (("vehicles[0].speed", 25), ("vehicles[1].speed", 35)):
    draws[path] = post.samples[:, :, post.paths.index(path)].ravel() / U.MPH
    lo, hi = np.percentile(draws[path], [5, 95])
    print(f"{path:20}{res.estimate[path] / U.MPH:10.2f}{res.std[path] / U.MPH:8.2f}   {lo:6.2f} - {hi:6.2f} mph"
          f"   {true} mph")
for warning in post.warnings:
    print("posterior:", warning)
for path, r in res.residuals.items():
    print(f"  {path:34} residual {r:+.2f} sigma")

fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
for ax, (path, d) in zip(axes, draws.items()):
    ax.hist(d, bins=25, color="0.6")
    ax.axvline(res.estimate[path] / U.MPH, color="k", label="estimate")
    ax.set_xlabel(f"{names[int(path[9])]}: speed at the impact (mph)")
    ax.legend()
axes[0].set_ylabel("posterior draws")
fig.tight_layout()

# %% [markdown]
# ## What the sedan's skid gives
#
# A skid of known length on a road of known friction ties the speed where it begins to the speed at its end, the
# impact: sqrt(v^2 + 2 mu g d). It says nothing about the impact speed by itself, so it is not a term of the fit;
# it carries the fitted impact speed back to where the marks begin (`vehicles[0].approach[1].speed`, a result of
# the case at the estimate), with its uncertainty scaled by v / v_start. The top view draws each vehicle's approach
# (dashed, a mark at each phase's start) and its path to rest as one trajectory.

# %%
inputs = everything.inputs
for path, value in res.estimate.items():
    inputs = ks_jax.set_input(inputs, path, value)
best = ks_jax.solve(dataclasses.replace(everything, inputs=inputs, name=f"{truth.name}\nat the estimate"))
sedan = best.result.approach[0]  # the state at the start of each of its phases
v, v_start = res.estimate["vehicles[0].speed"], float(sedan.speed[1])
closed = np.sqrt(v ** 2 + 2 * 0.75 * U.G0 * 48 * U.FT)
print(f"sedan: {v / U.MPH:.2f} mph at the impact, {v_start / U.MPH:.2f} mph where its marks begin"
      f" (sqrt(v^2 + 2 mu g d): {closed / U.MPH:.2f}), +- {res.std['vehicles[0].speed'] * v / v_start / U.MPH:.2f} mph,"
      f" {-float(sedan.time[1]):.2f} s before the impact")
ax = top_view(best)
ax.figure.set_size_inches(7, 7)

# %% [markdown]
# ## What each piece of evidence adds
#
# The same fit with each piece left out in turn (given a sigma a billion times its own, so that it weighs nothing):
# the standard error of each speed (from the fit's curvature), and whether the rest still determines it.

# %%
rows = []
for left_out in EVIDENCE:
    r = fit.reconstruct(with_evidence(ignored=[left_out]), starts=4, seed=1)
    rows.append((left_out, r))
print(f"{'left out':16}{'sedan (mph)':>18}{'pickup (mph)':>20}   not determined")
print(f"{'nothing':16}" + "".join(f"{res.estimate[p] / U.MPH:11.2f} +-{res.std[p] / U.MPH:5.2f}"
                                  for p in UNKNOWNS) + f"   {res.not_determined}")
for left_out, r in rows:
    print(f"{left_out:16}" + "".join(f"{r.estimate[p] / U.MPH:11.2f} +-{r.std[p] / U.MPH:5.2f}" for p in UNKNOWNS)
          + f"   {r.not_determined}")

# %% [markdown]
# The rest positions carry most of it. Without them the sedan's speed is not determined (the fit says so, at
# +-16 mph): what is left about the sedan is the pickup's delta-V, which in this near right-angle crash hardly depends
# on the sedan's speed; and the pickup's standard error doubles (0.20 to 0.45 mph), resting on its recorder alone. With
# the rest positions kept, the recorder narrows the pickup's speed a little (0.22 to 0.20 mph) and the delta-V adds
# nothing the others do not already say: here they are checks, each within a sigma of the fit (the residuals above).
# The skid adds no term to the fit; it carries the sedan's speed at the impact back to where its marks begin.
