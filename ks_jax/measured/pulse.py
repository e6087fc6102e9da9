"""A vehicle's measured delta-V from its crash-test accelerometers, with a one-sigma uncertainty (docs/measured.md).

The pipeline, per channel: read it (``ev5.read_channel``, SI); remove the mean of its pre-impact samples
(t < 0: the accelerometer's offset); filter it with the SAE J211/1 channel frequency class filter
(``cfc_filter``); integrate it with trapezoids from time 0 (first contact). Channels of one axis are averaged,
the SAE y axis (right) is turned into ks-jax's ISO body y (left), and the delta-V is read at the end of the pulse:
the last time the filtered resultant acceleration exceeds 2 % of its peak or 1 g, whichever is larger, searched
over the record less a settling interval. (The time of the largest |delta-V| is no rule: in a car-to-car test
the integral of a CG accelerometer can swing by 15 km/h for some 50 ms about its final value, as vehicle 2's
does in NHTSA test 7292.)

The one-sigma uncertainty is the root sum of squares of four parts, each stated with its basis:

1. offset: the standard error of the removed pre-impact mean (sample standard deviation / sqrt(n), from the
   raw samples; for several channels, that of their mean), times the integration window's length;
2. window: the largest move of the delta-V within the settling interval after the pulse's end (it ends later or
   earlier than the rule says, or an offset drifts);
3. channels: the sample standard deviation of the channels' own delta-Vs where an axis has several (left and right
   crossmember, primary and redundant): sensor location and sensor disagreement, not divided by sqrt(n);
4. accuracy: a relative accuracy of the integrated signal, 1 % by default: the order of an accelerometer's
   sensitivity (calibration) uncertainty, stated as an assumption, not read from the test.

The delta-V of a body-fixed accelerometer is the integral of the acceleration in the vehicle's axes; where the
vehicle yaws during the pulse it is not the ground-frame delta-V (docs/measured.md, "Limits").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ks_jax.units import G0, KPH

from .ev5 import Channel, CrashTest, read_channel

ACCURACY = 0.01  # relative accuracy of an integrated accelerometer signal (an assumed calibration uncertainty)
SETTLE = 0.05  # s: the interval after the pulse's end over which the window part is measured
END_LEVEL = 0.02  # the pulse ends when the filtered resultant acceleration last exceeds this share of its peak ...
END_FLOOR = G0  # ... or 1 g, whichever is larger (tyre forces after separation stay below it)
MIN_PRE_IMPACT = 10  # pre-impact samples needed to estimate an offset
CFC_DESIGN = 2.0775  # SAE J211/1 appendix C: the design frequency is 2.0775 CFC
CG = "VECG"  # SENATT of a vehicle's CG accelerometers
CROSSMEMBER = ("FLLR", "FLRR")  # SENATT of the left / right rear-seat crossmember accelerometers


def cfc_coefficients(cfc: float, dt: float) -> tuple:
    """(a0, a1, a2, b1, b2) of SAE J211/1 appendix C's two-pole Butterworth for channel frequency class ``cfc``
    (Hz) and sample interval ``dt`` (s): wd = 2 pi CFC 2.0775, wa = tan(wd T / 2), a0 = wa^2 / (1 + sqrt2 wa + wa^2),
    a1 = 2 a0, a2 = a0, b1 = -2 (wa^2 - 1) / (1 + sqrt2 wa + wa^2), b2 = (-1 + sqrt2 wa - wa^2) / (1 + sqrt2 wa +
    wa^2), for y[n] = a0 x[n] + a1 x[n-1] + a2 x[n-2] + b1 y[n-1] + b2 y[n-2]."""
    if not (math.isfinite(cfc) and cfc > 0):
        raise ValueError(f"cfc = {cfc:g}: must be a positive channel frequency class (Hz), e.g. 60 or 180")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt:g}: must be a positive sample interval (s)")
    wd = 2.0 * math.pi * cfc * CFC_DESIGN
    if wd * dt / 2.0 >= math.pi / 2.0:
        raise ValueError(f"cfc = {cfc:g} with dt = {dt:g} s: the design frequency {cfc * CFC_DESIGN:g} Hz must be "
                         f"below half the sampling rate ({0.5 / dt:g} Hz); sample faster or choose a lower class")
    wa = math.sin(wd * dt / 2.0) / math.cos(wd * dt / 2.0)
    d = 1.0 + math.sqrt(2.0) * wa + wa * wa
    a0 = wa * wa / d
    return a0, 2.0 * a0, a0, -2.0 * (wa * wa - 1.0) / d, (-1.0 + math.sqrt(2.0) * wa - wa * wa) / d


def _one_pass(x, a0, a1, a2, b1, b2):
    """The recursion forward over ``x``, started at rest on x[0] (the filter's unit DC gain holds it there)."""
    y = np.empty_like(x)
    x1 = x2 = y1 = y2 = float(x[0])
    for n, xn in enumerate(x.tolist()):
        yn = a0 * xn + a1 * x1 + a2 * x2 + b1 * y1 + b2 * y2
        y[n] = yn
        x2, x1, y2, y1 = x1, xn, y1, yn
    return y


def cfc_filter(values, dt: float, cfc: float = 60) -> np.ndarray:
    """``values`` (n,) sampled every ``dt`` s, filtered with the SAE J211/1 channel frequency class ``cfc`` filter:
    the two-pole Butterworth of ``cfc_coefficients`` run forward, then backward over the result, so that the phase
    cancels (a four-pole response, -3 dB at about 1.65 CFC Hz: 100 Hz for CFC 60, 300 Hz for CFC 180).

    Each end is extended by its odd reflection (2 x[0] - x[k]) over four periods of the design frequency, and
    each pass starts at rest on its first value, so that the record's ends do not ring."""
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or x.size < 3:
        raise ValueError(f"values: shape {x.shape}: must be one channel of at least 3 samples")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"values: sample {int(np.argmin(np.isfinite(x)))} is not finite: must all be finite")
    coefficients = cfc_coefficients(float(cfc), float(dt))
    pad = min(x.size - 1, int(math.ceil(4.0 / (cfc * CFC_DESIGN * dt))))
    ext = np.concatenate([2.0 * x[0] - x[pad:0:-1], x, 2.0 * x[-1] - x[-2:-pad - 2:-1]])
    forward = _one_pass(ext, *coefficients)
    both = _one_pass(forward[::-1].copy(), *coefficients)[::-1]
    return both[pad:pad + x.size]


@dataclass(frozen=True)
class Uncertainty:
    """The parts of a one-sigma uncertainty (the unit of the quantity): offset, window, channels, accuracy
    (module docstring); ``total`` is their root sum of squares."""

    offset: float
    window: float
    channels: float
    accuracy: float

    @property
    def total(self) -> float:
        return math.sqrt(self.offset ** 2 + self.window ** 2 + self.channels ** 2 + self.accuracy ** 2)


@dataclass(frozen=True, eq=False)
class MeasuredDeltaV:
    """A vehicle's delta-V from its accelerometers (``measured_delta_v``).

    test, vehicle: the NHTSA test and VEHNO. time (n,) s from first contact; delta_v_x, delta_v_y (n,) m/s: the
    history in the vehicle's ISO body axes (x forward, y left), delta_v_y None without a lateral channel.
    end_time (s): the end of the pulse; delta_v (x, y) m/s there (y None without a lateral channel);
    magnitude (m/s); pdof (deg): the direction the force came from, SAE J224 as ks-jax reports it (docs/model.md,
    "pdof and pdof_clock"): atan2(dv_y, -dv_x) mod 360, None without a lateral channel. sigma (m/s), sigma_pdof
    (deg), sigma_x, sigma_y (m/s): one-sigma uncertainties; parts: the magnitude's ``Uncertainty``. cfc: the filter
    class; offset_window (s, s): the pre-impact samples averaged; settle (s); accuracy (relative); curves_x,
    curves_y: the curves used; method: the above in words."""

    test: int
    vehicle: int
    time: np.ndarray
    delta_v_x: np.ndarray
    delta_v_y: np.ndarray | None
    end_time: float
    delta_v: tuple
    magnitude: float
    pdof: float | None
    sigma: float
    sigma_pdof: float | None
    sigma_x: float
    sigma_y: float | None
    parts: Uncertainty
    cfc: float
    offset_window: tuple
    settle: float
    accuracy: float
    curves_x: tuple
    curves_y: tuple
    method: str

    def evidence(self, index: int) -> list:
        """Fit evidence (docs/fit.md) for ks-jax vehicle ``index``, as a case file's "evidence" list holds it:
        its delta-V magnitude, and its PDOF where a lateral channel was measured."""
        out = [{"quantity": f"vehicles[{index}].delta_v_magnitude", "value": f"{self.magnitude:.6g} m/s",
                "sigma": f"{self.sigma:.6g} m/s"}]
        if self.pdof is not None:
            out.append({"quantity": f"vehicles[{index}].pdof", "value": f"{self.pdof:.6g} deg",
                        "sigma": f"{self.sigma_pdof:.6g} deg"})
        return out


@dataclass(frozen=True)
class Rebound:
    """A barrier test's rebound (``barrier_rebound``). impact_speed (m/s, VEHSPD); zero_time (s): the first time
    the velocity relative to the barrier reaches 0 (the largest dynamic crush); rebound_time (s) and
    rebound_velocity (m/s, negative: away from the barrier): its most negative value after zero_time;
    restitution: e = |rebound_velocity| / impact_speed; sigma_rebound (m/s), sigma_restitution: one sigma, the
    rebound's ``parts`` (m/s) over the impact speed (taken as exact); curves; method."""

    impact_speed: float
    zero_time: float
    rebound_time: float
    rebound_velocity: float
    restitution: float
    sigma_rebound: float
    sigma_restitution: float
    parts: Uncertainty
    curves: tuple
    method: str


@dataclass(frozen=True)
class _Axis:
    """One axis's channels: time (n,) from 0, each channel's filtered acceleration and delta-V (k, n), their offsets'
    standard errors (k,)."""

    time: np.ndarray
    accel: np.ndarray
    each: np.ndarray
    offset_se: np.ndarray
    curves: tuple

    @property
    def mean(self):
        return self.each.mean(axis=0)

    def offset_sigma(self, t):
        """The standard error of the channels' mean offset, times the window length ``t``."""
        return float(np.sqrt(np.sum(self.offset_se ** 2)) / len(self.offset_se) * t)

    def spread(self, k):
        """The channels' sample standard deviation at index ``k`` (0 for one channel)."""
        return float(np.std(self.each[:, k], ddof=1)) if len(self.each) > 1 else 0.0


def _integrated(channel: Channel, cfc: float) -> tuple:
    """(time from 0, filtered acceleration, delta-V from 0, the offset's standard error) of one channel: offset
    removed, filtered, integrated with trapezoids."""
    time, a = read_channel(channel)
    pre = a[time < 0]
    if pre.size < MIN_PRE_IMPACT:
        raise ValueError(f"{channel.path}: {pre.size} samples before time 0 (NFP = {channel.first}): need at "
                         f"least {MIN_PRE_IMPACT} to estimate the accelerometer's offset")
    filtered = cfc_filter(a - pre.mean(), channel.dt, cfc)
    i0 = int(np.searchsorted(time, 0.0))
    t, f = time[i0:], filtered[i0:]
    dv = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(t))])
    return t, f, dv, float(pre.std(ddof=1) / math.sqrt(pre.size))


def _axis(channels: list, cfc: float, test: CrashTest) -> _Axis:
    dts = sorted({c.dt for c in channels})
    if len(dts) > 1:
        raise ValueError(f"{test.path}: curves {', '.join(str(c.curve) for c in channels)}: DELT = "
                         f"{', '.join(f'{d / 1e-6:g}' for d in dts)} microseconds: the channels of one axis must "
                         "share a sample interval to be averaged")
    runs = [_integrated(c, cfc) for c in channels]
    n = min(len(r[0]) for r in runs)
    if n < 2:
        raise ValueError(f"{test.path}: curves {', '.join(str(c.curve) for c in channels)}: no samples after "
                         "time 0 (NLP must be positive)")
    return _Axis(runs[0][0][:n], np.array([r[1][:n] for r in runs]), np.array([r[2][:n] for r in runs]),
                 np.array([r[3] for r in runs]), tuple(c.curve for c in channels))


def _channels(test: CrashTest, vehicle: int) -> tuple:
    """(x channels, y channels, where) for a vehicle: its CG accelerometers (SENATT VECG) where it has them, else
    its rear-seat crossmember accelerometers (FLLR, FLRR); data status AM (as measured) only."""
    test.vehicle(vehicle)  # a clear error for a vehicle that is not there
    acc = [c for c in test.channels if c.vehicle == vehicle and c.sensor == "AC" and c.status == "AM"]
    for where, names in (("CG", (CG,)), ("rear-seat crossmember", CROSSMEMBER)):
        xs = [c for c in acc if c.attachment in names and c.axis == "XG"]
        if xs:
            return xs, [c for c in acc if c.attachment in names and c.axis == "YG"], where
    raise ValueError(f"{test.path}: vehicle {vehicle}: no accelerometer with SENATT VECG (CG) or FLLR / FLRR "
                     "(rear-seat crossmember), AXIS XG and DASTAT AM: nothing to integrate")


def measured_delta_v(test: CrashTest, vehicle: int = 1, cfc: float = 60, *, settle: float = SETTLE,
                     end_level: float = END_LEVEL, accuracy: float = ACCURACY) -> MeasuredDeltaV:
    """Vehicle ``vehicle``'s (VEHNO) delta-V in test ``test`` (``read_test``), with its one-sigma uncertainty.

    The channels: the vehicle's CG accelerometers (SENATT VECG, AXIS XG and YG) where present, else its left and
    right rear-seat crossmember X accelerometers (FLLR, FLRR; longitudinal only), primary and redundant alike,
    data status AM. Each is offset-corrected, CFC ``cfc`` filtered and integrated from 0 (module docstring); an
    axis's channels are averaged; the SAE y is negated into ISO's. The pulse ends at the last time the filtered
    resultant acceleration (of the averaged axes) exceeds ``end_level`` times its peak or 1 g, whichever is larger,
    within the record less ``settle`` s. The uncertainty's parts (module docstring) are found per axis, with
    ``accuracy`` the relative accuracy, and combined into the magnitude's and the PDOF's to first order.

    ValueError for a vehicle that is not in the test, no usable channel, too few pre-impact samples, a record
    shorter than ``settle``, no pulse above that level, or a channel file that disagrees with its record
    (``read_channel``)."""
    if not (math.isfinite(settle) and settle > 0):
        raise ValueError(f"settle = {settle!r}: must be a positive interval (s)")
    if not (math.isfinite(accuracy) and accuracy >= 0):
        raise ValueError(f"accuracy = {accuracy!r}: must be a relative accuracy >= 0 (0.01 is 1 %)")
    if not (math.isfinite(end_level) and 0 < end_level < 1):
        raise ValueError(f"end_level = {end_level!r}: must be a share of the peak acceleration in (0, 1)")
    xs, ys, where = _channels(test, vehicle)
    ax = _axis(xs, cfc, test)
    ay = _axis(ys, cfc, test) if ys else None
    n = len(ax.time) if ay is None else min(len(ax.time), len(ay.time))
    time = ax.time[:n]
    dvx = ax.mean[:n]
    dvy = None if ay is None else -ay.mean[:n]  # SAE y (right) -> ISO y (left)
    resultant = np.abs(dvx) if dvy is None else np.hypot(dvx, dvy)
    ax_mean = ax.accel.mean(axis=0)[:n]
    accel = np.abs(ax_mean) if ay is None else np.hypot(ax_mean, ay.accel.mean(axis=0)[:n])
    searched = time <= time[-1] - settle
    if time[-1] <= settle:
        raise ValueError(f"{test.path}: vehicle {vehicle}: the record ends {time[-1]:g} s after contact: must be "
                         f"longer than settle = {settle:g} s")
    level = max(end_level * float(accel[searched].max()), END_FLOOR)
    above = np.flatnonzero(searched & (accel > level))
    if above.size == 0:
        raise ValueError(f"{test.path}: vehicle {vehicle}: the filtered resultant acceleration stays below "
                         f"{END_FLOOR / G0:g} g: no pulse to integrate")
    k = int(above[-1])
    t_end = float(time[k])
    after = (time >= t_end) & (time <= t_end + settle)

    def parts(axis, values):
        return Uncertainty(offset=axis.offset_sigma(t_end), window=float(np.max(np.abs(values[after] - values[k]))),
                           channels=axis.spread(k), accuracy=accuracy * abs(float(values[k])))

    px = parts(ax, dvx)
    py = None if ay is None else parts(ay, dvy)
    x, y = float(dvx[k]), None if dvy is None else float(dvy[k])
    magnitude = float(resultant[k])
    if py is None:
        mag_parts = Uncertainty(px.offset, px.window, px.channels, accuracy * magnitude)
        pdof = sigma_pdof = None
    else:
        ux, uy = (x / magnitude, y / magnitude) if magnitude > 0 else (1.0, 0.0)
        mag_parts = Uncertainty(offset=math.hypot(ux * px.offset, uy * py.offset),
                                window=float(np.max(np.abs(resultant[after] - resultant[k]))),
                                channels=math.hypot(ux * px.channels, uy * py.channels),
                                accuracy=accuracy * magnitude)
        pdof = math.degrees(math.atan2(y, -x)) % 360.0
        sigma_pdof = (math.degrees(math.hypot(x * py.total, y * px.total) / magnitude ** 2)
                      if magnitude > 0 else 180.0)
    pre_start = min(c.first * c.dt for c in xs + ys)
    curves_y = () if ay is None else ay.curves
    method = (f"CFC {cfc:g} (SAE J211/1) {where} accelerometers, curves {_listed(ax.curves)} (x)"
              + (f" and {_listed(curves_y)} (y, SAE right turned to ISO left)" if curves_y else ", no lateral channel")
              + f"; each channel's mean over {pre_start * 1e3:g} to 0 ms removed, integrated with trapezoids from 0 "
              f"to the end of the pulse, {t_end * 1e3:.1f} ms, the last time the filtered resultant acceleration "
              f"exceeds {level / G0:.3g} g ({end_level:.3g} of its peak, at least 1 g; searched to "
              f"{settle * 1e3:g} ms before the record's end); an axis's channels averaged; one sigma: offset "
              f"(standard error x window), window (largest move over {settle * 1e3:g} ms after the end), channels "
              f"(their standard deviation), accuracy ({accuracy:.3g} of the value, assumed)")
    return MeasuredDeltaV(
        test=test.number, vehicle=vehicle, time=time, delta_v_x=dvx, delta_v_y=dvy, end_time=t_end,
        delta_v=(x, y), magnitude=magnitude, pdof=pdof, sigma=mag_parts.total, sigma_pdof=sigma_pdof,
        sigma_x=px.total, sigma_y=None if py is None else py.total, parts=mag_parts, cfc=cfc,
        offset_window=(pre_start, 0.0), settle=settle, accuracy=accuracy, curves_x=ax.curves, curves_y=curves_y,
        method=method)


def barrier_rebound(test: CrashTest, vehicle: int = 1, cfc: float = 60, *,
                    accuracy: float = ACCURACY) -> Rebound:
    """The rebound of vehicle ``vehicle`` from the barrier of a barrier test (TSTCFN VTB), along its x axis.

    Its velocity relative to the barrier is v(t) = VEHSPD + delta-V_x(t), with delta-V_x as ``measured_delta_v``
    makes it (offset removed, CFC ``cfc``, integrated from 0, channels averaged). v first reaches 0 at the
    largest dynamic crush; the rebound velocity is v's most negative value after that, to the record's end; the
    restitution e = |v_rebound| / VEHSPD. One sigma of the rebound velocity: the offset's standard error times its
    time, the channels' own rebound velocities' standard deviation, and ``accuracy`` times |delta-V_x| at that time
    (a gain error scales the whole integral); e's is that over VEHSPD, the impact speed taken as exact.

    ValueError for a test that is not a barrier test, a vehicle without a speed, or a velocity that does not reach
    0 within the record."""
    if test.configuration != "VTB":
        raise ValueError(f"{test.path}: TEST field 8 TSTCFN = {test.configuration!r}: a rebound from the barrier "
                         "needs a vehicle-into-barrier test (VTB)")
    speed = test.vehicle(vehicle).speed
    if not speed or speed <= 0:
        raise ValueError(f"{test.path}: vehicle {vehicle}: VEHSPD = {speed!r} m/s: must be a positive impact speed")
    xs, _, where = _channels(test, vehicle)
    ax = _axis(xs, cfc, test)
    v = speed + ax.mean
    each = speed + ax.each

    def rebound(velocity, label):
        crossed = np.flatnonzero(velocity <= 0.0)
        if crossed.size == 0:
            raise ValueError(f"{test.path}: vehicle {vehicle} ({label}): the velocity relative to the barrier stays "
                             f"above 0 (lowest {velocity.min():.4g} m/s): no rebound within the record")
        k0 = int(crossed[0])
        return k0, k0 + int(np.argmin(velocity[k0:]))

    k0, k = rebound(v, f"curves {_listed(ax.curves)}")
    own = [each[j][rebound(each[j], f"curve {c}")[1]] for j, c in enumerate(ax.curves)]
    t = float(ax.time[k])
    parts = Uncertainty(offset=ax.offset_sigma(t), window=0.0,
                        channels=float(np.std(own, ddof=1)) if len(own) > 1 else 0.0,
                        accuracy=accuracy * abs(float(ax.mean[k])))
    method = (f"CFC {cfc:g} (SAE J211/1) {where} X accelerometers, curves {_listed(ax.curves)}, offset removed, "
              f"integrated from 0 and added to VEHSPD {speed / KPH:g} km/h; zero at "
              f"{ax.time[k0] * 1e3:.1f} ms, most negative after it at {t * 1e3:.1f} ms")
    return Rebound(impact_speed=speed, zero_time=float(ax.time[k0]), rebound_time=t, rebound_velocity=float(v[k]),
                   restitution=float(-v[k] / speed), sigma_rebound=parts.total, sigma_restitution=parts.total / speed,
                   parts=parts, curves=ax.curves, method=method)


def _listed(curves) -> str:
    return ", ".join(str(c) for c in curves)
