"""docs/validation.md, "Measured crash tests": ks-jax beside instrumented crashes (docs/validation.py prints it).

Each test is a case file of docs/validation/measured/: its masses, inertias, dimensions, speeds and the published
centroid and contact normal as the sources give them, the measured results as its ``reference`` (printed beside
ks-jax's) and again as ``evidence`` with a stated sigma, and the unknowns a fit may set (restitution, friction, the
centroid). Two comparisons are made:

- forward: every case solved as written, with restitution and friction from one rule for every test
  (``RULE_RESTITUTION``, ``RULE_FRICTION``), not chosen per test; the difference to the measurement is the model's
  error under that rule;
- fitted: restitution, friction and the centroid fitted to the measured values of each test (``fit.reconstruct``,
  one call per file), with their standard errors, chi^2 and what the evidence leaves open.

The forward values are held to the figures recorded in ``RECORDED`` (``python docs/validation.py --write`` records
them), so that a change of the engine that moves them shows.
"""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np

import fit
import ks_jax
from ks_jax.case import defined_output, parse_output_value
from ks_jax.measured import barrier_rebound, measured_delta_v, read_test
from ks_jax.units import FT

HERE = Path(__file__).resolve().parent
MEASURED = HERE / "validation" / "measured"
RECORDED = MEASURED / "recorded.json"
NCAP = HERE / "validation" / "nhtsa" / "v10146.EV5"
CAR_TO_CAR = HERE / "validation" / "nhtsa" / "v07292.EV5"
FILES = {"rose": "rose_2006.json", "iihs": "iihs_small_overlap.json", "ncap": "nhtsa_10146.json"}
RULE_RESTITUTION, RULE_FRICTION = 0.1, 0.5  # every forward case file holds these (checked below)
RECORD_TOL = 1e-9  # relative: the forward values against their recorded figures

SHORT = {"contact.restitution": "restitution", "contact.friction": "friction", "contact.point[0]": "centroid x",
         "contact.point[1]": "centroid y"}
RESULT = {"delta_v_magnitude": "delta-V", "delta_yaw_rate": "yaw-rate change",
          "delta_v_body[0]": "delta-V, longitudinal", "delta_v_body[1]": "delta-V, lateral"}


class Compared(NamedTuple):
    """One measured result beside ks-jax's forward value, both in the source's unit."""

    case: str
    path: str
    result: str
    unit: str
    measured_text: str  # as the source prints it
    value: float
    value_si: float

    @property
    def measured(self) -> float:
        return float(self.measured_text)

    @property
    def difference(self) -> float:
        return self.value - self.measured

    @property
    def percent(self) -> float:
        return 100.0 * self.difference / abs(self.measured)


class Fitted(NamedTuple):
    """One test's fit: the shown estimate of each unknown, chi^2, the largest residual and what is left open."""

    case: str
    estimates: dict
    chi2: float
    largest_residual: float
    open: str
    result: fit.FitResult


def load(group):
    return ks_jax.load_case(MEASURED / FILES[group])


def _check_rule(cases, file):
    for c in cases:
        k = c.raw["contact"]
        if (k["restitution"], k["friction"]) != (RULE_RESTITUTION, RULE_FRICTION):
            raise ValueError(f"{file}: {c.name}: restitution {k['restitution']}, friction {k['friction']}: the "
                             f"forward cases hold the rule's {RULE_RESTITUTION}, {RULE_FRICTION}")


def in_reference_unit(sol, path, text):
    """A reference value as a case file writes it ("39.5 mph") beside ks-jax's result for ``path``: (the number as
    written, its unit, ks-jax's value in that unit, ks-jax's value in SI)."""
    number, unit = text.split(None, 1)
    scale = parse_output_value(text, path, sol.case.name) / float(number)
    got = float(np.asarray(defined_output(sol.result, path)))
    return number, unit, got / scale, got


def _label(path, names):
    i = int(path[9])
    field = path.split(".", 1)[1]
    return f"{RESULT[field]}, {names[i]}"


def forward_rows(group, cases=None):
    """Every measured result of the group's file beside ks-jax's forward value (one ``ks_jax.solve`` call)."""
    cases = load(group) if cases is None else cases
    _check_rule(cases, FILES[group])
    rows = []
    for sol in ks_jax.solve(cases):
        if sol.status != "ok":
            raise RuntimeError(f"{FILES[group]}: {sol.case.name}: status {sol.status}")
        names = [n.split(" ", 1)[1] if n[:4].isdigit() else n for n in sol.case.vehicle_names]
        for path, text in sol.case.raw["reference"].items():
            number, unit, value, got = in_reference_unit(sol, path, text)
            rows.append(Compared(sol.case.name, path, _label(path, names), unit, number, value, got))
    return rows


def _shown(path, value, std, statements):
    """An estimate as the table shows it: value +- standard error; "n.d." where the evidence sets no value on its
    own. The value the solver stopped at along such a direction is arbitrary (it moves with the starts and the
    rounding of the machine), so it is not shown; a friction that the evidence bounds only from below says whether
    the contact sticks."""
    scale, unit = (FT, " ft") if path.startswith("contact.point") else (1.0, "")
    if math.isfinite(std):
        return f"{value / scale:.3f} +- {std / scale:.3f}{unit}"
    for s in statements:
        if s.startswith(path) and "bounded below only" in s:
            return "n.d. (sticks)" if "contact sticks at the estimate" in s else "n.d. (slides or sticks)"
    return "n.d."


def _open(result):
    """What the evidence leaves open, in a few words: the unknowns it sets only in combination."""
    words = []
    for s in result.unidentified:
        if "not determined separately" in s:
            names = [SHORT[p] for p in SHORT if p in s.split(":", 1)[0]]
            words.append(", ".join(names[:-1]) + f" and {names[-1]}: one combination")
    return "; ".join(words) or "-"


def fitted_rows(group, cases=None):
    """Restitution, friction and the centroid fitted to each test's measurements, case by case as ``ks-jax fit``
    fits them (the cases of a file share one compiled program)."""
    cases = load(group) if cases is None else cases
    rows = []
    for r in (fit.reconstruct(c) for c in cases):
        if not r.converged:
            raise RuntimeError(f"{FILES[group]}: {r.case_name}: the fit did not converge")
        shown = {SHORT[p]: _shown(p, r.estimate[p], r.std[p], r.unidentified) for p in r.estimate}
        largest = max(abs(v) for v in r.residuals.values())
        rows.append(Fitted(r.case_name, shown, r.chi2, largest, _open(r), r))
    return rows


def tables():
    """{group: (forward rows, fitted rows)} for every file that is there, in float64."""
    jax.config.update("jax_enable_x64", True)
    out = {}
    for group, file in FILES.items():
        if (MEASURED / file).exists():
            cases = load(group)
            out[group] = (forward_rows(group, cases), fitted_rows(group, cases))
    return out


def recorded():
    return json.loads(RECORDED.read_text()) if RECORDED.exists() else {}


def record(groups):
    """The forward values (SI) by case and result, as ``RECORDED`` keeps them."""
    out = {}
    for forward, _ in groups.values():
        for r in forward:
            out.setdefault(r.case, {})[r.path] = r.value_si
    return out


# --------------------------------------------------------------------------- the page
def _num(x, digits):
    return f"{x + 0.0:.{digits}f}"


def _digits(text):
    return len(text.split(".")[1]) if "." in text else 0


def _forward_table(rows):
    lines = ["| test | result | measured | ks-jax (rule) | difference |", "|---|---|---|---|---|"]
    last = None
    for r in rows:
        d = _digits(r.measured_text)
        case = f"**{r.case}**" if r.case != last else ""
        last = r.case
        lines.append(f"| {case} | {r.result} | {r.measured_text} {r.unit} | {_num(r.value, d + 1)} {r.unit} | "
                     f"{_num(r.difference, d + 1)} {r.unit} ({r.percent:+.1f} %) |")
    return "\n".join(lines)


def _fitted_table(rows):
    names = [n for n in SHORT.values() if any(n in r.estimates for r in rows)]
    lines = ["| test | " + " | ".join(names) + " | chi^2 | largest residual | left open |",
             "|---|" + "---|" * (len(names) + 3)]
    for r in rows:
        cells = [r.estimates.get(n, "") for n in names]
        lines.append(f"| **{r.case}** | " + " | ".join(cells) + f" | {r.chi2:.2f} | {r.largest_residual:.1f} sigma | "
                     f"{r.open} |")
    return "\n".join(lines)


def summary(rows, results):
    """The mean and largest absolute percentage difference of the rows whose result starts with one of
    ``results``."""
    chosen = [abs(r.percent) for r in rows if r.result.startswith(results)]
    return float(np.mean(chosen)), float(np.max(chosen))


SOURCES = """\
## 5. Measured crash tests

The sections above show that ks-jax computes the KS model right. This one asks whether the model reproduces
real crashes: instrumented tests, their measured delta-V and yaw-rate changes beside ks-jax's. Each test is a
case file of `docs/validation/measured/` (the sources' numbers in the sources' units, bare angles in degrees),
so that `ks-jax solve --json` and `ks-jax fit --json` give the values below.

Sources:

- **Rose et al. 2006**: N. Rose et al., "Restitution Modeling for Crush Analysis: Theory and Validation", SAE
  2006-01-0908; four NHTSA car-to-SUV tests (4363, 4364, 4438, 4474), both vehicles moving at about 35 mph on
  paths 148-150 deg apart, front to front, offset and oblique (a 1997 Honda Accord against an SUV). The numbers
  are those of the paper as transcribed in the pycrash repository (github.com/joe-cormier/pycrash, commit 0356228,
  `projects/validation impact momentum/src/test_inputs_rose.py`; the vehicles' weights, dimensions and yaw
  inertias in `src/vehicle_data_collection.py` of the same folder, marked there as used in the paper), not read
  from the paper itself. Measured: impact speeds, each vehicle's delta-V and yaw-rate change. From the paper's
  analysis of the crush: the centroid (its distance and angle from each CG) and the normal's direction.
- **IIHS small-overlap tests**: the worksheet "test matrix" of `projects/validation impact momentum/docs/Brach
  Matrix.xlsx` in the same repository, 21 IIHS small-overlap and oblique tests at about 40 mph with a rigid
  barrier or pole, attributed there to Brach (the paper is not named). The ten tests of the two vehicles whose
  weight and yaw inertia the repository gives (2008/2009 Ford Fusion, 2012 Audi A4) are used. Measured: the
  impact speed, the longitudinal and lateral delta-V and the yaw-rate change, printed without signs; they are
  given here the directions of a driver's-side overlap (ks-jax's frame, y to the left): the car is slowed and
  pushed to the right, and yaws to the left. From the worksheet's analysis: the centroid (distance d and angle phi
  from the CG) and the crush surface's angle gamma from the car's axis; the normal is taken across that surface,
  at azimuth 270 - gamma.
- **NHTSA test 10146**: the NHTSA Vehicle Crash Test Database's test 10146, a 2018 Toyota Camry (1719 kg) at
  57.09 km/h into a rigid load-cell barrier (the NCAP frontal test), and its rear-seat crossmember accelerometer
  channels, shipped in `docs/validation/nhtsa/` (`SOURCES.md` there). Measured: the impact speed; the delta-V and
  the rebound, from the channels by `ks_jax.measured` (docs/measured.md).

The exchanges are planar: the sources give no CG heights, so both CGs and the centroid are put at 22 in, and the
roll and pitch inertias (a quarter of the yaw inertia, placeholders) play no part. Where a vehicle's CG position
is a placeholder in the source (the Blazer's, half the wheelbase), it does not enter either: the centroid is
placed from the published distances.

**(a) Forward**, with one rule for every test, fixed before the comparison and not adjusted to it: restitution
0.1, friction 0.5. The difference is ks-jax minus the measurement.
"""

FITTED = """\
**(b) Fitted**: restitution (within -0.5 and 0.6: a negative restitution is a contact that does not reach a
common velocity, docs/model.md), friction (0.05 to 2) and the centroid (within 2 ft of the published one; for the
barrier tests its lateral position only) fitted to each test's measurements (`fit.reconstruct`, as `ks-jax fit`
fits them), each measurement with a sigma the sources do not give and that is assumed here: 1 mph (1.47 ft/s) for a
delta-V, 10 deg/s for a yaw-rate change, and for test 10146 the one `ks_jax.measured` states. Standard errors are
the fit's (Laplace); "n.d." marks an unknown the evidence does not set on its own: alone, or only in a
combination with others ("left open"), or a friction it bounds only from below, because the contact sticks
(any friction above some value gives the same exchange).
"""


def _range(values, digits=0):
    lo, hi = (f"{x:.{digits}f}" for x in (min(values), max(values)))
    return lo if lo == hi else f"{lo} to {hi}"


def _rose_text(forward, fitted):
    dv = [abs(r.percent) for r in forward if r.result.startswith("delta-V")]
    suv = [abs(r.difference) for r in forward if r.result.startswith("yaw") and "Accord" not in r.result]
    car = [(r.case, r.value, r.measured) for r in forward if r.result.startswith("yaw") and "Accord" in r.result]
    flipped = [c for c, v, m in car if v * m < 0]
    combined = sum(1 for f in fitted if f.open != "-" or "n.d." in " ".join(f.estimates.values()))
    bound = next(b for b in (0.01, 0.1, 1.0, math.inf) if max(f.chi2 for f in fitted) < b)
    return (f"Rose's tests: every delta-V within {max(dv):.1f} % (mean {np.mean(dv):.1f} %) of the measured; the "
            f"SUVs' yaw-rate changes within {_range(suv)} deg/s. The car's own yaw-rate change is small and missed by "
            f"{_range([abs(v - m) for _, v, m in car])} deg/s"
            + (f", in {', '.join(flipped)} with the wrong sign" if flipped else "")
            + ": the centroid lies close to the line through the car's CG along the impulse, so the car's rotation "
            f"turns on where within the crush the centroid is put. Fitted, every test is reproduced (chi^2 below "
            f"{bound:g}) by a contact that sticks or nearly; but with four measurements and four unknowns, the "
            f"evidence leaves some of them set only in combination in {combined} of the {len(fitted)} tests, as the "
            "fit says: these tests confirm the model's delta-V and the SUV's rotation, not a value of restitution.")


def _iihs_text(forward, fitted):
    swipe = {r.case for r in forward}  # every test of the file
    lon = {r.case: r.percent for r in forward if r.result.startswith("delta-V, longitudinal")}
    e = {f.case: float(f.estimates["restitution"].split()[0]) for f in fitted}
    near = [c for c in swipe if abs(e[c]) <= 0.1]
    far = [c for c in swipe if e[c] < -0.1]
    worst = max(fitted, key=lambda f: f.chi2)
    kinds = {c.name: c.raw["description"].split(", ")[1] for c in load("iihs")}
    odd = sorted(c for c in near if kinds[c] == "non-sideswipe") + sorted(c for c in far if kinds[c] == "sideswipe")
    return (f"The small-overlap tests: under the rule, the longitudinal delta-V is over-estimated in every test, by "
            f"{_range([abs(lon[c]) for c in near])} % where the fitted restitution is near 0 ({len(near)} tests: "
            f"{_range([e[c] for c in near], 3)}; the car leaves the barrier without rebound) and by "
            f"{_range([abs(lon[c]) for c in far])} % in the other {len(far)} (fitted restitution "
            f"{_range([e[c] for c in far], 3)}); the split is the source's own, sideswipe or not"
            + (f", but for {', '.join(odd)}" if odd else "")
            + ". In the latter the measured delta-V is well short of a common velocity at the "
            "centroid, and one exchange reaches it only with a negative restitution, which is a statement about the "
            "model rather than a material property: the overlap loads the wheel, the suspension and the A-pillar over "
            "a long pulse while the car yaws and the centroid moves, and the sensors turn with the car. The friction "
            "is not set by these data: the contact sticks, or would within two standard errors. The worst fit, "
            f"{worst.case} (into a pole), keeps chi^2 {worst.chi2:.1f} with a residual of {worst.largest_residual:.1f} "
            "sigma: no single exchange at one point gives its small longitudinal delta-V with its lateral one.")


def ncap_measurements():
    """Test 10146's delta-V and rebound from its shipped channels (``ks_jax.measured``)."""
    test = read_test(NCAP)
    return measured_delta_v(test, 1), barrier_rebound(test, 1)


def _ncap_text(forward, fitted):
    r = forward[0]
    dv, rebound = ncap_measurements()
    return (f"Test 10146: the rule's restitution gives a delta-V {abs(r.percent):.1f} % below the measured "
            f"{dv.magnitude * 3.6:.2f} +- {dv.sigma * 3.6:.2f} km/h (at the pulse's end, {dv.end_time * 1e3:.0f} ms); "
            f"the fitted restitution is {fitted[0].estimates['restitution']}. The channels' own rebound, the most "
            f"negative velocity after the car stops ({rebound.rebound_velocity * 3.6:.2f} km/h at "
            f"{rebound.rebound_time * 1e3:.0f} ms), gives {rebound.restitution:.3f} "
            f"+- {rebound.sigma_restitution:.3f}: "
            "the car's velocity still changes a little after the rebound's peak, within the pulse, and a single "
            "exchange folds that into its restitution.")


def _car_to_car_text():
    """Why NHTSA test 7292, shipped beside 10146, is not in the tables: its two records disagree with momentum."""
    test = read_test(CAR_TO_CAR)
    one, two = (measured_delta_v(test, n) for n in (1, 2))
    masses = " and ".join(f"{v.mass:.0f}" for v in test.vehicles)
    return (f"NHTSA test 7292 (two Ford Taurus of {masses} kg, one at {test.closing_speed * 3.6:.1f} km/h into the "
            f"other at rest, {360 - test.impact_angle:.0f} deg apart, no frame-rail overlap) is shipped with the "
            f"reader but not tabled: its CG accelerometers give delta-Vs of {one.magnitude * 3.6:.1f} +- "
            f"{one.sigma * 3.6:.1f} and {two.magnitude * 3.6:.1f} +- {two.sigma * 3.6:.1f} km/h, where two cars of "
            "equal mass sharing one impulse have one delta-V. No exchange between rigid bodies matches both. The cars "
            "yaw during a long sliding contact, and the integral of a body-fixed accelerometer is then not the CG's "
            "delta-V over the ground, but by the estimate of docs/measured.md (\"Limits\") that accounts for only "
            "a part of a difference this size; the records are reported as they are.")


TEXT = {"rose": _rose_text, "iihs": _iihs_text, "ncap": _ncap_text}
TITLES = {"rose": "Rose et al. 2006, NHTSA car-to-SUV tests", "iihs": "IIHS small-overlap tests",
          "ncap": "NHTSA test 10146, a frontal barrier test"}


def markdown(groups) -> str:
    """The section: sources, the forward tables, the fitted tables, and what they show."""
    parts = [SOURCES]
    for g, (forward, _) in groups.items():
        parts.append(f"*{TITLES[g]}*\n\n" + _forward_table(forward) + "\n")
    parts.append(FITTED)
    for g, (_, fitted) in groups.items():
        parts.append(f"*{TITLES[g]}*\n\n" + _fitted_table(fitted) + "\n")
    parts.append("**What the tables show.**\n")
    parts += [textwrap.fill(TEXT[g](*groups[g]), 115, break_on_hyphens=False) + "\n" for g in groups]
    parts.append(textwrap.fill(_car_to_car_text(), 115, break_on_hyphens=False) + "\n")
    return "\n".join(parts)
