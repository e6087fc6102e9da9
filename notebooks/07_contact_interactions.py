# %% [markdown]
# # Contact interactions: side-slaps, chains and cumulative delta-V
#
# A crash is rarely one impulse. After the first exchange the vehicles are still moving, turning and sliding, and
# they may meet again: the rear of a car that was struck at its front swings round and slaps the other's side, a
# car pushed forward strikes the one ahead, the striking car catches the struck one again. In a case with a `road`,
# ks-jax watches every pair of bodies while they move to rest and makes a Kudlich-Slibar exchange wherever two
# of them meet and approach (docs/model.md, "Contact interactions"). The panel lists them one by one, as the
# Virtual CRASH manual does under "next contact".
#
# This notebook shows, for reconstruction work:
#
# 1. a side-slap: an oblique impact whose rotation brings the rears of the two vehicles together again;
# 2. a three-car chain: every exchange in time order, and each vehicle's way to rest;
# 3. the chain's exchange times and impulses checked against the closed form of sequential one-dimensional impacts;
# 4. each vehicle's cumulative delta-V beside the delta-V of its first exchange, and which of them an event data
#    recorder's delta-V should be compared with;
# 5. the side-slap's two speeds fitted from where the vehicles came to rest, where a model of the first exchange
#    alone cannot put them where they stopped, and its best speeds are biased;
# 6. a sedan into a semi-trailer: the hitch's impulse after the exchange, and the delta-V it gives the tractor.

# %%
import dataclasses

import jax
jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt
import numpy as np

import ks_jax
import fit
from ks_jax import units as U
from ks_jax.case import case_from_dict
from ks_jax.plot import top_view
from ks_jax.report import text_report
from ks_jax.solve import motion_paths


def keeping_paths(case):
    """The case set to keep every step of its motion: the paths for the pictures then come from the same solve
    (and the same compiled program) as the numbers."""
    return dataclasses.replace(case, motion=dataclasses.replace(case.motion, path=True))


def with_speed(case, i, mph):
    """The case with vehicle i's pre-impact speed set to ``mph``."""
    return dataclasses.replace(case, inputs=ks_jax.set_input(case.inputs, f"vehicles[{i}].speed", mph * U.MPH))


def exchange_rows(sol):
    """Every exchange of a solution, one line each: time, pair, interaction, impulse, energy loss."""
    names = sol.case.vehicle_names
    print(f"{'#':>2} {'time':>7}  {'between':24} {'interaction':>11} {'impulse':>10} {'energy loss':>12}")
    print(f"{'':>2} {'ms':>7}  {'':24} {'':>11} {'lbf s':>10} {'ft lbf':>12}")
    for e in sol.exchange_list():
        pair = " - ".join(names[b] for b in e["between"])
        print(f"{e['index']:2d} {e['time'] * 1000:7.1f}  {pair:24} {e['interaction']:11d}"
              f" {e['impulse_magnitude'] / U.LBF_S:10.1f} {e['energy_loss'] / U.FT_LBF:12.1f}")


# %% [markdown]
# ## 1. A side-slap
#
# An intersection crash: a sedan crosses at 25 mph heading east (yaw 0); a pickup at 40 mph on a heading of 105 deg
# runs into its right side just ahead of its CG, near the front axle. After the impact both drivers lock their
# wheels on a dry road (friction 0.75). The contact is automatic: the centroid and the normal come from the
# overlap of the outlines, 0.04 s after they first touch. The case in the units of the trade, solved, and the
# panel's list of exchanges:

# %%
sedan = {"name": "Sedan", "weight": "3300 lbf", "inertia": ["500 kg*m^2", "2400 kg*m^2", "2600 kg*m^2"],
         "length": "15.5 ft", "width": "6 ft", "height": "4.7 ft", "cg_to_front": "6.9 ft", "cg_height": "1.8 ft",
         "wheelbase": "9.2 ft", "track": "5.2 ft", "cg_to_front_axle": "3.9 ft",
         "position": ["0 ft", "0 ft"], "yaw": 0, "speed": "25 mph", "after": {"wheels": "locked"}}
pickup = {"name": "Pickup", "weight": "4800 lbf", "inertia": ["800 kg*m^2", "4200 kg*m^2", "4500 kg*m^2"],
          "length": "19 ft", "width": "6.7 ft", "height": "6.2 ft", "cg_to_front": "8 ft", "cg_height": "2.2 ft",
          "wheelbase": "12 ft", "track": "5.6 ft", "cg_to_front_axle": "5 ft",
          "position": ["9.1 ft", "-11.5 ft"], "yaw": 105, "speed": "40 mph", "after": {"wheels": "locked"}}
slap_dict = {
    "name": "Side-slap: a pickup into the right front of a crossing sedan, whose rear then slaps the pickup",
    "vehicles": [sedan, pickup],
    "contact": {"restitution": 0.1, "friction": 0.5, "penetration_time": "0.04 s"},
    "road": {"friction": 0.75},
    "interaction": {"max_exchanges": 16},
}
slap = case_from_dict(slap_dict)
slap_sol = ks_jax.solve(keeping_paths(slap))
panel = text_report(slap_sol)
print(panel[panel.index("  exchanges ("):])

# %% [markdown]
# The list has two exchanges, in two interactions. Exchange #0 is the impact the case describes. The outlines
# then part (interaction 0 ends), and about 0.3 s later they meet again: a new interaction, #1, with about a third
# of the first impulse. Where on each vehicle did each exchange act? The centroid of each exchange in each
# vehicle's own frame at that instant (x forward from the CG, y to the left), and each vehicle's heading then, from
# the vehicles' paths:

# %%
def where_on(sol, paths):
    """Each exchange's centroid in each vehicle's frame (ft), the part of the vehicle it lies in (front or rear of
    the CG, and left or right where it is more than a foot off the centre line), and the vehicle's heading then."""
    names = sol.case.vehicle_names
    for e in sol.exchange_list():
        parts = []
        for v in e["between"]:
            x, y, yaw = (np.interp(e["time"], paths[v][:, 0], paths[v][:, k]) for k in (1, 2, 3))
            d = np.asarray(e["point"][:2]) - (x, y)
            bx, by = np.cos(yaw) * d[0] + np.sin(yaw) * d[1], np.cos(yaw) * d[1] - np.sin(yaw) * d[0]
            lateral = "left " if by > 1.0 * U.FT else "right " if by < -1.0 * U.FT else ""
            side = lateral + ("front" if bx > 0 else "rear")
            parts.append(f"{names[v]} {side:11} ({bx / U.FT:+5.1f}, {by / U.FT:+5.1f}) ft,"
                         f" heading {np.degrees(yaw) % 360:5.1f} deg")
        print(f"#{e['index']} at {e['time'] * 1000:5.1f} ms:  " + ";  ".join(parts))

slap_paths = motion_paths(slap_sol)
where_on(slap_sol, slap_paths)
for name, r in zip(slap.vehicle_names, slap_sol.result.rest):
    print(f"{name:7} at rest at ({r.rest_position[0] / U.FT:5.1f}, {r.rest_position[1] / U.FT:5.1f}) ft,"
          f" heading {float(r.rest_yaw):5.1f} deg, after {float(r.time_to_rest):.2f} s")

# %% [markdown]
# Exchange #0 is the pickup's front against the sedan's right side ahead of its CG. The impulse, ahead of the
# sedan's CG, spins the sedan to the left (counter-clockwise); the pickup, its front dragged east by the sedan's
# side, turns to the right. Both rears swing round towards each other, and at #1 the sedan's right rear meets
# the pickup's left side behind its CG: the side-slap. It takes out much of the sedan's spin, and the sedan comes
# to rest pointing roughly north; section 5 shows where it would have ended without it.
#
# The top view draws the first exchange whole (outlines, centroid, contact plane, normal, impulse, friction cone),
# marks the later one where it happened with its number, its normal and its impulse on both vehicles, and draws
# each vehicle's path to rest with faded outlines along the way.

# %%
ax = top_view(slap_sol)
ax.figure.set_size_inches(6, 5.5)

# %% [markdown]
# ## 2. A three-car chain
#
# `docs/examples/three_car_chain.json`: a pickup at 30 mph strikes the rear of a sedan stopped at a light, 4.4 ft
# ahead of it; the sedan, its driver on the brake, is driven into the rear of an SUV stopped 6.3 ft ahead of the
# sedan, also braked. The pickup's driver locks the wheels at the impact. The first exchange is the pickup's with
# the sedan (`"between": [0, 1]`, the default); everything after it is found by the watch.

# %%
chain = ks_jax.load_case("../docs/examples/three_car_chain.json")
chain_sol = ks_jax.solve(keeping_paths(chain))
names = chain.vehicle_names
exchange_rows(chain_sol)

# %% [markdown]
# **What "next contact" means.** After an exchange the program does not assume the crash is over. It moves every
# vehicle on, step by step, with its tyre forces, and at every step looks at every pair of bodies: where two
# outlines overlap and the two bodies approach each other at the overlap's centroid, they are in contact again,
# and after the penetration time they exchange another impulse, computed from their velocities at that instant.
# That later exchange is the "next contact". An interaction is one spell of overlap of one pair: a pair that
# parts and meets again opens a new interaction.
#
# Here the list reads as the crash happened. #0: the pickup strikes the sedan. The sedan leaves at 20 mph and
# closes the 6.3 ft to the SUV: #1, 0.28 s later, is the sedan into the SUV (interaction 1). That slows the sedan
# from 15 to 6 mph, and the pickup, still sliding towards it and still overlapping it, strikes it again (#2,
# interaction 0 still: the pickup and the sedan never parted). The exchanges that follow grow smaller and smaller:
# the sedan is caught between the pickup and the SUV, pushed forward and stopped in turn, until all three are at
# rest in contact.
#
# Each vehicle's position along the road against time shows the same thing: the lines bend where an exchange
# pushes them (dots) and flatten where the tyres bring them to rest.

# %%
chain_paths = motion_paths(chain_sol)
fig, ax = plt.subplots(figsize=(8, 4.2))
for v, (name, p) in enumerate(zip(names, chain_paths)):
    ax.plot(p[:, 0], p[:, 1] / U.FT, color=f"C{v}", label=name)
for e in chain_sol.exchange_list():
    for v in e["between"]:
        p = chain_paths[v]
        ax.plot(e["time"], np.interp(e["time"], p[:, 0], p[:, 1]) / U.FT, "o", ms=4, color="k")
    if e["impulse_magnitude"] > 0.1 * chain_sol.exchange_list()[0]["impulse_magnitude"]:
        ax.annotate(f"#{e['index']}", (e["time"], np.interp(e["time"], chain_paths[e["between"][1]][:, 0],
                                                            chain_paths[e["between"][1]][:, 1]) / U.FT),
                    xytext=(3, 6), textcoords="offset points", fontsize=8)
ax.set_xlabel("time from the first exchange (s)")
ax.set_ylabel("CG position along the road, x (ft)")
ax.set_title("Three-car chain: each vehicle's CG to rest; dots: exchanges (numbered where over 10% of #0)",
             fontsize=9)
ax.grid(alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()

# %% [markdown]
# The top view: the first exchange drawn whole, the later ones numbered where they happened, and each vehicle's
# path and outline at rest.

# %%
ax = top_view(chain_sol)
ax.figure.set_size_inches(6.5, 4)

# %% [markdown]
# ## 3. A check against the closed form of sequential impacts
#
# The same three vehicles on a frictionless plane, in line on y = 0, the pickup at 30 mph, the other two at rest,
# restitution 0.3, no penetration time, every CG at the height of the contacts (2.35 ft, half the sedan's height)
# so that no impulse has a lever to pitch a vehicle. Then each exchange is a one-dimensional impact: where two
# neighbours k and k+1 close, they meet when the gap between them is closed, and the impulse is
#
# J = (1 + e) m_k m_k+1 / (m_k + m_k+1) (v_k - v_k+1),
#
# which changes their velocities by -J / m_k and +J / m_k+1; between impacts every vehicle keeps its velocity.
# The sequence below is computed from that alone, and ks-jax's exchanges must match it: the same pairs in the
# same order, at the same times, with the same impulses, and the same positions at the end.

# %%
ideal = {**chain.raw, "name": "three in line on a frictionless plane", "description": "",
         "vehicles": [{**v, "position": [v["position"][0], "0 ft"], "cg_height": "2.35 ft"}
                      for v in chain.raw["vehicles"]],
         "contact": {"restitution": 0.3, "friction": 0.5, "penetration_time": "0 s"},
         "road": {"friction": 0}}
ideal_case = keeping_paths(case_from_dict(ideal))
ideal_sol = ks_jax.solve(ideal_case)

m = np.array([float(v.mass) for v in ideal_case.inputs.vehicles])
x = np.array([U.parse_quantity(v["position"][0], "length") for v in ideal["vehicles"]])
front = np.array([U.parse_quantity(v["cg_to_front"], "length") for v in ideal["vehicles"]])
rear = np.array([U.parse_quantity(v["length"], "length") for v in ideal["vehicles"]]) - front
vel = np.array([30 * U.MPH, 0.0, 0.0])
e_r = 0.3
t, closed = 0.0, []
while True:
    closing = [((x[k + 1] - rear[k + 1] - x[k] - front[k]) / (vel[k] - vel[k + 1]), k)
               for k in range(2) if vel[k] > vel[k + 1]]
    if not closing:
        break
    dt, k = min(closing)
    t, x = t + dt, x + vel * dt
    j = (1 + e_r) * m[k] * m[k + 1] / (m[k] + m[k + 1]) * (vel[k] - vel[k + 1])
    vel[k], vel[k + 1] = vel[k] - j / m[k], vel[k + 1] + j / m[k + 1]
    closed.append((t, (k, k + 1), j))

got = ideal_sol.exchange_list()
t_first = float(ideal_sol.result.contact.time)
print(f"{'#':>2} {'pair':>6} {'time ks-jax':>12} {'closed form':>12} {'impulse ks-jax':>15} {'closed form':>12}")
for g, (tc, pair, jc) in zip(got, closed):
    print(f"{g['index']:2d} {str(tuple(g['between'])):>6} {t_first + g['time']:10.6f} s {tc:10.6f} s"
          f" {g['impulse_magnitude']:11.3f} N s {jc:10.3f} N s")
end = t_first + ideal_case.motion.time_limit
x_end = x + vel * (end - t)

assert [tuple(g["between"]) for g in got] == [pair for _, pair, _ in closed]
np.testing.assert_allclose([t_first + g["time"] for g in got], [tc for tc, _, _ in closed], rtol=0, atol=1e-9)
np.testing.assert_allclose([g["impulse_magnitude"] for g in got], [jc for _, _, jc in closed], rtol=1e-9)
np.testing.assert_allclose([r.rest_position[0] for r in ideal_sol.result.rest], x_end, rtol=0, atol=1e-8)
print(f"\n{len(closed)} exchanges: pairs, times (to 1e-9 s), impulses (to 1e-9 of each) and the positions"
      f" {ideal_case.motion.time_limit:.0f} s after the first exchange (to 1e-8 m) agree with the closed form")

# %% [markdown]
# ## 4. Cumulative delta-V and the delta-V of the first exchange
#
# For each vehicle, ks-jax reports the delta-V of each exchange it took part in, and over its first contact
# interaction a **cumulative delta-V**: its velocity just after the interaction's last exchange less its velocity
# just before the first (`vehicles[i].delta_v_cumulative`, `_magnitude`, `_pdof`). Beside it,
# `interactions[k].delta_v_impulses` is the sum of that interaction's impulses over the vehicle's mass: the
# velocity change the exchanges alone would give, without the tyres. For the chain:

# %%
d = chain_sol.to_dict()
ex = d["exchanges"]
table = []
print(f"{'vehicle':8} {'first exchange':>15} {'its delta-V':>12} {'impulses only':>14} {'cumulative':>11}"
      f" {'interaction lasts':>18}")
for i, v in enumerate(d["vehicles"]):
    inter = v["interactions"][0]
    first = next(e for e in ex if i in e["between"])
    dv_first = next(w["delta_v_magnitude"] for w in first["vehicles"] if w["vehicle"] == i)
    dv_imp = float(np.linalg.norm(inter["delta_v_impulses"]))
    dv_cum = v["delta_v_cumulative_magnitude"]
    span = ex[inter["exchanges"][-1]]["time"] - ex[inter["exchanges"][0]]["time"]
    table.append((dv_first, dv_imp, dv_cum))
    print(f"{v['name']:8} {'#' + str(first['index']):>15} {dv_first / U.MPH:8.2f} mph {dv_imp / U.MPH:10.2f} mph"
          f" {dv_cum / U.MPH:7.2f} mph {span * 1000:11.0f} ms, {len(inter['exchanges'])} exchanges")

fig, ax = plt.subplots(figsize=(7.5, 3.8))
width = 0.26
labels = ("delta-V of its first exchange", "sum of its interaction's impulses / mass",
          "cumulative delta-V (tyre forces included)")
for k, label in enumerate(labels):
    ax.bar(np.arange(3) + (k - 1) * width, [row[k] / U.MPH for row in table], width, label=label,
           color=("tab:gray", "tab:olive", "tab:purple")[k])
ax.set_xticks(np.arange(3), names)
ax.set_ylabel("delta-V (mph)")
ax.set_title("Three-car chain: each vehicle's delta-V over its first contact interaction", fontsize=9)
ax.legend(fontsize=8)
ax.grid(axis="y", alpha=0.3)
fig.tight_layout()

# %% [markdown]
# The three numbers differ for two reasons.
#
# - **Several exchanges.** The pickup and the sedan exchange five impulses in their one interaction, the sedan and
#   the SUV five in theirs. The first exchange's delta-V is only the start of it: the SUV's first exchange gives it
#   7.2 mph, and the four after it add 1.9 mph more.
# - **Tyre forces between them.** An interaction lasts as long as the two outlines overlap, here half a second
#   and more, and all that time every locked wheel slows its vehicle. The cumulative delta-V includes that:
#   the pickup's, 28 mph, is nearly all of its 30 mph, because it was braking in contact with the sedan until it
#   stopped; the SUV's is under 1 mph, because its brakes took back nearly all that the sedan gave it before the
#   last exchange. The sum of impulses over the mass leaves the tyres out and lies in between.
#
# **Which one an EDR's delta-V should be compared with.** An event data recorder integrates the acceleration its
# module measures: every force on the vehicle, the impulses and the tyre forces alike, over its recording window
# (for the longitudinal delta-V of a US record under 49 CFR Part 563, 250 ms from the event's start). So compare a
# recorded delta-V with the velocity change over that same window, tyre forces included: the cumulative delta-V
# where the interaction ends within the window, and the velocity change up to the window's end where it lasts
# longer, as here. Not with the first exchange's delta-V alone, unless the first exchange is the whole event. From
# each vehicle's path, the change of its CG velocity from just before its first exchange to 250 ms after it:

# %%
def velocity_at(p, t):
    """The CG velocity (vx, vy) m/s of a kept path at time t: over the step that holds t."""
    i = int(np.clip(np.searchsorted(p[:, 0], t) - 1, 0, len(p) - 2))
    return (p[i + 1, 1:3] - p[i, 1:3]) / (p[i + 1, 0] - p[i, 0])

before = [np.array([30 * U.MPH, 0.0]), np.zeros(2), np.zeros(2)]  # as the case gives them
for i, v in enumerate(d["vehicles"]):
    first = next(e for e in ex if i in e["between"])
    dv = velocity_at(chain_paths[i], first["time"] + 0.25) - before[i]
    print(f"{v['name']:7} 0-250 ms from its first exchange (#{first['index']}): {np.hypot(*dv) / U.MPH:5.2f} mph;"
          f" first exchange {table[i][0] / U.MPH:5.2f} mph, cumulative {table[i][2] / U.MPH:5.2f} mph")

# %% [markdown]
# For the pickup a 250 ms record would hold about 17 mph: 12.7 mph from the first exchange and some 4 mph of
# braking after it (its second exchange, at 325 ms, falls outside the window). Neither the first exchange's
# 12.7 mph nor the cumulative 28 mph, over 0.73 s, is what its recorder would hold. The sedan's record would
# show the push from behind less its braking, 16 mph; the SUV's, struck at 275 ms, the first exchange's 7.2 mph
# and the later ones less 250 ms of its own braking, about 5 mph.
#
# In the side-slap of section 1 the two exchanges are two interactions: the outlines parted in between. Each
# vehicle's cumulative delta-V is that of its first interaction, here the first exchange alone; the slap is
# reported as an interaction of its own. It came 0.31 s after the first impact, after a 250 ms window closes: a
# recorder that stores several events may hold it as a second one.

# %%
for v in slap_sol.to_dict()["vehicles"]:
    for inter in v["interactions"]:
        print(f"{v['name']:7} interaction {inter['interaction']} (exchanges {inter['exchanges']}):"
              f" delta-V {inter['delta_v_magnitude'] / U.MPH:5.2f} mph")
    print(f"{'':7} cumulative delta-V (its first interaction): {v['delta_v_cumulative_magnitude'] / U.MPH:5.2f} mph")

# %% [markdown]
# ## 5. Speeds from rest positions that need the side-slap
#
# Back to the side-slap of section 1, now as a reconstruction: both speeds are unknown, and the scene gives where
# the two vehicles came to rest and which way they pointed. The evidence is generated by the model itself at the
# speeds of section 1 (sedan 25 mph, pickup 40 mph), without noise, so that the fit can be checked against that
# truth; its sigmas are those of a careful scene survey: 1 ft for each rest coordinate, 5 deg for each rest
# heading. The unknowns are the sedan's speed (10 to 45 mph) and the pickup's (20 to 60 mph); four starts, one
# round.

# %%
measured = {}
for i, r in enumerate(slap_sol.result.rest):
    measured[f"vehicles[{i}].rest_position[0]"] = float(r.rest_position[0])
    measured[f"vehicles[{i}].rest_position[1]"] = float(r.rest_position[1])
for i, r in enumerate(slap_sol.result.rest):
    measured[f"vehicles[{i}].rest_yaw"] = float(r.rest_yaw)
sigma = {p: (5.0 if p.endswith("rest_yaw") else 1.0 * U.FT) for p in measured}   # SI; degrees for rest_yaw
evidence = [fit.Evidence(p, measured[p], sigma[p]) for p in measured]
unknowns = {"vehicles[0].speed": {"bounds": ["10 mph", "45 mph"]},
            "vehicles[1].speed": {"bounds": ["20 mph", "60 mph"]}}
res = fit.reconstruct(slap, unknowns, evidence, starts=4, max_starts=4)
print(f"converged: {res.converged}; chi^2 = {res.chi2:.1e}; {res.starts_at_best} of {res.starts} starts at the best;"
      f" unidentified: {res.unidentified}")
truth = {"vehicles[0].speed": 25.0, "vehicles[1].speed": 40.0}
for p, true in truth.items():
    print(f"  {p:18} {res.estimate[p] / U.MPH:7.3f} +- {res.std[p] / U.MPH:.2f} mph   (truth {true:.0f} mph)")
    assert abs(res.estimate[p] / U.MPH - true) < 0.01

# %% [markdown]
# The fit finds both speeds, each to about half a mile an hour.
#
# Now the same evidence for a model of the first exchange alone: the case with `"interaction": {"max_exchanges":
# 1}`, which solves the pickup's impact and then carries each vehicle to rest without any later exchange (the
# vehicles pass through each other where they would have slapped). Its best speeds are found by sweeping both
# speeds over their bounds (`ks_jax.sweep`: every point of a grid solved in one compiled call), then over a finer
# grid about the best point; its chi^2 is computed as the fit computes it (headings compared on the circle).

# %%
one = case_from_dict({**slap_dict, "interaction": {"max_exchanges": 1}})


def rest_results(case, speeds_mph):
    """The case solved at the two speeds (mph): each evidence path -> its value (SI; degrees for rest_yaw), and
    the solution."""
    sol = ks_jax.solve(with_speed(with_speed(case, 0, speeds_mph[0]), 1, speeds_mph[1]))
    return {p: float(ks_jax.get_output(sol.result, p)) for p in measured}, sol


def residuals(values):
    """Each evidence's (value - measured) / sigma, headings on the circle (values: numbers or arrays)."""
    r = {p: np.asarray(values[p], float) - measured[p] for p in measured}
    for p in r:
        if p.endswith("rest_yaw"):
            r[p] = (r[p] + 180.0) % 360.0 - 180.0
    return {p: r[p] / sigma[p] for p in r}


def grid_search(sedan_mph, pickup_mph):
    """chi^2 of the first-exchange model over a grid of the two speeds (mph): (chi^2 grid, its least point)."""
    swept = ks_jax.sweep(one, {"vehicles[0].speed": sedan_mph * U.MPH, "vehicles[1].speed": pickup_mph * U.MPH},
                         outputs=list(measured))
    chi2 = sum(r ** 2 for r in residuals({p: swept[p] for p in measured}).values())
    k = np.unravel_index(np.nanargmin(chi2), chi2.shape)
    return chi2, (sedan_mph[k[0]], pickup_mph[k[1]])


coarse, (s0, p0) = grid_search(np.linspace(10, 45, 15), np.linspace(20, 60, 17))
fine, best_x = grid_search(np.linspace(s0 - 2.5, s0 + 2.5, 15), np.linspace(p0 - 2.5, p0 + 2.5, 17))
best_chi2 = float(np.nanmin(fine))
one_values, one_sol = rest_results(one, best_x)
print(f"first exchange only: sedan {best_x[0]:.1f} mph, pickup {best_x[1]:.1f} mph (truth 25 and 40);"
      f" chi^2 = {best_chi2:.0f} for 6 evidence and 2 unknowns\n(99% of chi^2 draws on 4 degrees of freedom"
      " fall below 13.3)\n")
print(f"{'evidence':28} {'measured':>9} {'fit, every exchange':>21} {'first exchange only':>22}")
for p in measured:
    u, name = (1.0, "deg") if p.endswith("rest_yaw") else (U.FT, "ft")
    print(f"{p:28} {measured[p] / u:6.1f} {name:3} {res.fitted[p] / u:7.1f} ({residuals(res.fitted)[p]:+5.1f} sigma)"
          f" {one_values[p] / u:7.1f} ({residuals(one_values)[p]:+6.1f} sigma)")
at_truth = ks_jax.solve(with_speed(with_speed(one, 0, 25.0), 1, 40.0))
print("\nturned from the first exchange to rest, at the true speeds:")
for name, r_all, r_one in zip(slap.vehicle_names, slap_sol.result.rest, at_truth.result.rest):
    print(f"  {name:7} every exchange {float(r_all.rotation_to_rest):+6.1f} deg,"
          f" first exchange only {float(r_one.rotation_to_rest):+6.1f} deg")
print("\nthe first-exchange model's notes at its best fit:")
for note in one_sol.notes():
    print("  " + note)

# %% [markdown]
# Without the slap both vehicles spin on: at the true speeds the first-exchange model turns the sedan through
# 205 deg instead of 82, and the pickup through 173 deg instead of 108. The slap took that spin out of both. The
# only way the first-exchange model has to turn them less is a smaller first impulse, that is, less speed; so its
# best fit puts the sedan 6 mph and the pickup 7 mph below the truth, and pays for it in position: it leaves the
# sedan some 15 ft short of where it was found, still turned 46 deg too far, and the pickup about 5 ft off. Its
# chi^2 is far above anything a foot and 5 deg of measurement error would give. Its own notes say what is wrong
# with it: a pair was due for another exchange when the one allowed was spent, and the two vehicles end inside
# each other, by 3.1 m. The picture: each vehicle's outline where it was found (solid) and where the
# first-exchange model's best fit leaves it (dashed).

# %%
def outline(raw, x, y, yaw_deg):
    """A vehicle's footprint (closed, ft) with its CG at (x, y) ft, turned ``yaw_deg``."""
    length, front, width = (U.parse_quantity(raw[k], "length") / U.FT for k in ("length", "cg_to_front", "width"))
    box = np.array([[front, width / 2], [front, -width / 2], [front - length, -width / 2],
                    [front - length, width / 2], [front, width / 2]])
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    return box @ np.array([[c, s], [-s, c]]) + (x, y)


fig, ax = plt.subplots(figsize=(7.5, 6))
for i, raw in enumerate(slap_dict["vehicles"]):
    for values, style, what in ((measured, "-", "measured rest"), (one_values, "--", "first exchange only")):
        xy = outline(raw, values[f"vehicles[{i}].rest_position[0]"] / U.FT,
                     values[f"vehicles[{i}].rest_position[1]"] / U.FT, values[f"vehicles[{i}].rest_yaw"])
        ax.plot(xy[:, 0], xy[:, 1], style, color=f"C{i}", lw=1.6, label=f"{raw['name']}: {what}")
        ax.plot(xy[0:2, 0], xy[0:2, 1], style, color=f"C{i}", lw=3.5)   # the front face
    start = outline(raw, *(U.parse_quantity(q, "length") / U.FT for q in raw["position"]), raw["yaw"])
    ax.plot(start[:, 0], start[:, 1], ":", color=f"C{i}", lw=1, label=f"{raw['name']}: at the start of the case")
ax.set_aspect("equal")
ax.set_xlabel("x (ft)")
ax.set_ylabel("y (ft)")
ax.set_title("Side-slap: rest positions found, and the first-exchange model's best fit\n"
             f"(sedan {best_x[0]:.1f} mph, pickup {best_x[1]:.1f} mph; truth 25 and 40 mph; front faces thick)",
             fontsize=9)
ax.grid(alpha=0.3)
ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
fig.tight_layout()

# %% [markdown]
# For a reconstructionist: where the vehicles turned into each other again after the first impact (scuffs and
# crush along the rear quarters, a second set of debris), a model of the first exchange alone is the wrong model,
# and fitting speeds with it biases them, here by 6 and 7 mph, low. The misfit of the rest positions and headings is
# the warning; a model that includes the later exchanges removes it and returns the speeds the scene was made from.

# %% [markdown]
# ## 6. Articulated vehicles: a sedan into a semi-trailer
#
# `docs/examples/semi_trailer_side_impact.json`: a tractor and its loaded semi-trailer cross northbound at 15 mph; a
# sedan eastbound at 40 mph strikes the trailer's left side at its tandem axles. The trailer rides on the tractor's
# fifth wheel, 8 ft behind the tractor's CG (the trailer's `"hitch"`, docs/model.md, "Articulated vehicles"). The
# exchange is computed between the sedan and the trailer alone, ignoring the hitch, as Virtual CRASH does; right
# after it an impulse at the fifth wheel brings the two hitch points to one velocity (perfectly plastic). So the
# tractor, which the sedan never touched, is moved too. The panel from the trailer on, in US units:

# %%
semi = ks_jax.load_case("../docs/examples/semi_trailer_side_impact.json")
semi_sol = ks_jax.solve(keeping_paths(semi))
panel = text_report(semi_sol, units="us")
print(panel[panel.index("  vehicle 2 = "):])

# %% [markdown]
# Each vehicle's delta-V of the exchange beside its cumulative delta-V, which includes the joint's impulse, and the
# exchanges of its first interaction. The joint's impulse is internal to the three vehicles, as the exchange's is:
# the sum of each vehicle's mass times `delta_v_impulses` (its impulses, the joint's included, over its mass), the
# change of their total linear momentum that the impulses make, must be 0.

# %%
sd = semi_sol.to_dict()
print(f"{'vehicle':13} {'exchange delta-V, PDOF':>22}  {'cumulative, PDOF':>20}  exchanges")
for v in sd["vehicles"]:
    first = (f"{v['delta_v_magnitude'] / U.MPH:5.2f} mph, {v['pdof']:5.1f} deg" if v["pdof"] is not None
             else "(not in it)")
    print(f"{v['name']:13} {first:>22}  {v['delta_v_cumulative_magnitude'] / U.MPH:5.2f} mph,"
          f" {v['delta_v_cumulative_pdof']:5.1f} deg  {v['interactions'][0]['exchanges']}")
mass = np.array([float(v.mass) for v in semi.inputs.vehicles])
impulses = mass[:, None] * np.asarray(semi_sol.result.interactions.delta_v_impulses)   # N s, each vehicle's
joint = np.linalg.norm(impulses[2])   # the tractor's: the joint's impulse alone
exchange = float(semi_sol.result.contact.impulse_magnitude)
print(f"\nthe exchange's impulse {exchange / U.LBF_S:,.0f} lbf s; the joint's on the tractor {joint / U.LBF_S:,.0f}"
      f" lbf s; total momentum change {np.linalg.norm(impulses.sum(0)):.1e} N s")
assert np.linalg.norm(impulses.sum(0)) <= 1e-6 * exchange
assert sd["vehicles"][2]["interactions"][0]["exchanges"] == [] and joint > 0

# %% [markdown]
# The sedan's cumulative delta-V is its exchange's: the joint does not act on it. The trailer's grows from 3.7 to
# 4.1 mph and its PDOF moves from 279 to 275 deg: struck behind its CG, the trailer would swing its front west
# about its CG; the fifth wheel holds its front (a push east, which adds to its CG's velocity east) and makes the
# tractor share its loss of speed north. The tractor's 0.8 mph, from its front right (PDOF 64 deg: pushed west and
# slowed), comes from the joint alone: its interaction has no exchange of its own. A recorder in the tractor would
# see that push, not the sedan's. The top view marks the hitch (a diamond at the fifth wheel, joined to both CGs)
# at the exchange and at rest, where the trailer's heading is 6 deg left of the tractor's.

# %%
ax = top_view(semi_sol)
ax.figure.set_size_inches(6, 6)
