"""docs/validation.md: every published or closed-form case ks-jax reproduces, each result beside its
reference value, with the difference and the tolerance it is held to; and instrumented crash tests beside
ks-jax's forward and fitted values (``validation_measured.py``).

    python docs/validation.py            # print the Markdown of docs/validation.md
    python docs/validation.py --write    # rewrite docs/validation.md

The reference values come from outside the library's exchange: the Virtual CRASH manual's panels (the
``reference`` tables of the seed case files in ks_jax/cases/), and closed forms computed here in plain
Python from the case files in docs/validation/ (Brach's planar impact model, the inline impact, impacts
into a wall). ks-jax's values are the same case files solved by ``ks_jax.load_case`` and ``ks_jax.solve``
in float64, all in one call. tests/test_validation.py holds every difference to its tolerance and the
page to what this script prints, so that the page cannot drift from the code.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from importlib import resources
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

import ks_jax

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # the measured tests' tables live beside this script
import validation_measured as measured

PAGE = HERE / "validation.md"
CASES = HERE / "validation"
SEEDS = ("seed_000_saturn_pontiac.json", "seed_001_lucid_kia.toml")

CLOSED_FORM_TOL = 1e-9  # relative (absolute in rad/s for a yaw rate that should be 0)
SHOWN_FLOOR = 1e-12  # differences below it are shown as "< 1e-12": their digits are rounding, not results
MANUAL_FLOOR = 1e-4  # the manual's values: their printed rounding, or 0.01 %, whichever is looser
MANUAL_SLIPS = {  # (file, path) -> (tolerance, why): where the chapter's own arithmetic is off
    ("seed_001_lucid_kia.toml", "contact.impulse_magnitude"): (2e-4, "see note 1"),
}


class Row(NamedTuple):
    """One line of a table: the texts shown, and the difference and tolerance the test holds."""

    case: str
    result: str
    reference: str
    value: str
    difference: float
    tolerance: float
    shown_difference: str
    shown_tolerance: str

    @property
    def within(self) -> bool:
        return abs(self.difference) <= self.tolerance


# --------------------------------------------------------------------------- case files read by hand
def _read(name):
    """A case file of docs/validation/ as plain JSON: the hand calculations read it without ks_jax."""
    return json.loads((CASES / name).read_text())


def _body(v):
    """A vehicle of a case file (bare numbers: SI, angles in degrees, yaw rates in deg/s) as the planar
    rigid body the closed forms need: mass, yaw inertia, CG (x, y), CG velocity (x, y), yaw rate."""
    if "velocity" in v:
        vel = np.array(v["velocity"][:2], dtype=float)
    else:
        course = math.radians(v.get("course", v["yaw"]))
        vel = v["speed"] * np.array([math.cos(course), math.sin(course)])
    return dict(m=float(v["mass"]), izz=float(v["inertia"][2]), x=np.array(v["position"][:2], dtype=float),
                v=vel, w=math.radians(v.get("yaw_rate", 0.0)))


def _normal(c):
    """The unit normal (x, y) of a contact: an azimuth in degrees or a vector."""
    n = c["normal"]
    n = np.array(n[:2], dtype=float) if isinstance(n, list) else np.array([math.cos(math.radians(n)),
                                                                           math.sin(math.radians(n))])
    return n / math.hypot(*n)


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


# --------------------------------------------------------------------------- planar rigid-body impact
def _frame(bodies, point, n):
    """The contact frame of a planar impact: t = k x n; for each body (sign +1 for the body that takes
    +J, -1 for the one that takes -J) the arm r = P - x. Returns the 2x2 matrix of the relative contact
    velocity's change per impulse, in (n, t) components, and the relative contact velocity (u_n, u_t):

        K_nn = sum 1/m + r_t^2 / I,   K_tt = sum 1/m + r_n^2 / I,   K_nt = -sum r_n r_t / I.
    """
    t = np.array([-n[1], n[0]])
    knn = ktt = knt = 0.0
    u = np.zeros(2)
    for sign, b in bodies:
        r = point - b["x"]
        rn, rt = float(r @ n), float(r @ t)
        knn += 1.0 / b["m"] + rt * rt / b["izz"]
        ktt += 1.0 / b["m"] + rn * rn / b["izz"]
        knt -= rn * rt / b["izz"]
        u += sign * (b["v"] + b["w"] * np.array([-r[1], r[0]]))  # v + w k x r
    return t, knn, ktt, knt, float(u @ n), float(u @ t)


def _solve2(knn, ktt, knt, a_n, a_t):
    """(P_n, P_t) with K (P_n, P_t) = (a_n, a_t), by Cramer's rule."""
    det = knn * ktt - knt * knt
    return (a_n * ktt - knt * a_t) / det, (knn * a_t - knt * a_n) / det


def _after(bodies, point, j):
    """Velocities and yaw rates after the impulse j (on the +1 body; -j on the other), and the kinetic
    energy lost (translation and yaw), each body's before minus after."""
    out, loss = [], 0.0
    for sign, b in bodies:
        r = point - b["x"]
        v = b["v"] + sign * j / b["m"]
        w = b["w"] + sign * _cross(r, j) / b["izz"]
        out.append(dict(velocity=v, yaw_rate=w, delta_v=math.hypot(*j) / b["m"]))
        loss += 0.5 * b["m"] * (b["v"] @ b["v"] - v @ v) + 0.5 * b["izz"] * (b["w"] ** 2 - w ** 2)
    return out, loss


def brach(b1, b2, point, n, e, mu):
    """Brach's planar impact of two bodies (R. M. Brach, "Mechanical Impact Dynamics"): restitution on the
    normal contact velocity, u_n' = -e u_n, and an impulse ratio P_t / P_n. The critical ratio mu_0 is
    the one that also stops the tangential contact velocity (u_t' = 0); the contact slides when mu <
    |mu_0|, with the ratio mu of mu_0's sign and P_n = -(1 + e) u_n / (K_nn + ratio K_nt); otherwise
    the impulse is the critical one. Returns the impulse on body 1, whether it slides, and the results
    after."""
    bodies = ((1.0, b1), (-1.0, b2))
    t, knn, ktt, knt, un, ut = _frame(bodies, point, n)
    pn, pt = _solve2(knn, ktt, knt, -(1.0 + e) * un, -ut)
    sliding = mu < abs(pt / pn)
    if sliding:
        ratio = math.copysign(mu, pt / pn)
        pn = -(1.0 + e) * un / (knn + ratio * knt)
        pt = ratio * pn
    j = pn * n + pt * t
    after, loss = _after(bodies, point, j)
    return dict(impulse=j, sliding=sliding, energy_loss=loss, vehicles=after)


def wall(b, point, n, e, mu):
    """A body striking a fixed wall (infinite mass and inertia, at rest), by the KS rule of docs/model.md:
    the stick impulse (P_n, P_t) = -K^-1 (u_n, u_t) brings the contact point to rest; it stands if
    |P_t| <= mu P_n (sticking), else the contact slides with P_t = s mu P_n, s the sign of the stick P_t,
    and P_n = -u_n / (K_nn + s mu K_nt). Restitution scales the whole impulse by (1 + e)."""
    bodies = ((1.0, b),)
    t, knn, ktt, knt, un, ut = _frame(bodies, point, n)
    pn, pt = _solve2(knn, ktt, knt, -un, -ut)
    sliding = abs(pt) > mu * pn
    if sliding:
        s = math.copysign(1.0, pt)
        pn = -un / (knn + s * mu * knt)
        pt = s * mu * pn
    j = (1.0 + e) * (pn * n + pt * t)
    after, loss = _after(bodies, point, j)
    return dict(impulse=j, sliding=sliding, energy_loss=loss, vehicles=after,
                ees=math.sqrt(2.0 * loss / b["m"]))


# --------------------------------------------------------------------------- rows
def _num(x):
    return f"{x + 0.0:.10g}"  # + 0.0: no "-0"


def _sci(x):
    """1e-09 as 1e-9."""
    mantissa, exponent = f"{x:.1e}".split("e")
    mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{int(exponent)}"


def _shown(values, scale):
    """Values as shown: entries within ``SHOWN_FLOOR`` of ``scale`` of zero are rounding, shown as 0, so
    that the page reads the same wherever it is made."""
    values = np.where(np.abs(values) <= SHOWN_FLOOR * scale, 0.0, values)
    return _num(values[0]) if values.size == 1 else "(" + ", ".join(_num(x) for x in values) + ")"


def _closed(case, result, ref, got, unit, tol=CLOSED_FORM_TOL):
    """A row comparing ks-jax with a closed form: relative difference (a vector's: |got - ref| / |ref|),
    absolute where the reference is 0."""
    ref, got = np.atleast_1d(np.asarray(ref, float)), np.atleast_1d(np.asarray(got, float))
    norm = float(np.linalg.norm(ref))
    scale = norm if norm > 0 else 1.0
    d = float(np.linalg.norm(got - ref)) / scale
    absolute = "" if norm > 0 else f" {unit}"
    shown = f"< {_sci(SHOWN_FLOOR)}" if d < SHOWN_FLOOR else _sci(d)
    return Row(case, result, f"{_shown(ref, scale)} {unit}", f"{_shown(got, scale)} {unit}", d, tol,
               shown + absolute, _sci(tol) + absolute)


def _flag(case, ref, got):
    """Whether the contact slides, by the closed form and by ks-jax."""
    word = {True: "slides", False: "sticks"}
    same = bool(ref) == bool(got)
    return Row(case, "contact", word[bool(ref)], word[bool(got)], 0.0 if same else 1.0, 0.0,
               "same" if same else "differs", "same")



def _label(c, file, k=None):
    where = f"`docs/validation/{file}`" + ("" if k is None else f" #{k + 1}")
    return f"**{c['name']}**: {c['description']} ({where})"


def _seed_label(case, file):
    """A manual chapter's title and inputs, from its case file as written (the chapter's units)."""
    raw = case.raw
    cars = ", ".join(f"{v['name']} {v.get('weight', v.get('mass'))} at {v['speed']}" for v in raw["vehicles"])
    k = raw["contact"]
    return (f"**{case.name.split(': ', 1)[-1]}**: {cars}; e {k['restitution']}, mu {k['friction']} "
            f"(`ks_jax/cases/{file}`)")


def _manual_rows(file, sol):
    """The chapter's published values (the case file's ``reference``, in the units it prints them in)
    beside ks-jax's; crushes are left out: the case file's boxes were chosen to give them."""
    rows = []
    names = sol.case.vehicle_names
    labels = {"contact.impulse_magnitude": "impulse", "contact.energy_loss": "energy loss"}
    for path, value in sol.case.raw["reference"].items():
        if path.endswith(".crush"):
            continue
        i = int(path[9]) if path.startswith("vehicles[") else None
        field = path.split(".")[-1]
        result = labels.get(path) or {"delta_v_magnitude": "delta-V", "ees": "EES",
                                      "speed_after": "speed after"}[field] + f", {names[i]}"
        number, unit, got, _ = measured.in_reference_unit(sol, path, value)
        want = float(number)
        decimals = len(number.split(".")[1]) if "." in number else 0
        d = (got - want) / want
        tol, why = MANUAL_SLIPS.get((file, path), (max(0.5 * 10.0 ** -decimals / abs(want), MANUAL_FLOOR), ""))
        unit = unit.replace("*", " ")
        case = "" if rows else _seed_label(sol.case, file)
        rows.append(Row(case, result, f"{number} {unit}", f"{got:.{decimals + 1}f} {unit}", d, tol,
                        f"{d * 100:+.4f} %", f"{tol * 100:.3f} %" + (f" ({why})" if why else "")))
    return rows


def _inline_rows(c, sol, label):
    """Closed forms of an inline impact: J = (1 + e) m1 m2 / (m1 + m2) |u|, E = (1 - e^2) m_red u^2 / 2,
    delta-V_i = J / m_i, with u the closing speed along the line of the CGs."""
    b1, b2 = (_body(v) for v in c["vehicles"])
    n, e = _normal(c["contact"]), float(c["contact"]["restitution"])
    u = float((b1["v"] - b2["v"]) @ n)
    m_red = b1["m"] * b2["m"] / (b1["m"] + b2["m"])
    j = (1.0 + e) * m_red * abs(u)
    r, v = sol.result.contact, sol.result.vehicles
    names = sol.case.vehicle_names
    return [_closed(label, "impulse", j, r.impulse_magnitude, "N s"),
            _closed("", "energy loss", (1.0 - e * e) * m_red * u * u / 2.0, r.energy_loss, "J"),
            _closed("", f"delta-V, {names[0]}", j / b1["m"], v[0].delta_v_magnitude, "m/s"),
            _closed("", f"delta-V, {names[1]}", j / b2["m"], v[1].delta_v_magnitude, "m/s")]


def _brach_rows(c, sol, label):
    """Brach's planar model against ks-jax: whether it slides, impulse, energy loss, velocities and yaw
    rates after."""
    b1, b2 = (_body(v) for v in c["vehicles"])
    k = c["contact"]
    want = brach(b1, b2, np.array(k["point"][:2], float), _normal(k), float(k["restitution"]), float(k["friction"]))
    r, v = sol.result.contact, sol.result.vehicles
    names = sol.case.vehicle_names
    rows = [_flag(label, want["sliding"], r.sliding),
            _closed("", "impulse (x, y)", want["impulse"], r.impulse[:2], "N s"),
            _closed("", "energy loss", want["energy_loss"], r.energy_loss, "J")]
    for i in range(2):
        rows += [_closed("", f"velocity after, {names[i]}", want["vehicles"][i]["velocity"], v[i].velocity_after[:2],
                         "m/s"),
                 _closed("", f"yaw rate after, {names[i]}", want["vehicles"][i]["yaw_rate"], v[i].yaw_rate_after,
                         "rad/s")]
    return rows


def _frontal(b, point, n):
    """Whether an impact into a wall is full frontal: the centroid on the CG's line of travel, the
    velocity along the normal (to rounding: an azimuth of 180 deg has a sine of 1e-16), no yaw rate."""
    r = point - b["x"]
    return (abs(_cross(r, n)) <= SHOWN_FLOOR * math.hypot(*r)
            and abs(_cross(b["v"], n)) <= SHOWN_FLOOR * math.hypot(*b["v"]) and b["w"] == 0.0)


def _wall_rows(c, sol, label):
    """A vehicle into a wall: the frontal closed forms J = (1 + e) m v, delta-V = (1 + e) v,
    E = (1 - e^2) m v^2 / 2, EES = sqrt(2 E / m) where the case is frontal (centroid on the CG's line of
    travel, normal against it), else ``wall`` (the planar rigid body with its yaw inertia)."""
    b = _body(c["vehicles"][0])
    k = c["contact"]
    point, n, e, mu = np.array(k["point"][:2], float), _normal(k), float(k["restitution"]), float(k["friction"])
    name = c["vehicles"][0]["name"]
    if _frontal(b, point, n):
        speed = -float(b["v"] @ n)
        m = b["m"]
        energy = (1.0 - e * e) * m * speed * speed / 2.0
        want = [("impulse (x, y)", (1.0 + e) * m * speed * n, "N s"), ("energy loss", energy, "J"),
                (f"delta-V, {name}", (1.0 + e) * speed, "m/s"), (f"EES, {name}", math.sqrt(2.0 * energy / m), "m/s")]
        got = [sol.result.contact.impulse[:2], sol.result.contact.energy_loss,
               sol.result.vehicles[0].delta_v_magnitude, sol.result.vehicles[0].ees]
        flag = None
    else:
        h = wall(b, point, n, e, mu)
        after = h["vehicles"][0]
        want = [("impulse (x, y)", h["impulse"], "N s"), ("energy loss", h["energy_loss"], "J"),
                (f"delta-V, {name}", after["delta_v"], "m/s"), (f"EES, {name}", h["ees"], "m/s"),
                (f"velocity after, {name}", after["velocity"], "m/s"),
                (f"yaw rate after, {name}", after["yaw_rate"], "rad/s")]
        got = [sol.result.contact.impulse[:2], sol.result.contact.energy_loss,
               sol.result.vehicles[0].delta_v_magnitude, sol.result.vehicles[0].ees,
               sol.result.vehicles[0].velocity_after[:2], sol.result.vehicles[0].yaw_rate_after]
        flag = h["sliding"]
    rows = []
    if flag is not None:
        rows.append(_flag(label, flag, sol.result.contact.sliding))
    for k, (result, value, unit) in enumerate(want):
        case = label if not rows else ""
        rows.append(_closed(case, result, value, got[k], unit))
    return rows



def tables():
    """Every case solved (one ``ks_jax.solve`` call) and compared: {group: [Row, ...]}."""
    jax.config.update("jax_enable_x64", True)  # the closed forms are held to 1e-9: float32 has 7 digits
    seeds = []
    for name in SEEDS:
        with resources.as_file(resources.files("ks_jax.cases") / name) as path:
            seeds.append(ks_jax.load_case(path))
    files = {"inline": "inline.json", "brach": "planar.json", "wall": "wall.json"}
    raw = {g: _read(f)["cases"] for g, f in files.items()}
    loaded = {g: ks_jax.load_case(CASES / f) for g, f in files.items()}
    order = seeds + [c for g in loaded for c in loaded[g]]
    solved = iter(ks_jax.solve(order))
    out = {"manual": [], "inline": [], "brach": [], "wall": []}
    for name in SEEDS:
        out["manual"] += _manual_rows(name, next(solved))
    build = {"inline": _inline_rows, "brach": _brach_rows, "wall": _wall_rows}
    for g, file in files.items():
        sols = [next(solved) for _ in loaded[g]]
        for k, (c, sol) in enumerate(zip(raw[g], sols)):
            if sol.status != "ok":
                raise RuntimeError(f"{file} #{k + 1}: status {sol.status}")
            out[g] += build[g](c, sol, _label(c, file, k))
    return out


# --------------------------------------------------------------------------- the page
def _table(rows, reference):
    lines = [f"| case | result | {reference} | ks-jax | difference | tolerance |", "|---|---|---|---|---|---|"]
    lines += [f"| {r.case} | {r.result} | {r.reference} | {r.value} | {r.shown_difference} | {r.shown_tolerance} |"
              for r in rows]
    return "\n".join(lines)


INTRO = """\
# Validation

Every case below has a value known without ks-jax: a published panel or a closed form. Each table gives
the case's inputs, that value, ks-jax's, their difference and the tolerance it is held to. The cases
are case files (the two Virtual CRASH manual chapters in `ks_jax/cases/`, the others in `docs/validation/`, bare numbers
in SI and angles in degrees), solved by `ks_jax.load_case` and `ks_jax.solve` in float64. The closed
forms are computed in plain Python from the same files, apart from the library.

```
python docs/validation.py            # prints this page
python docs/validation.py --write    # rewrites it
```

`tests/test_validation.py` holds every difference to its tolerance and this page to what the script
prints. Differences are relative (a vector's: |ks-jax - reference| / |reference|), absolute where the
reference is 0; those under 1e-12 are rounding and shown as "< 1e-12".

Section 5 is of another kind: instrumented crash tests, whose measurements ks-jax's model of one exchange
can only approach. There the difference is the model's error, shown as it is; the test holds ks-jax's
values to the figures recorded for them (`docs/validation/measured/recorded.json`).
"""

MANUAL = """\
## 1. The Virtual CRASH manual

The two chapters of the Virtual CRASH manual on KS impulse data, "Reading Collision Data" (a Pontiac
Grand Prix into the rear of a Saturn L300) and "Reading Kudlich-Slibar Impulse Data" (a Kia K5 into the
rear of a Lucid Air); docs/model.md, "Worked examples", sets out their staging. The manual's values are
the case files' `reference` tables, in the units the chapters print. They agree to their printed
rounding, or to 0.01 % where the chapter prints more digits than its rounded inputs carry (the first
chapter's crushes are printed to 0.001 ft, and its EES follow from them). The crushes themselves are
left out: the first case file's boxes were chosen to give them, and the second chapter prints none.
`ks-jax demo` prints the same comparison.

"""

MANUAL_NOTES = """
Note 1: the second chapter's own arithmetic is off in its last digits: (1 + 0.1) x 61.04 slug x 22 ft/s
is 1477.17 lbf s (it prints 1477.21 lbf s), and its 6571.96 N s is 1477.44 lbf s. ks-jax gives
1477.169 lbf s (6570.775 N s), so this row is held to 0.02 %.
"""

INLINE = """\
## 2. Inline impacts: closed forms

Source: momentum and restitution along a line. The centroid lies on the line through both CGs, at CG
height, and the closing velocity u is along it, so no moment arises and friction plays no part:

    J = (1 + e) m1 m2 / (m1 + m2) |u|,   E = (1 - e^2) m_red u^2 / 2,   delta-V_i = J / m_i

with m_red = m1 m2 / (m1 + m2). Tolerance 1e-9.

"""

BRACH = """\
## 3. Planar impacts: Brach's model

Source: R. M. Brach, "Mechanical Impact Dynamics", the planar impact of two rigid bodies with an impulse
ratio mu, computed here from its formulas. In the contact frame (n, t = k x n) with arms r_i = P - x_i,
an impulse (P_n, P_t) on vehicle 1 changes the relative contact velocity (u_n, u_t) by K (P_n, P_t):

    K_nn = sum 1/m_i + r_it^2 / I_i,   K_tt = sum 1/m_i + r_in^2 / I_i,   K_nt = -sum r_in r_it / I_i

with I_i the yaw inertia. Restitution acts on the normal contact velocity, u_n' = -e u_n. The critical
ratio mu_0 = P_t / P_n is the one that also ends the tangential contact velocity (u_t' = 0); the contact
slides when mu < |mu_0|, then P_t = mu P_n with mu of mu_0's sign and
P_n = -(1 + e) u_n / (K_nn + mu K_nt). Velocities and yaw rates after follow from the impulse,
v_i' = v_i +- J / m_i, w_i' = w_i +- (r_i x J) / I_i, and the energy loss from the kinetic energies
(translation and yaw) before and after.

The KS exchange is Brach's model wherever the normal impulse is compressive, in these cases: a sliding
contact (|P_t| = mu P_n, restitution on the normal part only), a sticking one with e = 0 (both end at
a common velocity at P), and a collinear one (no tangential velocity). They part where the contact sticks
off the line with e > 0: KS restitution scales the whole stick impulse, so the tangential contact velocity
reverses to -e u_t, where Brach's ends at 0. All four cases have the CGs and the centroid at one height.
Tolerance 1e-9; "contact" compares whether the contact slides.

"""

WALL = """\
## 4. Impacts into a wall

Source: hand calculation. A fixed object has infinite mass and inertia and is at rest (docs/model.md,
"Fixed objects"); the vehicle takes all of the energy loss, EES = sqrt(2 E / m). The wall's face is
given by a point and its normal, which points out of the wall towards the road, and the contact normal n
is the wall's.

A full frontal impact at speed v, the centroid on the CG's line of travel:

    J = (1 + e) m v n,   delta-V = (1 + e) v,   E = (1 - e^2) m v^2 / 2,   EES = sqrt(2 E / m)

An oblique impact with friction, the centroid off the CG (arm r = P - x, yaw inertia I, t = k x n): the
contact point's velocity is u = v + w k x r, and an impulse (P_n, P_t) changes it by K (P_n, P_t), with

    K_nn = 1/m + r_t^2 / I,   K_tt = 1/m + r_n^2 / I,   K_nt = -r_n r_t / I.

The stick impulse (P_n, P_t) = -K^-1 (u_n, u_t) brings the contact point to rest. It stands where it
lies in the friction cone, |P_t| <= mu P_n (sticking); otherwise the contact slides, P_t = s mu P_n
with s the sign of the stick P_t, and P_n = -u_n / (K_nn + s mu K_nt). Restitution scales either
impulse by (1 + e) (the KS rule: a sticking contact leaves at -e u). After: v' = v + J / m,
w' = w + (r x J) / I, and E is the kinetic energy (translation and yaw) before minus after.
Tolerance 1e-9; "contact" compares whether the contact slides.

"""



def markdown(groups=None, measured_groups=None) -> str:
    """The page: the prose and the tables (the four of closed forms and published panels, then the measured
    tests')."""
    g = tables() if groups is None else groups
    m = measured.tables() if measured_groups is None else measured_groups
    return "\n".join([
        INTRO, MANUAL + _table(g["manual"], "manual") + "\n" + MANUAL_NOTES,
        INLINE + _table(g["inline"], "closed form") + "\n",
        BRACH + _table(g["brach"], "Brach") + "\n",
        WALL + _table(g["wall"], "hand") + "\n",
        measured.markdown(m),
    ]).rstrip("\n") + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Print (or --write) docs/validation.md: every published or "
                                "closed-form case ks-jax reproduces, beside ks-jax's values.")
    p.add_argument("--write", action="store_true", help="rewrite docs/validation.md and record the measured "
                   "tests' forward values (docs/validation/measured/recorded.json)")
    args = p.parse_args(argv)
    m = measured.tables()
    text = markdown(measured_groups=m)
    if args.write:
        PAGE.write_text(text)
        measured.RECORDED.write_text(json.dumps(measured.record(m), indent=1) + "\n")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
