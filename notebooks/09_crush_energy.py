# %% [markdown]
# # Crush energy beside momentum: a T-bone fitted from delta-V, from crush, and from both
#
# A momentum reconstruction is usually checked against the vehicles' crush: the depths measured across the damage
# (the crush profile) and the damaged side's stiffness (A and B, from crash tests of similar vehicles) give the
# energy each vehicle's structure absorbed (CRASH3; docs/model.md, "Crush energy"). ks-jax reports that energy, its
# uncertainty from those of the stiffness and the measurements, the equivalent speed, and CRASH3's delta-V; where
# both vehicles have a profile, the exchange's energy loss is shared between them in proportion to their crush
# energies; and a fit takes a crush energy as evidence (docs/fit.md, "Crush energy").
#
# The case is `docs/examples/tbone_crush_profiles.json`: a pickup's front (vehicle 2, 35 mph) into the right side
# of a crossing sedan (vehicle 1, 25 mph), six depths measured across each damaged side. The motion to rest does not
# bear on the crush and is left out here (the road and the wheels' settings removed), so each fit compiles in
# seconds.

# %%
import copy
import json

import jax
jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt

import ks_jax
import fit
from ks_jax import units as U
from ks_jax.case import case_from_dict
from ks_jax.plot import top_view

raw = json.loads(open("../docs/examples/tbone_crush_profiles.json").read())
for key in ("road", "interaction"):
    raw.pop(key)
for v in raw["vehicles"]:
    for key in ("wheelbase", "track", "cg_to_front_axle", "after"):
        v.pop(key)
truth = case_from_dict(raw)
names = truth.vehicle_names
for name, v in zip(names, raw["vehicles"]):
    print(f"{name:7} {v['speed']:>7}  stiffness {v['stiffness']}\n{'':17}profile {v['crush_profile']}")

# %% [markdown]
# ## Crush energy and momentum, side by side
#
# Solved at the true speeds: each vehicle's crush energy (with its one-sigma uncertainty), the speed at which its
# kinetic energy would be that energy (its EES), and CRASH3's delta-V, which assumes a central impact that ends at a
# common velocity, against the exchange's own. The two crush energies sum to 95 % of the exchange's energy loss,
# well within their uncertainty; the EES here is the exchange's, its energy loss shared by the crush energies.

# %%
sol = ks_jax.solve(truth)
out = sol.to_dict()
loss = out["contact"]["energy_loss"]
print(f"exchange's energy loss {loss / 1e3:.1f} kJ; crush energies sum to "
      f"{sum(v['crush_energy'] for v in out['vehicles']) / 1e3:.1f} kJ")
print(f"{'':8}{'crush energy':>18}{'crush EES':>11}{'EES':>8}{'CRASH3 dV':>11}{'exchange dV':>13}")
for v in out["vehicles"]:
    print(f"{v['name']:8}{v['crush_energy'] / 1e3:10.1f} +- {v['crush_energy_sigma'] / 1e3:3.1f} kJ"
          f"{v['crush_ees'] / U.MPH:7.1f} mph{v['ees'] / U.MPH:5.1f} mph{v['crush_delta_v'] / U.MPH:7.1f} mph"
          f"{v['delta_v_magnitude'] / U.MPH:9.1f} mph")

# %% [markdown]
# The top view draws each measured profile to scale on its damaged side where the vehicles meet (here zoomed on the
# contact): the crushed outline, filled to the undeformed face, C1 at the front end of the sedan's side and at the
# left end of the pickup's front. The box overlap at the exchange, and the crush the panel calls "crush, box
# overlap (model)", are the model's contact geometry, not these measurements.

# %%
ax = top_view(sol)
ax.figure.set_size_inches(7, 6.5)
ax.set_adjustable("box")  # the limits below, at equal scales
ax.set_xlim(-3.5, 4.5)
ax.set_ylim(-3.5, 2.5)

# %% [markdown]
# ## Three fits: delta-V alone, crush alone, both
#
# Both speeds are unknown. The delta-V evidence is what the two event data recorders would give: each vehicle's
# longitudinal and lateral delta-V, rounded to 0.1 mph, with a sigma of 1 mph. The crush evidence is each vehicle's
# crush energy from its profile and stiffness, with the sigma propagated from theirs.

# %%
dv = [[round(x / U.MPH, 1) for x in v["delta_v_body"][:2]] for v in out["vehicles"]]
EVIDENCE = {
    "delta-V": [{"quantity": f"vehicles[{i}].delta_v_body[{k}]", "value": f"{dv[i][k]} mph", "sigma": "1 mph"}
                for i in (0, 1) for k in (0, 1)],
    "crush": [{"quantity": f"vehicles[{i}].crush_energy"} for i in (0, 1)],
}
UNKNOWNS = {"vehicles[0].speed": {"bounds": ["5 mph", "60 mph"], "start": "20 mph"},
            "vehicles[1].speed": {"bounds": ["5 mph", "60 mph"], "start": "30 mph"}}


def fitted(kinds, case=raw):
    """The fit of both speeds from the evidence of ``kinds``, on ``case`` (a file's dict)."""
    return fit.reconstruct(case_from_dict(dict(case, unknowns=UNKNOWNS,
                                               evidence=[e for k in kinds for e in EVIDENCE[k]])), starts=4)


def show(label, res):
    speeds = "   ".join(f"{res.estimate[p] / U.MPH:5.2f} +- {res.std[p] / U.MPH:4.2f}" for p in UNKNOWNS)
    print(f"{label:26}{speeds}   chi^2 {res.chi2:5.2f}")


print(f"{'evidence':26}{'sedan, mph':>15}{'pickup, mph':>17}")
fits = {kinds: fitted(kinds.split(" + ")) for kinds in ("delta-V", "crush", "delta-V + crush")}
for kinds, res in fits.items():
    show(kinds, res)
print("\ncrush alone:", fits["crush"].unidentified[0])

# %% [markdown]
# Delta-V alone determines both speeds; the pickup's (the striking vehicle's) more tightly than the sedan's. Crush
# alone cannot: the two energies fix the exchange's energy loss, one combination of the speeds, and the fit says so
# (its standard errors are infinite, and `unidentified` names the combination). Together they agree: every residual
# is within a quarter of a sigma, and the crush narrows the sedan's speed a little.
#
# ## Where they disagree
#
# Suppose the sedan's side stiffness was taken from a stiffer category, with A and B doubled (240 lbf/in and
# 90 lbf/in^2): its crush energy is then about twice what the crash made. The fit from delta-V and crush together:

# %%
wrong = copy.deepcopy(raw)
wrong["vehicles"][0]["stiffness"].update(A="240 lbf/in", B="90 lbf/in^2")
high = ks_jax.solve(case_from_dict(wrong)).to_dict()["vehicles"][0]["crush_energy"]
print(f"the sedan's crush energy: {high / 1e3:.1f} kJ with A and B doubled, "
      f"{out['vehicles'][0]['crush_energy'] / 1e3:.1f} kJ before")
res = fitted(["delta-V", "crush"], wrong)
show("delta-V + wrong crush", res)
for path, r in res.residuals.items():
    print(f"  {path:28} residual {r:+.2f} sigma")
at = ks_jax.solve(case_from_dict(dict(raw, vehicles=[dict(v, speed=f"{res.estimate[f'vehicles[{i}].speed']!r} m/s")
                                                     for i, v in enumerate(raw["vehicles"])])))
alone = fits["delta-V"]
shift = (res.estimate["vehicles[0].speed"] - alone.estimate["vehicles[0].speed"]) / alone.std["vehicles[0].speed"]
print(f"the contact at the estimate: {'sliding' if bool(at.result.contact.sliding) else 'sticking'};"
      f" the sedan's speed moved {shift:.1f} standard errors of the delta-V fit")

# %% [markdown]
# chi^2 stays small and no residual stands out, yet the sedan's speed has moved far from the truth's 25 mph. The
# extra energy has found a place to go: at the true speeds the contact sticks, but a faster sedan makes it slide
# along the sedan's side, and a sliding contact's impulse, so both delta-Vs, hardly depends on the sedan's speed,
# while the energy lost to the sliding grows with it. The fit cannot
# tell a wrong stiffness from a faster sedan; what shows the disagreement is the fit with the crush left out: here
# the sedan's speed moves by several of its standard errors when the crush is added. A reconstruction that rests on
# crush energy should be fitted with and without it, as notebook 08 does with each piece of its evidence.

# %%
fig, ax = plt.subplots(figsize=(7, 2.8))
rows = [("delta-V", fits["delta-V"]), ("delta-V + crush", fits["delta-V + crush"]),
        ("delta-V + wrong crush", res)]
for y, (label, r) in enumerate(rows):
    for k, (path, color) in enumerate(zip(UNKNOWNS, ("tab:blue", "tab:orange"))):
        ax.errorbar(r.estimate[path] / U.MPH, y + 0.12 * (k - 0.5), xerr=r.std[path] / U.MPH, fmt="o",
                    color=color, capsize=3, label=names[k] if y == 0 else None)
for speed, color in ((25, "tab:blue"), (35, "tab:orange")):
    ax.axvline(speed, color=color, lw=0.8, ls=":")
ax.set_yticks(range(len(rows)), [label for label, _ in rows])
ax.set_xlabel("speed at the impact (mph), +- one standard error; dotted: the truth")
ax.legend(loc="lower right", fontsize=8)
fig.tight_layout()
