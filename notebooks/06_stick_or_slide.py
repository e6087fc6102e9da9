# %% [markdown]
# # Stick or slide: what the posterior says where the best fit misleads
#
# In the KS model the tangential part of the impulse is limited by the friction at the impulse centroid. If the
# friction is high enough to bring the two surfaces to a common velocity there, the contact **sticks**, and every
# friction above that threshold gives the same exchange. If not, the contact **slides**, the impulse lies on the
# edge of the friction cone, and the friction sets it. Evidence that fits a sticking contact therefore says only
# "friction above some value", and a sliding contact with a friction just below the threshold can fit nearly as
# well, or a little better where the measurements' errors happen to favour it.
#
# A least-squares fit returns one point and a Gaussian about it (the Laplace approximation). When that point
# slides just below the threshold, the Gaussian is all about the sliding answer. The posterior, drawn by NUTS
# through the smooth engine, shows both answers and how much of the probability each holds.
#
# The shipped case `fit_stick_or_slide.json` is an oblique side impact: a sedan's front into an SUV's right side.
# Six unknowns (both speeds, restitution, friction, the centroid's x and y), ten evidence (both EDR delta-V
# components, yaw rates and speeds after the impact, crush). The evidence was made from a sticking contact with
# friction 0.25, with a random error of one sigma added to each measurement, so the answers can be checked.

# %%
import re
from importlib import resources

import jax
jax.config.update("jax_enable_x64", True)
import matplotlib.pyplot as plt
import numpy as np

import ks_jax
import fit
from ks_jax import units as U
from ks_jax.plot.corner import corner

case = ks_jax.load_case(resources.files("ks_jax.cases") / "fit_stick_or_slide.json")
print(case.name)
for name, raw in zip(case.vehicle_names, case.raw["vehicles"]):
    print(f"  {name:6} {raw['weight']}")
print("unknowns:", ", ".join(f"{p} in {s['bounds']}" for p, s in case.raw["unknowns"].items()))
print("evidence:")
for e in case.raw["evidence"]:
    print(f"  {e['quantity']:30} {e['value']:>12} +- {e['sigma']}")
TRUTH = {"vehicles[0].speed": 30.8 * U.MPH, "vehicles[1].speed": 37.6 * U.MPH, "contact.restitution": 0.16,
         "contact.friction": 0.25, "contact.point[0]": -0.37 * U.FT, "contact.point[1]": -2.13 * U.FT}

# %% [markdown]
# ## The best fit
#
# `fit.reconstruct` with its defaults: starts spread over the bounds, more rounds of starts until two of them
# agree on the best cost.

# %%
res = fit.reconstruct(case)
unit = {"vehicles[0].speed": (U.MPH, "mph"), "vehicles[1].speed": (U.MPH, "mph"), "contact.restitution": (1.0, ""),
        "contact.friction": (1.0, ""), "contact.point[0]": (U.FT, "ft"), "contact.point[1]": (U.FT, "ft")}
laplace_sd = {p: float(np.sqrt(res.covariance[i, i])) for i, p in enumerate(res.estimate)}
print(f"chi^2 = {res.chi2:.2f} for {len(res.evidence)} evidence and {len(res.unknowns)} unknowns;"
      f" {res.starts_at_best} of {res.starts} starts reached it")
print(f"{'':20}{'estimate':>10}{'Laplace sd':>12}{'truth':>9}")
for p, x in res.estimate.items():
    u, name = unit[p]
    print(f"{p:20}{x / u:10.3f}{laplace_sd[p] / u:12.3f}{TRUTH[p] / u:9.3f} {name}")
print()
print(*res.unidentified, sep="\n")

# %% [markdown]
# The best fit **slides**, with a friction of 0.023. Its linearisation gives that friction a standard error of
# 0.008: read as a Gaussian, the friction would be 0.023 +/- 0.016 at 95%, some 28 standard errors from the truth
# (0.25), and a contact of crumpling sheet metal with almost no grip. The fit does not report that standard error: it
# says the friction is bounded below only, because from 0.032 on the contact would stick and every friction above
# gives the same exchange. What it cannot say is how likely each answer is, nor what the speeds are if the
# contact stuck.
#
# ## The evidence along the friction
#
# Hold the friction at values from 0.005 to 1.5 and fit the other five unknowns at each: a prior on the friction
# with a sigma of 1e-4 of its value holds it there, and the fit is the one compiled above. The evidence's
# chi^2 of each fit (the prior's term left out) is the evidence's own verdict on that friction:

# %%
frictions = np.geomspace(0.005, 1.5, 25)


def held_at(mu):
    """The case's unknowns with the friction held at mu by a prior of a tiny sigma."""
    unknowns = dict(case.raw["unknowns"])
    unknowns["contact.friction"] = {"bounds": [0, 1.5], "prior": {"mean": mu, "sigma": 1e-4 * mu}}
    return unknowns


profile = np.array([sum(r * r for r in fit.reconstruct(case, held_at(mu)).residuals.values()) for mu in frictions])
threshold = 0.0324  # where the best fit's contact would stick (the fit's note above)

fig, ax = plt.subplots(figsize=(6.5, 3.4))
ax.semilogx(frictions, profile, "o-", color="0.3", ms=4, label="best chi^2 with the friction fixed")
ax.plot(res.estimate["contact.friction"], res.chi2, "D", color="C3", label="the best fit (slides)")
ax.axvspan(threshold, 1.5, color="C0", alpha=0.12, label="the contact sticks")
ax.axvline(TRUTH["contact.friction"], color="C2", ls="--", label="truth (0.25)")
ax.set_xlabel("friction at the centroid")
ax.set_ylabel("chi^2")
ax.set_ylim(res.chi2 - 0.5, res.chi2 + 5)
ax.legend(fontsize=9, loc="upper right")
print(f"best chi^2 sliding {profile.min():.2f}, sticking {profile[frictions > threshold].min():.2f}"
      f" (every friction above {threshold} alike)")

# %% [markdown]
# The sliding dip is narrow (frictions of about 0.017 to 0.03) and only about 0.5 of chi^2 below the sticking
# plateau, which runs unchanged from 0.032 to the bound of 1.5. A difference of 0.5 in chi^2 is a likelihood ratio
# of exp(0.25) = 1.3: at each of its points the evidence prefers the dip a little, but the plateau is a hundred
# times wider. Which answer is more probable is a question of that width, which the best fit and its Gaussian
# cannot see.
#
# ## The posterior
#
# `fit.reconstruct(case, posterior=1000)` (`ks-jax fit fit_stick_or_slide.json --posterior 1000` on the
# command line) draws 4 chains of 1000 by NUTS, each after 1000 adaptation steps, from the posterior: the
# evidence's likelihood through the smooth engine, with uniform priors within the bounds. Each draw is then
# solved again to see whether its contact slides.

# %%
post_res = fit.reconstruct(case, posterior=1000, seed=3)
post = post_res.posterior
draws = post.samples.reshape(-1, len(post.paths))
column = {p: draws[:, j] for j, p in enumerate(post.paths)}
sliding = np.asarray(ks_jax.sweep(case, column, outputs=["contact.sliding"], mode="zip")["contact.sliding"], bool)
print(f"{post.chains} chains x {post.draws} draws, {post.divergences} divergent; warnings: {post.warnings or 'none'}")
print(f"the contact slides in {sliding.mean():.1%} of the draws and sticks in {1 - sliding.mean():.1%}\n")
print(f"{'':20}{'mean':>9}{'sd':>8}{'2.5%':>9}{'97.5%':>9}{'R-hat':>7}    Laplace: estimate, sd")
for p, s in post.summary.items():
    u, name = unit[p]
    print(f"{p:20}{s['mean'] / u:9.3f}{s['std'] / u:8.3f}{s['q025'] / u:9.3f}{s['q975'] / u:9.3f}{s['rhat']:7.3f}"
          f"    {res.estimate[p] / u:9.3f} {laplace_sd[p] / u:6.3f} {name}")

# %% [markdown]
# The two answers side by side: the friction's draws, split into those whose contact slides and those whose
# contact sticks, with the Laplace Gaussian of the best fit (its linearisation's standard error); the same for
# the first 0.1 of friction, closer; and the sedan's speed, the same way.

# %%
# the best fit's Gaussian in friction: the linearisation's standard error, which the fit's note states
note = next(t for t in res.unidentified if t.startswith("contact.friction"))
mu, sd = res.estimate["contact.friction"], float(re.search(r"\+/- ([0-9.e-]+) by the linearisation", note).group(1))
gauss = lambda x, m, s: np.exp(-0.5 * ((x - m) / s) ** 2) / (s * np.sqrt(2 * np.pi))
f = column["contact.friction"]
each = np.full(len(f), 1.0 / len(f))  # each draw's share of the probability


def split(ax, x, bins):
    """The draws x as a density (of all the draws, not only those in the bins), slide and stick stacked."""
    w = each / np.diff(bins)[0]
    ax.hist([x[sliding], x[~sliding]], bins=bins, weights=[w[sliding], w[~sliding]], stacked=True,
            color=["C3", "C0"], label=["draws that slide", "draws that stick"])


fig, (a, z, b) = plt.subplots(1, 3, figsize=(10, 3.2))
split(a, f, np.linspace(0, 1.5, 151))
split(z, f, np.linspace(0, 0.1, 41))
for ax in (a, z):
    grid = np.linspace(*ax.get_xlim(), 600)
    ax.plot(grid, gauss(grid, mu, sd), color="k", lw=1, label="Laplace (best fit)")
    ax.axvline(threshold, color="0.5", ls=":", label="sticks from here")
    ax.set_ylim(0, 4)
    ax.set_xlabel("friction at the centroid")
a.axvline(TRUTH["contact.friction"], color="C2", ls="--", label="truth")
a.set_ylabel("probability density")
a.annotate(f"Laplace: a peak of {gauss(mu, mu, sd):.0f} at {mu:.3f}", (mu, 4), xytext=(0.25, 3.4), fontsize=9,
           arrowprops=dict(arrowstyle="->", lw=0.7))
a.legend(fontsize=8.5, loc="center right")
z.set_title("the first 0.1 of it", fontsize=9)
v = column["vehicles[1].speed"] / U.MPH
split(b, v, np.linspace(v.min(), v.max(), 40))
g = np.linspace(v.min() - 0.5, v.max() + 0.5, 200)
b.plot(g, gauss(g, res.estimate["vehicles[1].speed"] / U.MPH, laplace_sd["vehicles[1].speed"] / U.MPH),
       color="k", lw=1, label="Laplace (best fit)")
b.axvline(TRUTH["vehicles[1].speed"] / U.MPH, color="C2", ls="--", label="truth")
b.set_xlabel(f"{case.vehicle_names[1]}'s speed at impact (mph)")
b.set_yticks([])
b.legend(fontsize=8.5)
fig.tight_layout()

# %% [markdown]
# Every unknown at once: the corner plot of the draws (each pair's scatter, each unknown's histogram), with the
# Laplace approximation of the best fit over them (its estimate and 1- and 2-sigma ellipses). `ks-jax fit
# --posterior 1000 --plot fit.png` writes the same picture beside the top view, as `fit_posterior.png`.

# %%
paths = post.paths
scale = np.array([unit[p][0] for p in paths])
labels = [f"{p} [{unit[p][1]}]" if unit[p][1] else p for p in paths]
fig = plt.figure(figsize=(6, 6))
corner(fig, draws / scale, labels, np.array([res.estimate[p] for p in paths]) / scale,
       np.asarray(res.covariance) / np.outer(scale, scale))
fig.suptitle("posterior draws and the Laplace approximation (none for the friction: not determined)");

# %% [markdown]
# ## What to take from it
#
# - **Both answers are in the posterior.** Nearly all of its probability sticks, spread evenly over every friction
#   from the threshold to the bound: the evidence says the friction was high enough to stick, and nothing more.
#   A few percent slide, in the narrow dip of the best fit. How many is a rough figure: the chains start at the
#   sliding best fit and cross between the dip and the plateau seldom, so the share moves from run to run (0.6% to
#   5% of the draws over six seeds of 4 chains x 1000, 1.2% to 1.7% over five of 16 chains x 500). Either way
#   sticking is some 20 to 100 times as probable as sliding.
# - **The best fit is the less probable answer, and Laplace describes only it.** Its Gaussian puts all the
#   probability on sliding with a friction of 0.02 (a value no investigator would accept for two crushing
#   vehicles), and its speeds' standard errors carry the sliding answer's trade of friction against speed. The
#   posterior's speeds, nearly all of them sticking, sit a few tenths of a mile an hour from the best fit's and
#   spread less (the SUV's by about a third), because a sticking exchange does not depend on the friction.
# - **Against the truth**: the posterior's 95% intervals hold the true speeds and restitution (the sedan's near its
#   upper end) and the truth's friction lies on the sticking plateau, where the best fit's Gaussian gives it no
#   chance at all. Neither puts the centroid's y where it was: the sedan's crush was measured 3.3 sigma deeper
#   than the truth's (8.4 in against 5.1 in; an error of that size comes once in a thousand measurements), and
#   a deeper centroid explains it. That error is also much of why the best fit slides: no method recovers
#   what the evidence's errors moved, but the posterior says how far they could have moved it.
# - **What to report**: the posterior's quantiles of the speeds, and for the friction "above about 0.03; the
#   contact most probably stuck".
# - **Check the diagnostics.** The sampler has to cross between a narrow dip and a wide plateau. R-hat, the
#   effective sample size and the divergences say whether the chains agree and how rough the tails are; here
#   they raise no warning (other seeds warn of an effective sample size below 100 per chain for the SUV's
#   speed). Where `post.warnings` is not empty, draw more (`posterior=4000`) or run more chains before reading
#   the tails, and read a small mode's share as rough in any case.
