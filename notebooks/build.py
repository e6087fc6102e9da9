"""Build the notebooks from the cell sources below, execute each on a fresh kernel and write it with its outputs.

    python notebooks/build.py                            # every notebook
    python notebooks/build.py 02_parameter_sweeps.ipynb  # only those named
    python notebooks/build.py --no-execute               # without outputs

The notebooks are shipped executed, so that a reader browsing the repository sees the figures. A notebook
whose run fails is not written: the command names the notebook, the cell and the error, and exits with 1.
"""

import argparse
import re
import sys
import time
from pathlib import Path

import nbclient
import nbformat
from nbclient.exceptions import CellExecutionError, CellTimeoutError, DeadKernelError

HERE = Path(__file__).parent
NOTEBOOKS = {}

# The kernel's options: figures inline as PNG at 110 dpi, so that legends and tick labels (8-9 pt) read at
# 12-14 pixels, and only its errors on the log (its start-up warning about unencrypted local TCP is noise in
# the command's progress). A notebook's column is about 1000-1400 pixels wide and shows a wider image scaled
# down, text and all: figures are at most 13 inches wide (11-12 for most), and the colour maps' PNGs stay
# under tests/test_notebooks.py's limit (notebook 02's three maps, the largest, about 140 KB).
KERNEL_ARGUMENTS = ["--InlineBackend.rc={'figure.dpi': 110}", "--log-level=ERROR"]
CELL_TIMEOUT = 600  # seconds


def notebook(name):
    def register(fn):
        NOTEBOOKS[name] = fn
        return fn

    return register


def cells(*items):
    out = []
    for kind, src in items:
        src = src.strip("\n")
        out.append(nbformat.v4.new_markdown_cell(src) if kind == "md" else nbformat.v4.new_code_cell(src))
    return out


@notebook("01_reading_ks_impulse_data.ipynb")
def reading():
    return cells(
        ("md", """
# Reading Kudlich-Slibar impulse data

The two Virtual CRASH manual chapters on KS impulse data, "Reading Collision Data" and "Reading
Kudlich-Slibar Impulse Data", each stage an inline rear impact and read the auto-ees panel: impulse, deformation energy, delta-V, crush and EES. Here both are solved with ks-jax from
the case files shipped in the package, and the impulse, energy, delta-V and EES are rebuilt by hand beside the
manual's, step by step. (The crushes are not a check: the "Reading Collision Data" case's dimensions were chosen so that
the box-to-centroid distances are the manual's deformations, and the hand EES below uses those crushes.)
"""),
        ("code", """
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
"""),
        ("md", """
## Reading Collision Data: Pontiac Grand Prix into a Saturn L300

Saturn (vehicle 1) 3183.475 lbf at 5 mph; Pontiac (vehicle 2) 3496.531 lbf at 21 mph; restitution 0.1;
centroid at CG height on the line of the CGs, so no rotation and the collision is one-dimensional:

- reduced mass m = m1 m2 / (m1 + m2)
- impulse J = (1 + eps) m |u.n|
- energy loss E = (1 - eps^2) m (u.n)^2 / 2
- delta-V_i = J / m_i
- EES (Burg): EES_2 = sqrt(2 E / (m2 (1 + C1/C2))), EES_1 = EES_2 sqrt(m2 C1 / (m1 C2))
"""),
        ("code", """
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
"""),
        ("md", "The auto-ees style panel, with the manual's panel values at the bottom:"),
        ("code", "print(text_report(sol0))"),
        ("md", """
## Reading Kudlich-Slibar Impulse Data: Kia K5 into a Lucid Air

Lucid (vehicle 1) 155.75 slug at 5 mph; Kia (vehicle 2) 100.38 slug at 20 mph; restitution 0.1.
The closing speed is exactly 22 ft/s (15 mph) and the reduced mass 61.04 slug to four digits, so the impulse
is 1.1 x 61.04 x 22 = 1477.17 lbf s; the chapter prints 1477.21 lbf s, and beside it 6571.96 N s, which is
1477.44 lbf s. Its kinetic energies carry the same slips in the last digits (14624.38 ft lbf against
14623.97 by hand). The hand column here is exact arithmetic, and ks-jax agrees with it.
"""),
        ("code", """
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
"""),
        ("code", "print(text_report(sol1))"),
        ("md", """
## The picture

The top view: both outlines, the centroid, the contact plane, the normal, the impulse on each vehicle, the
friction cone and the velocities before and after.
"""),
        ("code", """
import matplotlib.pyplot as plt
from ks_jax.plot import top_view

fig, axes = plt.subplots(1, 2, figsize=(11, 6.5))
top_view(sol0, ax=axes[0])
top_view(sol1, ax=axes[1])
fig.tight_layout()
"""),
    )



@notebook("02_parameter_sweeps.ipynb")
def sweeps():
    return cells(
        ("md", """
# Parameter sweeps

A reconstruction rarely has one set of inputs: speeds, restitution, friction and the impulse centroid are known
only within ranges. `ks_jax.sweep` solves one case at every point of a grid of some of its inputs in one
compiled, vectorised call and hands back only the results asked for. This notebook shows

1. delta-V and deformation energy over the bullet vehicle's speed and the restitution (the Virtual CRASH
   manual's "Reading Kudlich-Slibar Impulse Data": Kia K5 into the rear of a Lucid Air), as maps;
2. where an oblique contact sticks and where it slides, over friction and the position of the impulse centroid;
3. a million-point sweep, timed.

Sweep values are SI (m/s, m, rad); the plots convert to mph and ft.
"""),
        ("code", """
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
"""),
        ("md", """
## 1. Delta-V and energy over bullet speed x restitution

The Lucid Air (vehicle 1) is struck at 5 mph; the Kia's speed runs from 6 to 60 mph and the restitution
from 0 to 0.5. The grid is 109 x 51 points.
"""),
        ("code", """
kia_speed = np.linspace(6, 60, 109) * U.MPH          # m/s
restitution = np.linspace(0, 0.5, 51)
r = sweep(lucid_case,
          over={"vehicles[1].speed": kia_speed, "contact.restitution": restitution},
          outputs=["vehicles[0].delta_v_magnitude", "vehicles[1].delta_v_magnitude", "contact.energy_loss"])
print(r.shape, r.status_counts, f"solved in {r.seconds:.2f} s after compiling in {r.compile_seconds:.2f} s")
"""),
        ("code", """
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
"""),
        ("md", """
What the maps say:

- **delta-V** grows linearly with the closing speed (Kia speed minus the Lucid's 5 mph) and with (1 + eps):
  delta-V_i = (1 + eps) m_red (v_2 - v_1) / m_i. The lighter Kia always gets the larger delta-V
  (m_1 / m_2 = 1.55 times the Lucid's).
- The red line in the first map holds every (speed, restitution) pair that gives the manual's 6.47 mph
  delta-V of the Lucid: 20 mph at eps = 0.1, but also about 18.8 mph at eps = 0.2 or 21.5 mph at eps = 0. A delta-V alone
  fixes only (1 + eps) times the closing speed; the restitution has to come from elsewhere (crash tests,
  post-impact separation). Notebook 03 shows the fit saying exactly this.
- **Deformation energy** E = (1 - eps^2) m_red u^2 / 2 grows with the square of the closing speed and
  *falls* with restitution: the more elastic the contact, the less energy goes into crush.
"""),
        ("md", """
## 2. Stick or slide: friction x centroid position on an oblique contact

An angled side impact: a sedan (vehicle 1) crossing at 15 mph is struck on its right side by a pickup
(vehicle 2) travelling at 30 mph on a heading of 110 deg, so the pickup also moves against the sedan's
direction. The contact plane is the sedan's right side (normal azimuth 90 deg, from the pickup into the
sedan). The impulse centroid is moved along that side, from 8 ft behind to 6 ft ahead of the sedan's CG
(`contact.point[0]`), and the friction limit mu from 0 to 1.

The KS model first computes the stick impulse (the one that brings the relative velocity at the centroid
to zero) with tangential part |T_c| and normal part N_c. If mu >= |T_c| / N_c the friction can supply it and
the contact **sticks**; otherwise the contact **slides**: the tangential impulse is capped at mu times the
normal one (`contact.sliding` is True).
"""),
        ("code", """
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
"""),
        ("code", """
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
"""),
        ("md", """
Reading the maps:

- Below the black line the friction cannot supply the stick impulse: the vehicles **slide** along the contact
  plane through the exchange, and the tangential impulse is exactly mu times the normal one. Above it they
  reach a common velocity at the centroid (**stick**, full "common velocity" KS exchange).
- The friction needed to stick is least (about 0.49) with the centroid about 1.5 ft ahead of the sedan's CG,
  and rises towards the ends of the side: an off-centre impulse also spins the vehicles, the point of contact
  then keeps moving along the plane, and more tangential impulse is needed to stop it there. Behind about
  -4.5 ft even mu = 1 is not enough: those contacts always slide.
- In the stick region the delta-V contours are vertical: friction no longer matters, only where the centroid is.
  In the slide region they bend: the delta-V depends on the friction value chosen. So where the
  reconstruction sits relative to the black line decides whether the friction is worth arguing about (and a fit
  cannot determine friction from a contact that sticks).
"""),
        ("md", """
## 3. A million points, timed

The same rear impact over a 1000 x 1000 grid of Kia speed and restitution: 10^6 exchanges. Compilation happens
once per combination of swept paths, outputs, grid shape and chunk size, so the warm-up solves only the first
65536 points (four chunks of 16384) of the same grid; the timed call then runs without compiling.
"""),
        ("code", """
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
"""),
        ("md", """
Each point is a full three-dimensional KS exchange with all the section-4 results; only the two requested
outputs (and a status byte per point) come back to the host. For sweeps much larger than memory, pass
`on_chunk=` and `keep=False` (docs/sweeps.md).

For a first look without writing the plotting by hand, `ks_jax.plot.sweep_view` draws any output of a sweep in
the units asked for (`units="si"` or `"us"`, here US), with the vehicles' names beside the paths: a map over two
swept inputs (as here), a line over one, a histogram of `mode="zip"` samples.
From the shell, `ks-jax sweep ... --plot grid.png` draws the same pictures beside the results file.
"""),
        ("code", """
from ks_jax import plot

fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
for ax, path in zip(axes, outs):
    plot.sweep_view(rb, path, ax, units="us")
fig.tight_layout()
"""),
    )


@notebook("03_reconstruction.ipynb")
def reconstruction():
    return cells(
        ("md", """
# Reconstruction: from evidence to pre-impact speeds

The reverse problem. An intersection collision: an SUV strikes the right front of a crossing sedan at an angle.
The scene and the vehicles give

- the sedan's **EDR** (airbag control module) longitudinal and lateral delta-V,
- the sedan's **crush** depth, which places the impulse centroid,
- the **post-impact speeds** and **departure angles** of both vehicles (from their rest positions, the
  post-impact trajectories and drag factors).

`fit.reconstruct` finds the pre-impact speeds, the restitution, the friction limit and the centroid depth
that reproduce this evidence, by weighted least squares through the model's gradients, with standard errors,
a Monte Carlo check, and a plain statement of anything the evidence cannot determine.

Here the evidence is synthetic: the case is solved with "true" inputs, and the results are measured with
stated random errors, so that the fit can be compared with the truth.
"""),
        ("code", """
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import matplotlib.pyplot as plt

import ks_jax
import fit
from ks_jax import units as U
from ks_jax.case import case_from_dict
from ks_jax.plot import top_view
"""),
        ("md", """
## The case, in the units of the trade

Vehicle 1 is the sedan heading east (yaw 0) at 28 mph; vehicle 2 is the SUV on a heading of 115 deg at 38 mph.
The user contact puts the impulse centroid 2.5 ft ahead of the sedan's CG, 1.05 ft inside its right side,
with the contact plane along that side (normal azimuth 90 deg, from the SUV into the sedan).
These are the "true" values the fit will have to find.
"""),
        ("code", """
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
"""),
        ("md", """
The top view: the sedan (blue) and the SUV (orange) at the exchange, the centroid, the contact plane (red line)
and normal, the friction cone, the impulse, and each vehicle's velocity before (dotted) and after (solid).
The contact **slides** (the impulse lies on the edge of the friction cone), so the friction limit matters.

## The evidence

Each measurement is the true result plus a random error drawn with the stated sigma (a fixed seed, so the
notebook is reproducible): EDR delta-V to 1 mph, crush to 0.15 ft, post-impact speeds to 2 mph, departure
angles to 4 deg.
"""),
        ("code", """
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
"""),
        ("md", """
## The fit

Five unknowns with their plausible ranges, written as in a case file: both pre-impact speeds, the
restitution, the friction limit, and the centroid's lateral position `contact.point[1]` (how deep into the
sedan's side it lies; the sedan's right side is at y = -3.05 ft). The fit runs eight starts spread over
these ranges and keeps the best; `monte_carlo=200` then refits 200 copies of the evidence, each perturbed by
its sigmas.
"""),
        ("code", """
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
print(f"\\n{'unknown':22}{'estimate':>10}{'+-':>3}{'std':>7}{'true':>9}  {'(est - true) / std':>20}")
for p, (unit, uname) in show.items():
    est, sd = fr.estimate[p], fr.std[p]
    print(f"{p:22}{est / unit:10.2f}{'+-':>3}{sd / unit:7.2f}{true_value[p] / unit:9.2f}"
          f"  {(est - true_value[p]) / sd:20.2f}  {uname}")
"""),
        ("md", """
The speeds come back within about one standard error of the truth, to about +-2 mph (1 sigma). The last column
is how many standard errors each estimate is from the truth: with honest error bars it should rarely exceed 2.

Correlations tell which unknowns trade off against each other:
"""),
        ("code", """
names = list(show)
print(" " * 22 + "".join(f"{n.split('.')[-1][:11]:>12}" for n in names))
for a in names:
    print(f"{a:22}" + "".join(f"{fr.correlation[a][b]:12.2f}" for b in names))
"""),
        ("md", """
## Residuals

How far the fitted model is from each measurement, in units of its sigma. Values within +-2 are what random
error produces; a larger one would point at a bad measurement or a wrong assumption in the case (a
centroid in the wrong place, a wrong mass).
"""),
        ("code", """
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
"""),
        ("md", """
## Monte Carlo against the Laplace standard errors

The standard errors above come from the curvature of the least-squares cost at the optimum (the Laplace, or
Gauss-Newton, approximation). The Monte Carlo refits show the actual spread of the estimates when the evidence
is perturbed by its sigmas. The histograms are the 200 refits; the curve is the normal distribution with the
Laplace standard error about the estimate; the dashed line is the truth.
"""),
        ("code", """
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
"""),
        ("md", """
Here the histograms and the curves agree (the titles compare the two standard deviations): the model is close
to linear over the uncertainty, and the Laplace standard errors can be quoted as they are. Where a histogram is
skewed or cut off at a bound (a restitution near 0, say, or a contact on the edge of sticking), the 5/50/95
percentiles in `fr.monte_carlo["percentiles"]` are the better summary:
"""),
        ("code", """
for q in ("5", "50", "95"):
    row = fr.monte_carlo["percentiles"][q]
    print(f"{q:>3}%: " + ", ".join(f"{p.split('.')[-1]} {row[p] / show[p][0]:.2f} {show[p][1]}" for p in names))
"""),
        ("md", """
## When the evidence cannot determine a speed

Now suppose only the EDR is available: the sedan's longitudinal and lateral delta-V, and nothing from the scene
after the impact. The unknowns are both speeds and the restitution (friction and centroid taken as known).

First a picture: the SUV's speed against the restitution, coloured by the sedan's lateral delta-V. The red line
is every pair that reproduces the measured lateral delta-V.
"""),
        ("code", """
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
"""),
        ("code", """
edr_only = evidence[:2]                  # EDR longitudinal and lateral delta-V of the sedan
unknowns_edr = {k: unknowns[k] for k in ("vehicles[0].speed", "vehicles[1].speed", "contact.restitution")}
fu = fit.reconstruct(case, unknowns_edr, edr_only)
for p in unknowns_edr:
    unit, uname = show[p]
    print(f"{p:22} estimate {fu.estimate[p] / unit:8.2f} {uname:4} std {fu.std[p] / unit:10.3g}")
print("\\nunidentified:")
for line in fu.unidentified:
    print(" -", line)
"""),
        ("md", """
The fit still returns numbers (any point of the valley reproduces the evidence), but it gives them no usable
error bar: the standard errors of the SUV's speed and of the restitution are infinite, the sedan's is hundreds
of mph, and `unidentified` says why, in words:

- **SUV speed and restitution**: the contact slides, so the impulse is set by the normal closing speed times
  (1 + eps); the SUV's speed and the restitution trade off along the red line above. The delta-V fixes only
  their combination.
- **Sedan speed** (which even ends at its bound of 0 mph, and `fu.at_bound` says so; the restitution ends
  wherever the starts led along the red line, here about 0.27): the sedan moves along the contact plane. In a sliding contact the
  tangential impulse is mu times the normal one whatever the sliding speed, so its speed hardly changes the
  delta-V at all: the evidence leaves it practically free ("poorly determined").

This is why the first fit needed the post-impact speeds and directions: they measure where the momentum went,
which fixes the closing speed and the restitution separately. Without them, the restitution (or a speed) has to
be given, and the report should say it was assumed.
"""),
    )


@notebook("04_automatic_contact.ipynb")
def automatic_contact():
    return cells(
        ("md", """
# Automatic contact: first contact and depth of penetration

With automatic contact (no `point` and no `normal` in the case) ks-jax moves the vehicles freely from their
case positions until their outlines first touch (time t_i), lets them run on for the **penetration time**
dt_p, and exchanges the impulse there: at the centroid of the overlap of the two outlines, across the contact
plane through the two points where the outlines cross. This is the Virtual CRASH "auto-position" and
"depth of penetration".

The penetration time is a modelling choice, and this notebook shows how much the results move with it for
the shipped T-bone case (`auto_tbone.json`): a pickup at 30 mph into the right side of a sedan crossing at
15 mph.
"""),
        ("code", """
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
"""),
        ("md", "One sweep over `contact.penetration_time`, from 0 (the exchange at the instant of first touch) to 0.15 s:"),
        ("code", """
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
"""),
        ("code", """
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
"""),
        ("md", """
What moves, and why (the grey line is the file's 50 ms):

- **First contact** does not depend on dt_p: t_i is fixed by the starting positions and speeds.
- Up to about 78 ms the pickup's front sinks into the sedan's right side and the overlap is a rectangle that
  deepens (30 mph is 0.53 in per ms): the centroid moves into the sedan (centroid y rises) while its x stays on
  the pickup's centre line, the normal stays across the sedan's side (90 deg), and each vehicle's **crush**
  (centroid to that vehicle's undeformed outline, along the normal) is half the depth: the two crush curves
  coincide. The file's 50 ms puts the centroid about 1.1 ft into each vehicle.
- **delta-V** and energy fall slowly over the same range: the closing speed along the normal stays 30 mph,
  but the sedan keeps moving forward, so the pickup's front is further and further behind the sedan's CG.
  With a longer lever arm the sedan yields more by rotating, its effective mass at the centroid drops, and the
  impulse is smaller.
- At about 78 ms the sedan's rear corner passes the pickup's left side (compare the top views below). The
  outlines now cross on the sedan's rear face and on the pickup's side, each vehicle with a corner inside the
  other: the line through the crossings is only the overlap's diagonal, so the normal is the axis the faces
  first touched along, still across the sedan's side (90 deg; docs/model.md, "Automatic contact"). With the
  lever arm still growing, the contact starts to slide (orange) at about 94 ms, and delta-V and energy go on
  falling smoothly. From about 136 ms the pickup's front has gone through the sedan's whole width: the outlines
  cross in four points, the normal falls back to the axis of least penetration, now along the sedan, and
  the vehicles are not approaching along it: no exchange at all (grey). A staging that deep is past what the
  footprints can say; give `contact.normal`.
- At dt_p = 0 the exchange is at the instant of touching: the overlap has no area and there is no crush, so
  EES (which shares the energy by crush) is not drawn there.

The lesson for a reconstruction: the penetration time should put the centroid where the crush says it is
(compare the crush curve with the measured crush depth), and results near a change of character (stick to
slide, an exchange to none) deserve a second look at the staging.
"""),
        ("md", """
## Two penetration times side by side

Top views at 20 ms and 100 ms: the outlines at first contact (dashed) and at the exchange (solid), the overlap
(grey), the centroid, the contact plane (red) and the impulses.
"""),
        ("code", """
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
"""),
    )


@notebook("05_rest_positions.ipynb")
def rest_positions():
    return cells(
        ("md", """
# From measured rest positions to pre-impact speeds

Where two vehicles came to rest is often the best evidence a scene keeps. With a `road` in the case, ks-jax
carries each vehicle on from the collision to rest (tyre forces on each wheel, braked or free, on a road of a
given friction), so a rest position is a result like any other, and `fit.reconstruct` can work back from it to
the speeds at impact.

The shipped case `fit_rest_positions.json` is a T-bone: a sedan (vehicle 1) crosses heading +x, a pickup
(vehicle 2) heading +y strikes its right side. After the impact the sedan's driver has the front brakes half on,
the pickup's driver locks all four wheels; the road's friction is 0.75. Both speeds are unknown. The evidence
is the two rest positions (measured to a foot) and the crush of each vehicle. The rest positions were made from
speeds of 25 mph (sedan) and 35 mph (pickup), so the fit can be checked against them.

The notebook fits the speeds, draws the collision and both paths to rest at the estimate, and then shows what
rest positions alone cannot tell apart: the road's friction and the speeds.
"""),
        ("code", """
import dataclasses
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
"""),
        ("md", """
## The case at its start values

Before fitting, the case is solved as written: the speeds in the file (20 and 30 mph) are only where the fit
starts. The top view shows the collision (outlines at the exchange, centroid, contact plane, impulse, velocities)
and each vehicle's path to rest: its CG's path, faded outlines at equal steps of time (they bunch up where it
slows), and its outline at rest. The measured rest positions are the x marks, each in a dashed circle of one
sigma (1 ft).
"""),
        ("code", """
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
"""),
        ("md", """
At 20 and 30 mph both vehicles come to rest well away from the marks (the sedan about 12 ft, the pickup about
7 ft), and the sedan turns through 60 deg where the scene has it at some 100 deg from its heading.

## The fit

`fit.reconstruct` reads the unknowns and the evidence from the case file, starts from eight points spread over
the bounds (5 to 60 mph for each speed) and moves both speeds until the solved rest positions and crush match
the measured ones as closely as their sigmas ask, by weighted least squares.
"""),
        ("code", """
res = fit.reconstruct(case)
print("converged:", res.converged, f"| chi^2 = {res.chi2:.4f} for {len(res.evidence)} evidence and",
      f"{len(res.unknowns)} unknowns | unidentified: {res.unidentified}")
print(f"\\n{'unknown':20}{'estimate':>10}{'+-':>4}{'std':>6}   true")
for path, true in (("vehicles[0].speed", 25.0), ("vehicles[1].speed", 35.0)):
    print(f"{path:20}{res.estimate[path] / U.MPH:10.2f}{'+-':>4}{res.std[path] / U.MPH:6.2f}  {true:5.1f} mph")
print(f"correlation of the two speeds: {res.correlation['vehicles[0].speed']['vehicles[1].speed']:+.2f}")
print()
for path, r in res.residuals.items():
    print(f"{path:30} measured {measured[path] / U.FT:6.2f} ft, fitted {res.fitted[path] / U.FT:6.2f} ft,"
          f" residual {r:+.2f} sigma")
"""),
        ("md", """
Both speeds come back at the speeds the rest positions were made from, with standard errors under 1 mph: a
foot of uncertainty in where a vehicle stopped is worth well under a mile an hour here, because the pickup
slides to rest over some 25 ft and the sedan over some 58 ft.

The case at the estimate: its unknowns set to the fitted speeds (`ks_jax.set_input`) and solved again. Its rest
outlines now sit on the measured marks. (`ks-jax fit fit_rest_positions.json --plot fit.png` draws the same
picture from the command line.)
"""),
        ("code", """
def at(case, values, name):
    \"\"\"The case with the inputs at ``values`` (path -> SI) and a new name.\"\"\"
    inputs = case.inputs
    for path, value in values.items():
        inputs = ks_jax.set_input(inputs, path, value)
    return dataclasses.replace(case, inputs=inputs, name=name)

best = ks_jax.solve(at(case, res.estimate, f"{case.name}\\nat the estimate: "
                        + ", ".join(f"{res.estimate[p] / U.MPH:.1f} mph" for p in res.estimate)))
report_rest(best)
ax = top_view(best, evidence=measured, sigma=sigma)
ax.figure.set_size_inches(7, 7.5)
"""),
        ("md", """
## What rest positions cannot tell apart: speed and drag

The fit above took the road's friction as known (0.75). In practice it is measured, looked up, or argued over.
How much do the rest positions say about it? Make it a third unknown, between 0.4 and 1.0, and fit again
with the same evidence:
"""),
        ("code", """
unknowns = dict(case.raw["unknowns"])
unknowns["road.friction"] = {"bounds": [0.4, 1.0]}
three = fit.reconstruct(case, unknowns)
paths = list(unknowns)
unit = {"vehicles[0].speed": (U.MPH, "mph"), "vehicles[1].speed": (U.MPH, "mph"), "road.friction": (1.0, "")}
print("converged:", three.converged, f"| chi^2 = {three.chi2:.4f}")
for p in paths:
    u, name = unit[p]
    print(f"{p:20}{three.estimate[p] / u:10.3f} +- {three.std[p] / u:.3f} {name}")
print("\\nunidentified:", three.unidentified)
print("\\ncorrelation:")
print(" " * 20 + "".join(f"{p:>20}" for p in paths))
for a in paths:
    print(f"{a:20}" + "".join(f"{three.correlation[a][b]:20.3f}" for b in paths))
"""),
        ("md", """
The fit still lands near the truth, but look at the numbers around it. The standard error of the friction is
about 0.19, as wide as knowing nothing beyond "somewhere between 0.4 and 1.0", and the fit says so in
`unidentified` ("poorly determined"). The speeds' standard errors grow from under 1 mph to 3 or 4 mph. The
correlations close to +1 say why: a higher friction with higher speeds puts the vehicles in nearly the same
places. A vehicle sliding to rest covers about v^2 / (2 mu g): the rest position fixes v^2 / mu much better
than v or mu. The two do not trade exactly, because the tyres' rolling resistance and cornering forces do not
scale with the friction, and that small difference is all the evidence has to go on.

The same trade seen directly: fix the friction at 0.6, 0.75 and 0.9 in turn and fit only the speeds. Each
friction gets its own speeds, and each matches the rest positions:
"""),
        ("code", """
frictions = (0.6, 0.75, 0.9)
fixed = [fit.reconstruct(at(case, {"road.friction": mu}, case.name)) for mu in frictions]
for mu, r in zip(frictions, fixed):
    worst = max(abs(r.residuals[p]) for p in r.residuals)
    print(f"friction {mu:4.2f}: sedan {r.estimate['vehicles[0].speed'] / U.MPH:5.1f} +- {r.std['vehicles[0].speed'] / U.MPH:4.2f} mph,"
          f" pickup {r.estimate['vehicles[1].speed'] / U.MPH:5.1f} +- {r.std['vehicles[1].speed'] / U.MPH:4.2f} mph;"
          f" chi^2 {r.chi2:5.2f}, largest residual {worst:.2f} sigma")
"""),
        ("md", """
A friction of 0.6 or 0.9 is no worse an explanation of the scene than 0.75, judged by the rest positions
alone, and each gives speeds several mph apart. Each fit's own standard errors (under 1 mph) hold only for
its friction: the friction's own uncertainty comes on top.

## What to do about it

For the reconstructionist, the friction belongs with the evidence, not with the unknowns fitted blind: a drag
factor from test skids at the scene, or a documented range for the surface, given as a prior (a mean and a
sigma). With a prior of 0.75 +- 0.05 the fit carries that uncertainty into the speeds honestly:
"""),
        ("code", """
with_prior = dict(unknowns)
with_prior["road.friction"] = {"bounds": [0.4, 1.0], "prior": {"mean": 0.75, "sigma": 0.05}}
known = fit.reconstruct(case, with_prior)
for p in paths:
    u, name = unit[p]
    print(f"{p:20}{known.estimate[p] / u:10.3f} +- {known.std[p] / u:.3f} {name}")
print("unidentified:", known.unidentified)
"""),
        ("md", """
The speeds are back within about 1 mph, and now that figure includes the uncertainty of the friction: 0.05 of
friction is worth about 1 mph here. In plain words:

- Rest positions measure how much speed the road took away, which is speed and drag together. They pin the
  speeds tightly only where the drag is known.
- A fit that leaves the friction free says so: a friction standard error as wide as its range, a note in
  `unidentified`, and correlations near 1 between the friction and the speeds.
- Other evidence that does not go through the road (an EDR's delta-V or pre-crash speed, crush energy) breaks
  the trade; without it, state the friction you assumed and carry its uncertainty, as the prior does.
"""),
    )



@notebook("06_stick_or_slide.ipynb")
def stick_or_slide():
    return cells(
        ("md", """
# Stick or slide: what the posterior says where the best fit misleads

In the KS model the tangential part of the impulse is limited by the friction at the impulse centroid. If the
friction is high enough to bring the two surfaces to a common velocity there, the contact **sticks**, and every
friction above that threshold gives the same exchange. If not, the contact **slides**, the impulse lies on the
edge of the friction cone, and the friction sets it. Evidence that fits a sticking contact therefore says only
"friction above some value", and a sliding contact with a friction just below the threshold can fit nearly as
well, or a little better where the measurements' errors happen to favour it.

A least-squares fit returns one point and a Gaussian about it (the Laplace approximation). When that point
slides just below the threshold, the Gaussian is all about the sliding answer. The posterior, drawn by NUTS
through the smooth engine, shows both answers and how much of the probability each holds.

The shipped case `fit_stick_or_slide.json` is an oblique side impact: a sedan's front into an SUV's right side.
Six unknowns (both speeds, restitution, friction, the centroid's x and y), ten evidence (both EDR delta-V
components, yaw rates and speeds after the impact, crush). The evidence was made from a sticking contact with
friction 0.25, with a random error of one sigma added to each measurement, so the answers can be checked.
"""),
        ("code", """
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
"""),
        ("md", """
## The best fit

`fit.reconstruct` with its defaults: starts spread over the bounds, more rounds of starts until two of them
agree on the best cost.
"""),
        ("code", """
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
print(*res.unidentified, sep="\\n")
"""),
        ("md", """
The best fit **slides**, with a friction of 0.023. Its linearisation gives that friction a standard error of
0.008: read as a Gaussian, the friction would be 0.023 +/- 0.016 at 95%, some 28 standard errors from the truth
(0.25), and a contact of crumpling sheet metal with almost no grip. The fit does not report that standard error: it
says the friction is bounded below only, because from 0.032 on the contact would stick and every friction above
gives the same exchange. What it cannot say is how likely each answer is, nor what the speeds are if the
contact stuck.

## The evidence along the friction

Hold the friction at values from 0.005 to 1.5 and fit the other five unknowns at each: a prior on the friction
with a sigma of 1e-4 of its value holds it there, and the fit is the one compiled above. The evidence's
chi^2 of each fit (the prior's term left out) is the evidence's own verdict on that friction:
"""),
        ("code", """
frictions = np.geomspace(0.005, 1.5, 25)


def held_at(mu):
    \"\"\"The case's unknowns with the friction held at mu by a prior of a tiny sigma.\"\"\"
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
"""),
        ("md", """
The sliding dip is narrow (frictions of about 0.017 to 0.03) and only about 0.5 of chi^2 below the sticking
plateau, which runs unchanged from 0.032 to the bound of 1.5. A difference of 0.5 in chi^2 is a likelihood ratio
of exp(0.25) = 1.3: at each of its points the evidence prefers the dip a little, but the plateau is a hundred
times wider. Which answer is more probable is a question of that width, which the best fit and its Gaussian
cannot see.

## The posterior

`fit.reconstruct(case, posterior=1000)` (`ks-jax fit fit_stick_or_slide.json --posterior 1000` on the
command line) draws 4 chains of 1000 by NUTS, each after 1000 adaptation steps, from the posterior: the
evidence's likelihood through the smooth engine, with uniform priors within the bounds. Each draw is then
solved again to see whether its contact slides.
"""),
        ("code", """
post_res = fit.reconstruct(case, posterior=1000, seed=3)
post = post_res.posterior
draws = post.samples.reshape(-1, len(post.paths))
column = {p: draws[:, j] for j, p in enumerate(post.paths)}
sliding = np.asarray(ks_jax.sweep(case, column, outputs=["contact.sliding"], mode="zip")["contact.sliding"], bool)
print(f"{post.chains} chains x {post.draws} draws, {post.divergences} divergent; warnings: {post.warnings or 'none'}")
print(f"the contact slides in {sliding.mean():.1%} of the draws and sticks in {1 - sliding.mean():.1%}\\n")
print(f"{'':20}{'mean':>9}{'sd':>8}{'2.5%':>9}{'97.5%':>9}{'R-hat':>7}    Laplace: estimate, sd")
for p, s in post.summary.items():
    u, name = unit[p]
    print(f"{p:20}{s['mean'] / u:9.3f}{s['std'] / u:8.3f}{s['q025'] / u:9.3f}{s['q975'] / u:9.3f}{s['rhat']:7.3f}"
          f"    {res.estimate[p] / u:9.3f} {laplace_sd[p] / u:6.3f} {name}")
"""),
        ("md", """
The two answers side by side: the friction's draws, split into those whose contact slides and those whose
contact sticks, with the Laplace Gaussian of the best fit (its linearisation's standard error); the same for
the first 0.1 of friction, closer; and the sedan's speed, the same way.
"""),
        ("code", """
# the best fit's Gaussian in friction: the linearisation's standard error, which the fit's note states
note = next(t for t in res.unidentified if t.startswith("contact.friction"))
mu, sd = res.estimate["contact.friction"], float(re.search(r"\\+/- ([0-9.e-]+) by the linearisation", note).group(1))
gauss = lambda x, m, s: np.exp(-0.5 * ((x - m) / s) ** 2) / (s * np.sqrt(2 * np.pi))
f = column["contact.friction"]
each = np.full(len(f), 1.0 / len(f))  # each draw's share of the probability


def split(ax, x, bins):
    \"\"\"The draws x as a density (of all the draws, not only those in the bins), slide and stick stacked.\"\"\"
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
"""),
        ("md", """
Every unknown at once: the corner plot of the draws (each pair's scatter, each unknown's histogram), with the
Laplace approximation of the best fit over them (its estimate and 1- and 2-sigma ellipses). `ks-jax fit
--posterior 1000 --plot fit.png` writes the same picture beside the top view, as `fit_posterior.png`.
"""),
        ("code", """
paths = post.paths
scale = np.array([unit[p][0] for p in paths])
labels = [f"{p} [{unit[p][1]}]" if unit[p][1] else p for p in paths]
fig = plt.figure(figsize=(6, 6))
corner(fig, draws / scale, labels, np.array([res.estimate[p] for p in paths]) / scale,
       np.asarray(res.covariance) / np.outer(scale, scale))
fig.suptitle("posterior draws and the Laplace approximation (none for the friction: not determined)");
"""),
        ("md", """
## What to take from it

- **Both answers are in the posterior.** Nearly all of its probability sticks, spread evenly over every friction
  from the threshold to the bound: the evidence says the friction was high enough to stick, and nothing more.
  A few percent slide, in the narrow dip of the best fit. How many is a rough figure: the chains start at the
  sliding best fit and cross between the dip and the plateau seldom, so the share moves from run to run (0.6% to
  5% of the draws over six seeds of 4 chains x 1000, 1.2% to 1.7% over five of 16 chains x 500). Either way
  sticking is some 20 to 100 times as probable as sliding.
- **The best fit is the less probable answer, and Laplace describes only it.** Its Gaussian puts all the
  probability on sliding with a friction of 0.02 (a value no investigator would accept for two crushing
  vehicles), and its speeds' standard errors carry the sliding answer's trade of friction against speed. The
  posterior's speeds, nearly all of them sticking, sit a few tenths of a mile an hour from the best fit's and
  spread less (the SUV's by about a third), because a sticking exchange does not depend on the friction.
- **Against the truth**: the posterior's 95% intervals hold the true speeds and restitution (the sedan's near its
  upper end) and the truth's friction lies on the sticking plateau, where the best fit's Gaussian gives it no
  chance at all. Neither puts the centroid's y where it was: the sedan's crush was measured 3.3 sigma deeper
  than the truth's (8.4 in against 5.1 in; an error of that size comes once in a thousand measurements), and
  a deeper centroid explains it. That error is also much of why the best fit slides: no method recovers
  what the evidence's errors moved, but the posterior says how far they could have moved it.
- **What to report**: the posterior's quantiles of the speeds, and for the friction "above about 0.03; the
  contact most probably stuck".
- **Check the diagnostics.** The sampler has to cross between a narrow dip and a wide plateau. R-hat, the
  effective sample size and the divergences say whether the chains agree and how rough the tails are; here
  they raise no warning (other seeds warn of an effective sample size below 100 per chain for the SUV's
  speed). Where `post.warnings` is not empty, draw more (`posterior=4000`) or run more chains before reading
  the tails, and read a small mode's share as rough in any case.
"""),
    )

def build(name):
    """The notebook ``name`` (a file name of ``NOTEBOOKS``) as built from the cells above, without outputs."""
    nb = nbformat.v4.new_notebook()
    nb.cells = NOTEBOOKS[name]()
    for i, cell in enumerate(nb.cells):
        cell.id = f"{Path(name).stem[:2]}-{i:02d}"   # stable ids: a rebuild changes nothing it need not
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    return nb


class NotebookError(Exception):
    """A notebook's run failed: the message names the notebook, the cell (index into its cells) and the error."""


ANSI = re.compile(r"\x1b\[[0-9;]*m")  # the colours of IPython's tracebacks


def execute(nb, name):
    """Run ``nb`` (the notebook ``name``) top to bottom on a fresh ``python3`` kernel in notebooks/, in place,
    and tidy it (``tidy``). A failing cell raises ``NotebookError`` with that cell's own traceback only."""
    current = {}
    client = nbclient.NotebookClient(
        nb, timeout=CELL_TIMEOUT, kernel_name="python3", extra_arguments=KERNEL_ARGUMENTS,
        record_timing=False, resources={"metadata": {"path": str(HERE)}},
        on_cell_start=lambda cell, cell_index: current.update(index=cell_index))
    try:
        client.execute()
    except CellExecutionError as e:
        i = current["index"]
        tb = next(("\n".join(o.traceback) for o in nb.cells[i].outputs if o.output_type == "error"), e.traceback)
        raise NotebookError(f"{name}: cell {i} failed: {e.ename}: {e.evalue}\n{ANSI.sub('', tb)}") from None
    except (CellTimeoutError, DeadKernelError) as e:
        raise NotebookError(f"{name}: cell {current.get('index')} failed: {type(e).__name__}: "
                            f"{str(e).splitlines()[0]}") from None
    tidy(nb)
    return nb


def tidy(nb):
    """Keep nothing in an executed notebook that changes from one run to the next but the outputs: execution
    counts 1..n (as on a fresh kernel, whatever ran it) and no Python patch version (the kernel's)."""
    count = 0
    for cell in nb.cells:
        if cell.cell_type == "code":
            count += 1
            cell.execution_count = count
            for out in cell.outputs:
                if out.output_type == "execute_result":
                    out.execution_count = count
    nb.metadata.get("language_info", {}).pop("version", None)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", metavar="NOTEBOOK",
                        help=f"notebooks to build (file names; default all): {', '.join(NOTEBOOKS)}")
    parser.add_argument("--no-execute", action="store_true", help="write the notebooks without outputs")
    args = parser.parse_args(argv)
    names = [Path(n).name for n in args.names] or list(NOTEBOOKS)
    unknown = [n for n in names if n not in NOTEBOOKS]
    if unknown:
        parser.error(f"no notebook {', '.join(unknown)}; there are {', '.join(NOTEBOOKS)}")
    failed = []
    for name in names:
        nb = build(name)
        if not args.no_execute:
            print(f"{name}: executing ...", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            try:
                execute(nb, name)
            except NotebookError as e:
                print(e, file=sys.stderr)
                print(f"{name}: not written", file=sys.stderr)
                failed.append(name)
                continue
            print(f"{name}: executed in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        nbformat.write(nb, HERE / name)
        print(f"wrote {HERE / name}", file=sys.stderr)
    if failed:
        sys.exit(f"failed: {', '.join(failed)}")


if __name__ == "__main__":
    main()
