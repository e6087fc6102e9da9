"""Draws the pictures of docs/model.md, "Automatic contact": the contact plane of an offset frontal, a
rear-end with partial overlap, a T-bone and a corner entering a side, each at its exchange instant as
automatic contact finds it (``ks_jax.model.contact.automatic_contact``): the footprints, their overlap,
the two points where the outlines cross and the line through them (dashed), the plane through the
centroid and the normal, from vehicle 2 into vehicle 1. Where the crossings lie on one side, that line is
the side, and the plane is parallel to it; where they lie on faces that face each other, it is the
overlap's diagonal, and the plane is across the axis of least penetration instead.

    python docs/pictures/draw.py          # writes the PNG files beside this script
"""

from __future__ import annotations

import math
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Polygon

import ks_jax
from ks_jax.model.contact import automatic_contact, footprint

HERE = Path(__file__).parent
COLORS = ("tab:blue", "tab:orange")


def vehicle(length, width, cg_to_front, mass=1500.0):
    return ks_jax.Vehicle.create(mass, jnp.array([500.0, 2500.0, 2700.0]), length, width, 1.4, cg_to_front, 0.55)


CAR1 = vehicle(4.6, 1.8, 2.1)
CAR2 = vehicle(4.8, 1.9, 2.6, mass=1800.0)


def state(xy, yaw_deg, speed):
    yaw = math.radians(yaw_deg)
    return ks_jax.State.create(list(xy), yaw, speed=speed, yaw_rate=0.0, cg_height=0.55)


def contact(penetration_time):
    return ks_jax.Contact.create(jnp.zeros(3), jnp.array([1.0, 0.0, 0.0]), 0.1, 0.5,
                                 penetration_time=penetration_time)


# name: (title, state 1, state 2, penetration time s, half width of the close-up m)
CASES = {
    "contact_offset_frontal": (
        ("offset frontal, 40% overlap: the crossings lie on facing faces;\n"
         "n is the axis of least penetration, not across the diagonal"),
        state((0.0, 0.0), 0, 15.0), state((10.0, 1.13), 180, 15.0), 0.02, 0.9),
    "contact_rear_end": (
        ("rear-end, 50% overlap: the crossings lie on facing faces;\n"
         "n is the axis of least penetration, not across the diagonal"),
        state((10.0, 0.0), 0, 5.0), state((0.0, -0.95), 0, 15.0), 0.05, 0.9),
    "contact_tbone": (
        "T-bone: both crossings lie on vehicle 1's right side;\nthe plane is that side",
        state((0.0, 0.0), 0, 0.0), state((0.3, -6.0), 90, 10.0), 0.04, 1.4),
    "contact_corner_into_side": (
        "corner into a side: both crossings lie on vehicle 1's right side;\nthe plane is that side",
        state((0.0, 0.0), 0, 0.0), state((-4.6, -5.2), 45, 10.0), 0.06, 0.9),
}


def _scene(ax, auto, geo, labels):
    """Both footprints at the exchange, their overlap, and (``labels``) each vehicle's name and heading."""
    for k, (car, st) in enumerate(((CAR1, auto.state1), (CAR2, auto.state2))):
        corners = np.asarray(footprint(car, st.position[:2], st.yaw))
        ax.add_patch(Polygon(corners, closed=True, fill=False, edgecolor=COLORS[k], lw=1.6))
        if labels:
            heading = np.array([math.cos(st.yaw), math.sin(st.yaw)])
            centre = corners.mean(0)
            ax.annotate("", xy=centre + 1.2 * heading, xytext=centre - 0.2 * heading,
                        arrowprops={"arrowstyle": "->", "color": COLORS[k], "lw": 1.2})
            side = np.array([-heading[1], heading[0]])
            ax.text(*(centre + 0.45 * side), f"vehicle {k + 1}", color=COLORS[k], ha="center", va="center",
                    fontsize=7, rotation=(math.degrees(float(st.yaw)) + 90) % 180 - 90)
    ax.add_patch(Polygon(geo.polygon[: int(geo.count)], closed=True, facecolor="0.65", edgecolor="0.3", lw=0.8))
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6)


def draw(name, title, s1, s2, penetration_time, half):
    """One PNG: the whole scene (left) and a close-up of the overlap (right)."""
    auto = automatic_contact(CAR1, s1, CAR2, s2, contact(penetration_time), 0.0, auto_point=True, auto_normal=True)
    geo = jax.tree_util.tree_map(np.asarray, auto.geometry)
    fig, (whole, near) = plt.subplots(1, 2, figsize=(6.4, 2.9), dpi=100, gridspec_kw={"width_ratios": (1.25, 1)})
    _scene(whole, auto, geo, labels=True)
    p, n = geo.point[:2], geo.normal[:2]
    everything = np.concatenate([np.asarray(footprint(car, st.position[:2], st.yaw))
                                 for car, st in ((CAR1, auto.state1), (CAR2, auto.state2))])
    lo, hi = everything.min(0) - 0.3, everything.max(0) + 0.3
    whole.set_xlim(lo[0], hi[0])
    whole.set_ylim(lo[1], hi[1])
    whole.add_patch(plt.Rectangle(p - half, 2 * half, 2 * half, fill=False, edgecolor="0.4", lw=0.6, ls=":"))
    whole.set_title("the scene at the exchange", fontsize=7)

    _scene(near, auto, geo, labels=False)
    t = np.array([-n[1], n[0]])
    near.plot(*np.stack([p - 2 * half * t, p + 2 * half * t]).T, color="tab:red", lw=1.4,
              label="contact plane\n(through the centroid)")
    c = geo.crossings
    d = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
    near.plot(*np.stack([c[0] - 2 * half * d, c[1] + 2 * half * d]).T, color="0.2", lw=0.9, ls="--",
              label="line through the crossings")
    near.plot(*geo.crossings.T, "kx", ms=7, mew=1.6, zorder=5, label="outline crossings")
    near.annotate("", xy=p + 0.55 * half * n, xytext=p,
                  arrowprops={"arrowstyle": "-|>", "color": "tab:red", "lw": 1.6})
    near.text(*(p + 0.68 * half * n), "n", color="tab:red", ha="center", va="center", fontsize=10, style="italic")
    near.plot(*p, "o", color="tab:red", ms=4, zorder=6, label="centroid")
    near.set_xlim(p[0] - half, p[0] + half)
    near.set_ylim(p[1] - half, p[1] + half)
    near.set_title("close-up of the overlap", fontsize=7)
    near.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=6, frameon=False)
    fig.suptitle(title, fontsize=8)
    fig.tight_layout()
    path = HERE / f"{name}.png"
    fig.savefig(path)
    plt.close(fig)
    return path


def main():
    for name, (title, s1, s2, pt, half) in CASES.items():
        print(draw(name, title, s1, s2, pt, half))


if __name__ == "__main__":
    main()
