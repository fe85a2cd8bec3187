"""The numbers of a commissioning, from the records logged every bus cycle. ROS-free, no I/O: plain
functions over (time, value) samples, tested on synthetic profiles.

- :func:`loop_timing`: the program loop's period (the heartbeat's rate) and the longest time the
  heartbeat stood still, from the intervals :func:`~vr_driver.commission.bus.heartbeat_brackets`
  gives (each loop dated between two requests of the master).
- :func:`loop_spread`: the spread of the loop's periods, from how the heartbeat wanders about a
  line over windows of several lengths (also where the bus cycle is longer than the loop), or
  "not resolved" and why.
- :func:`date_loops`: a time for every loop of a window -- on the line ``a + P k`` through the
  brackets (a steady loop: no master scheduling in it), per run between two stalls.
- :func:`cruise`: the constant-speed part of a move from rest to rest and its speed.
- :func:`fit_ramp`: the speed ramp from rest (and to rest): its duration, linear or S-shaped,
  with the cruise line fixing where it is centred (a ramp of duration r ends r / 2 after the cruise
  line leaves the rest position, for either shape).
- :func:`cruise_move`: a move long (or slow) enough to reach a cruise, from one that reached none.
- :func:`min_speed_near`: the lowest speed of a stream near each of its points (a stop or a blend),
  from :func:`steady_speeds` (each the median of three: one mis-dated record is not a stop).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

__all__ = ["LoopTiming", "loop_timing", "LoopSpread", "loop_spread", "watch_more", "STEADY_SPREAD", "date_loops", "Cruise", "top_speed", "cruise", "RampFit", "fit_ramp",
           "MoveFit", "fit_move", "RampTimes", "ramp_times", "ramp_linear", "ramp_s_curve", "passing_times", "steady_speeds", "min_speed_near", "moved_interval",
           "cruise_move"]

Samples = Sequence[Tuple[float, float]]


# ----------------------------------------------------------------------------------- the loop

@dataclass(frozen=True)
class LoopTiming:
    """The program loop seen through the heartbeat: its period and gaps (its spread:
    :func:`loop_spread`)."""

    period: float                 # [s] the mean loop period (slope of loop time over loop count)
    max_gap: float                # [s] the longest time between two new heartbeats as seen
    loops: int                    # loops counted
    span: float                   # [s] over this time


def _line(xs: Sequence[float], ys: Sequence[float]) -> Tuple[float, float]:
    """Least squares y = a + b x: (a, b)."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    if sxx <= 0.0:
        return my, 0.0
    b = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx
    return my - b * mx, b


def _robust_line(xs: Sequence[float], ys: Sequence[float]) -> Tuple[float, float]:
    """y = a + b x through points of which a few may be far off (a record dated late on a loaded
    machine): the slope is the median of the pairwise slopes (Theil-Sen), the intercept the median
    of y - b x."""
    n = len(xs)
    slopes = sorted((ys[j] - ys[i]) / (xs[j] - xs[i]) for i in range(n) for j in range(i + 1, n) if xs[j] != xs[i])
    if not slopes:
        return _line(xs, ys)
    b = slopes[len(slopes) // 2]
    rest = sorted(y - b * x for x, y in zip(xs, ys))
    return rest[len(rest) // 2], b


def loops_seen(brackets: Sequence[Tuple[int, float, float]]) -> int:
    """How many program loops ran over the records of ``brackets`` (:func:`~vr_driver.commission.
    bus.heartbeat_brackets`): the heartbeat's advance, not the number of records that brought a new
    one -- at a bus slower than the loop (20 cycles/s against a 10 ms loop) each record brings about
    five loops."""
    return brackets[-1][0] if brackets else 0


def loop_timing(brackets: Sequence[Tuple[int, float, float]]) -> Optional[LoopTiming]:
    """The loop's period and gaps from (loop count, earliest, latest) brackets; None with fewer than 3."""
    if len(brackets) < 3:
        return None
    ks = [float(k) for k, _, _ in brackets]
    mids = [(e + l) / 2.0 for _, e, l in brackets]
    _, period = _line(ks, mids)
    max_gap = max(l2 - l1 for (_, _, l1), (_, _, l2) in zip(brackets, brackets[1:]))
    return LoopTiming(period, max_gap, brackets[-1][0] - brackets[0][0], brackets[-1][2] - brackets[0][2])


#: [s] a loop whose periods spread less than this is "steady" (the uniform +-2 ms of a 10-20 ms loop
#: spreads 1.15 ms: never steady)
STEADY_SPREAD = 0.0005
#: a verdict needs a spread of STEADY_SPREAD to add at least this share to the heartbeat's scatter
#: over the longest window (below it a jittery loop and a steady one look alike: "not resolved")
SPREAD_SENSITIVITY = 0.5
#: the fewest records a window of the spread's estimate holds
SPREAD_WINDOW = 16


@dataclass(frozen=True)
class LoopSpread:
    """The spread of the loop's periods as the heartbeat shows it over windows of several lengths."""

    verdict: str                  # "steady", "irregular" or "not resolved"
    spread: Optional[float]       # [s] the estimate (the median over the window lengths); None: too few records
    low: float                    # [s] the lowest and highest estimate of the window lengths
    high: float
    why: str                      # the verdict's reason, in words
    records: int
    span: float                   # [s] the time the records cover
    needed: Optional[float] = None   # [s] of records a verdict would need (not resolved for want of time)

    @property
    def resolved(self) -> bool:
        return self.verdict != "not resolved"


def _residual_variance(points: Sequence[Tuple[float, int]]) -> float:
    """The variance of the times about the line time = a + P count fitted through ``points``."""
    ks = [float(k) for _, k in points]
    ts = [t for t, _ in points]
    a, b = _line(ks, ts)
    return sum((t - a - b * k) ** 2 for t, k in zip(ts, ks)) / max(1, len(points) - 2)


def loop_spread(points: Sequence[Tuple[float, int]], bus_period: float, limit: float = STEADY_SPREAD
                ) -> LoopSpread:
    """The spread of the loop's periods from (time, heartbeat) of every record (:func:`~vr_driver.
    commission.bus.heartbeat_samples`; the heartbeat unwrapped), whatever the bus cycle against the loop.

    What the bus shows: at each record's time ``t`` the loop count ``k``. A steady loop keeps every
    (k, t) within one period of a straight line however long the window -- the scatter about a line
    fitted over a window is the same for a window of 2 s or of 20 s. Periods that spread by s each
    add up (a loop that runs late stays late): over a window of N loops the times wander from the
    line by a random walk, whose variance about the fitted line grows as s^2 N / 15 (a Brownian
    path less its least-squares line). So the scatter is taken over windows of several lengths --
    the whole record, halves, quarters, and short ones of 1/16 -- and s^2 = 15 x (its growth) /
    (the loops it grew over), from each of the three long lengths against the short one. That
    holds at a bus cycle longer than the loop (50 ms against 16 ms at 19.2 kbit/s): the heartbeat's
    quantisation (a period, whatever the bus) does not grow with the window.

    Verdict: "steady" when every estimate is below ``limit`` and a spread of ``limit`` would have
    added at least SPREAD_SENSITIVITY of the short windows' scatter over the longest window;
    "irregular" when every one is above it (with a fifth of that sensitivity: a spread well above
    the limit shows sooner); else "not resolved", said why and how long a watch would tell
    (``needed``). In synthetic runs of 10-20 ms loops, +-0-6 ms, through 50 ms bus cycles (a few
    ms of the master's own timing noise), 20 s told every one right; 5 s left the steady ones and
    some of +-2 ms "not resolved"."""
    n = len(points)
    span = points[-1][0] - points[0][0] if n >= 2 else 0.0
    if n < 8 * SPREAD_WINDOW or points[-1][1] - points[0][1] < 8 * SPREAD_WINDOW:
        return LoopSpread("not resolved", None, 0.0, 0.0, "too few records (%d over %.1f s; it needs at least %d, "
                          "and as many loops)" % (n, span, 8 * SPREAD_WINDOW), n, span,
                          span * 8 * SPREAD_WINDOW / max(1, min(n, points[-1][1] - points[0][1])) if span else None)
    base = max(SPREAD_WINDOW, n // 16)

    def scatter(size: int) -> Tuple[float, float]:
        """(mean loops, mean residual variance) over the windows of ``size`` records."""
        loops, var = [], []
        for i in range(0, n - size + 1, size):
            w = points[i:i + size]
            loops.append(float(w[-1][1] - w[0][1]))
            var.append(_residual_variance(w))
        return sum(loops) / len(loops), sum(var) / len(var)

    l0, v0 = scatter(base)
    estimates, longest = [], 0.0
    for size in (n, n // 2, n // 4):
        if size < 2 * base:
            continue
        loops, var = scatter(size)
        if loops <= l0:
            continue
        estimates.append(math.sqrt(max(0.0, 15.0 * (var - v0) / (loops - l0))))
        longest = max(longest, loops - l0)
    period = (points[-1][0] - points[0][0]) / max(1, points[-1][1] - points[0][1])
    sampled = ("the bus cycle, %.0f ms, is longer than the loop, %.1f ms: the spread shows only in how the heartbeat "
               "wanders over many loops" % (bus_period * 1e3, period * 1e3)) if bus_period > period else \
        "from the heartbeat's wander over many loops"
    if len(estimates) < 3:
        return LoopSpread("not resolved", None, 0.0, 0.0, "too few records (%d over %.1f s) for windows of "
                          "several lengths" % (n, span), n, span)
    lo, hi = min(estimates), max(estimates)
    spread = sorted(estimates)[len(estimates) // 2]
    # the short windows' scatter less what the estimated spread adds to it there: the heartbeat's
    # quantisation and the master's timing noise, against which a spread must show
    floor = max(v0 - spread * spread * l0 / 15.0, 0.05 * v0, 1e-12)
    sensitivity = limit * limit * longest / 15.0 / floor
    windows = "windows of %.1f-%.1f s" % (span * base / n, span)
    if hi < limit and sensitivity >= SPREAD_SENSITIVITY:
        return LoopSpread("steady", spread, lo, hi, "under %.1f ms over %s; %s" % (limit * 1e3, windows, sampled),
                          n, span)
    if lo > limit and sensitivity >= SPREAD_SENSITIVITY / 5.0:
        return LoopSpread("irregular", spread, lo, hi, "%.2f ms, %.2f-%.2f over %s; %s" % (
            spread * 1e3, lo * 1e3, hi * 1e3, windows, sampled), n, span)
    if sensitivity < SPREAD_SENSITIVITY:
        needed = span * SPREAD_SENSITIVITY / max(sensitivity, 1e-9)
        return LoopSpread("not resolved", spread, lo, hi, "%s, and %.1f s of it are too few loops to tell a spread "
                          "of %.1f ms from none (%.2f-%.2f ms over %s): it needs about %.0f s at this bus rate, or a "
                          "bus cycle well under the loop's %.1f ms (a higher line rate) for a shorter watch"
                          % (sampled, span, limit * 1e3, lo * 1e3, hi * 1e3, windows, needed, period * 1e3),
                          n, span, needed)
    needed = 4.0 * span
    return LoopSpread("not resolved", spread, lo, hi, "%s; the estimates over %s, %.2f-%.2f ms, lie on both sides "
                      "of %.1f ms: a longer watch (about %.0f s) would tell"
                      % (sampled, windows, lo * 1e3, hi * 1e3, limit * 1e3, needed), n, span, needed)


def watch_more(spread: LoopSpread, longest: float) -> float:
    """How much longer [s] to watch the heartbeat for a spread ``not resolved`` for want of loops,
    where the watch it needs is within ``longest`` seconds in all (0: no longer watch helps, or none
    is needed)."""
    if spread.resolved or spread.needed is None or not spread.span < spread.needed <= longest:
        return 0.0
    return spread.needed * 1.1 - spread.span       # a tenth more: the estimate of the need is itself rough


def date_loops(brackets: Sequence[Tuple[int, float, float]], stall: float) -> dict:
    """{loop count: time} for every bracket: on the line a + P k fitted per run of brackets without a
    stall (a gap between two new heartbeats longer than ``stall`` seconds starts a new run), ``a``
    placed in the middle of what every bracket of the run allows (the tightest dating a steady loop
    has), each time then clipped into its own bracket (a loop that ran late is seen there); a run
    too short for a line keeps the brackets' middles."""
    out = {}
    runs: List[List[Tuple[int, float, float]]] = []
    for b in brackets:
        if runs and b[2] - runs[-1][-1][2] <= stall:
            runs[-1].append(b)
        else:
            runs.append([b])
    for run in runs:
        if len(run) < 5:
            for k, e, l in run:
                out[k] = (e + l) / 2.0
            continue
        a, p = _line([float(k) for k, _, _ in run], [(e + l) / 2.0 for _, e, l in run])
        lo = max(e - p * k for k, e, _ in run)
        hi = min(l - p * k for k, _, l in run)
        if lo <= hi:
            a = (lo + hi) / 2.0
        for k, e, l in run:
            out[k] = min(max(a + p * k, e), l)      # a late loop shows in its bracket
    return out


# ----------------------------------------------------------------------------------- moves

@dataclass(frozen=True)
class Cruise:
    """The constant-speed part of a move."""

    speed: float                  # signed [unit/s]
    start: float                  # [s] its first and last sample
    end: float
    samples: int
    line_at: float                # [s] when the cruise line passes ``line_value``
    line_value: float


def moved_interval(samples: Samples, eps: float) -> Optional[Tuple[int, int]]:
    """(last index at the start value, first index at the end value) of a move from rest to rest:
    the samples between them are the motion; None if the value never left its start."""
    if len(samples) < 3:
        return None
    q0, q1 = samples[0][1], samples[-1][1]
    first = next((i for i, (_, q) in enumerate(samples) if abs(q - q0) > eps), None)
    if first is None:
        return None
    last = next(i for i in range(len(samples) - 1, -1, -1) if abs(samples[i][1] - q1) > eps)
    return max(0, first - 1), min(len(samples) - 1, last + 1)


def top_speed(speeds: Sequence[float]) -> float:
    """The speed a move cruises at: the median of the speeds within 20 % of the third fastest (one or
    two fast outliers -- a sample's timing error, a record dated too early after a bus stall -- do not
    set it: a fresh-clone run's look-ahead stream, steady at 60 deg/s, ended on one such record at
    583 deg/s, which set the "cruise" and made every point a stop; the ramps and the rest do not
    count)."""
    mags = sorted(abs(v) for v in speeds)
    if not mags:
        return 0.0
    ref = mags[-min(3, len(mags))]
    if ref <= 0.0:
        return 0.0
    top = [m for m in mags if 0.8 * ref <= m <= ref / 0.8]
    return top[len(top) // 2]


def cruise(samples: Samples, tolerance: float = 0.03, span: int = 4) -> Optional[Cruise]:
    """The cruise of a move from rest to rest: the longest run of samples whose speed over ``span``
    samples (a single sample-to-sample speed carries each sample's timing error) stays within
    ``tolerance`` of the move's top speed (:func:`top_speed`), the line fitted through
    its positions. None if it spans fewer than 4 samples (no cruise reached)."""
    n = len(samples)
    if n < span + 6:
        return None
    speeds = []
    for (t1, q1), (t2, q2) in zip(samples, samples[span:]):
        speeds.append((q2 - q1) / (t2 - t1) if t2 > t1 else 0.0)
    vtop = top_speed(speeds)
    if vtop <= 0.0:
        return None
    ok = [abs(abs(v) - vtop) <= tolerance * vtop for v in speeds]
    best, run_start = (0, 0), None
    for i, good in enumerate(ok + [False]):
        if good and run_start is None:
            run_start = i
        elif not good and run_start is not None:
            if i - run_start > best[1] - best[0]:
                best = (run_start, i)
            run_start = None
    lo, hi = best[0], best[1] - 1 + span      # speed i spans samples i .. i + span
    if best[1] - best[0] < 2 or hi - lo < 3:
        return None
    pts = samples[lo:hi + 1]
    a, b = _robust_line([t for t, _ in pts], [q for _, q in pts])
    mid = (pts[0][0] + pts[-1][0]) / 2.0
    return Cruise(b, pts[0][0], pts[-1][0], len(pts), mid, a + b * mid)


def ramp_linear(tau: float, r: float) -> float:
    """Distance covered ``tau`` after leaving rest with a linear speed ramp of ``r`` to speed 1."""
    if tau <= 0.0:
        return 0.0
    if tau >= r:
        return tau - r / 2.0
    return tau * tau / (2.0 * r)


def ramp_s_curve(tau: float, r: float) -> float:
    """The same for an S-shaped ramp (speed 3u^2 - 2u^3 of the ramp's share u): the same distance
    in the same time as the linear ramp, the peak acceleration 1.5 times its."""
    if tau <= 0.0:
        return 0.0
    if tau >= r:
        return tau - r / 2.0
    u = tau / r
    return r * (u ** 3 - 0.5 * u ** 4)


@dataclass(frozen=True)
class RampFit:
    """A speed ramp from rest (or to rest) fitted to the samples."""

    duration: float               # [s] from rest to cruise speed
    shape: str                    # "linear" or "s_curve" (the better fit)
    residual: float               # [unit] mean absolute residual of the better fit
    residual_other: float         # [unit] of the other shape
    samples: int                  # samples in the ramp
    duration_other: float = 0.0   # [s] the duration the other shape's fit found

    def duration_as(self, shape: str) -> float:
        """The ramp's duration if it has ``shape`` (the two fits differ by the shape's curve)."""
        return self.duration if shape == self.shape else self.duration_other

    @property
    def s_curve_evidence(self) -> float:
        """log(linear's residual / S-curve's): > 0 where the S-curve fits better. Summed over many
        ramps it decides the shape where single ramps are too noisy to."""
        lin, s = ((self.residual, self.residual_other) if self.shape == "linear"
                  else (self.residual_other, self.residual))
        return math.log(max(lin, 1e-12) / max(s, 1e-12))

    @property
    def confident(self) -> bool:
        """The shapes told apart: the other fits at least 1.5 times worse."""
        return self.residual_other >= 1.5 * self.residual


def fit_ramp(samples: Samples, speed: float, rest: float, leave: float, to_rest: bool = False,
             r_max: float = 5.0) -> Optional[RampFit]:
    """Fit the ramp of a move from rest (``to_rest``: into rest) of cruise speed ``speed`` (signed)
    whose cruise line is at ``rest`` at time ``leave`` (the ramp of duration r then begins at
    ``leave - r / 2``; into rest: ends at ``leave + r / 2``). Both shapes, r by golden-section
    search over (0, r_max] for the least sum of absolute residuals (a few records dated late on a
    loaded machine do not pull it); the samples within r_max of ``leave`` count. None without
    samples inside a ramp."""
    sign = -1.0 if to_rest else 1.0
    pts = [(t, q) for t, q in samples if abs(t - leave) <= r_max]
    if len(pts) < 4 or speed == 0.0:
        return None

    def sse(r: float, shape) -> float:
        total = 0.0
        for t, q in pts:
            tau = sign * (t - leave) + r / 2.0
            model = rest + sign * speed * shape(tau, r)
            total += abs(q - model)
        return total

    fits = {}
    for name, shape in (("linear", ramp_linear), ("s_curve", ramp_s_curve)):
        # a coarse scan first (the SSE of a few samples has local minima), then golden section
        grid = [r_max * (i + 1) / 400.0 for i in range(400)]
        best = min(grid, key=lambda r: sse(r, shape))
        lo, hi = max(1e-6, best - r_max / 400.0), best + r_max / 400.0
        g = (math.sqrt(5.0) - 1.0) / 2.0
        for _ in range(40):
            a, b = hi - g * (hi - lo), lo + g * (hi - lo)
            if sse(a, shape) < sse(b, shape):
                hi = b
            else:
                lo = a
        r = (lo + hi) / 2.0
        fits[name] = (r, sse(r, shape) / len(pts))
    name = min(fits, key=lambda n: fits[n][1])
    other = "s_curve" if name == "linear" else "linear"
    r = fits[name][0]
    inside = sum(1 for t, _ in pts if 0.0 < sign * (t - leave) + r / 2.0 < r)
    if inside < 2:
        return None
    return RampFit(r, name, fits[name][1], fits[other][1], inside, fits[other][0])


@dataclass(frozen=True)
class MoveFit:
    """A move from rest to rest: its cruise speed and both ramps."""

    speed: float                  # signed [unit/s]
    ramp_in: RampFit
    ramp_out: RampFit
    cruise_samples: int


def fit_move(samples: Samples, loop: float = 0.01) -> Optional[MoveFit]:
    """Cruise speed and both ramps of a move from rest to rest, refined together: the cruise line
    from the samples between the two ramps, the ramps centred on where that line leaves and reaches
    rest, three times over (a first line from :func:`cruise` holds samples of the ramps' ends). None
    when the move has no cruise (it never reached a constant speed) or a ramp cannot be fitted.
    ``loop``: the sampling period (a floor for the ramps' search range)."""
    cr = cruise(samples)
    if cr is None:
        return None
    start, end = samples[0][1], samples[-1][1]
    v, at, value = cr.speed, cr.line_at, cr.line_value
    lo, hi = cr.start, cr.end
    fit_in = fit_out = None
    count = cr.samples
    for _ in range(3):
        leave = at + (start - value) / v
        arrive = at + (end - value) / v
        fit_in = fit_ramp([p for p in samples if p[0] <= hi], v, start, leave, r_max=3.0 * max(lo - leave, loop))
        fit_out = fit_ramp([p for p in samples if p[0] >= lo], v, end, arrive, to_rest=True,
                           r_max=3.0 * max(arrive - hi, loop))
        if fit_in is None or fit_out is None:
            return None
        lo, hi = leave + fit_in.duration / 2.0, arrive - fit_out.duration / 2.0
        pts = [p for p in samples if lo < p[0] < hi]
        if len(pts) < 3:
            return None
        a, v = _robust_line([t for t, _ in pts], [q for _, q in pts])
        at = (pts[0][0] + pts[-1][0]) / 2.0
        value = a + v * at
        count = len(pts)
    assert fit_in is not None and fit_out is not None
    return MoveFit(v, fit_in, fit_out, count)


#: joints whose times to full speed lie within this share of their mean share one ramp time (at 20
#: cycles/s with an irregular loop a joint's own 0.5 s ramps came out 0.44-0.54 s)
SHARED_RAMP = 0.15


@dataclass(frozen=True)
class RampTimes:
    """The time from rest to full speed, from every measured joint's ramps together."""

    ramp_time: float                              # [s] what the driver counts (ControllerFacts.ramp_time)
    uncertainty: float                            # [s] its standard error
    shared: bool                                  # True: every joint agrees with one ramp time
    per_axis: Dict[int, Tuple[float, float]]      # axis: (time to full speed, its standard error) [s]
    accelerations: Dict[int, Tuple[float, float]]  # axis: (rad/s^2, its standard error)
    words: str


def ramp_times(ramps: Mapping[int, Tuple[float, Sequence[float]]], vmax: Mapping[int, float],
               spacing: float = 0.0, floor: float = 0.02) -> RampTimes:
    """The ramp time and each joint's acceleration from ``ramps`` -- axis: (the cruise speed its
    ramps reached [rad/s], their durations [s]) -- and the joints' full speeds ``vmax``.

    Each joint's time to full speed is its median ramp scaled to full speed (the G2 accelerates the
    same to a lower speed), its standard error the durations' scatter over the root of their number,
    but at least that of a time known to one record (``spacing`` [s] between records / sqrt 12: a
    joint's few ramps share the records' dating -- through 50 ms cycles a jittery loop's 0.1 s
    ramps scattered little and came out 10-40 % long) and ``floor`` of the time. Where every
    joint agrees with one time (within 2.5 standard errors of their weighted mean, or SHARED_RAMP of
    it) that mean is the ramp time, with its error (widened by the joints' scatter about it where
    their own errors understate that), and each joint's acceleration is its full speed over it -- every
    ramp of the run counts, not the slowest joint's few (the largest of six noisy figures came out
    13 % long at 20 cycles/s). Of four joints or more, one off the others keeps its own figure and
    the rest share theirs; the ramp time is then the odd joint's only where it is the slower. Where
    they differ more, each joint keeps its own and the ramp time is the slowest joint's (what the
    driver must allow for)."""
    per_axis: Dict[int, Tuple[float, float]] = {}
    for axis, (v, durations) in ramps.items():
        ds = sorted(durations)
        scale = vmax[axis] / v
        median = ds[len(ds) // 2] if len(ds) % 2 else (ds[len(ds) // 2 - 1] + ds[len(ds) // 2]) / 2.0
        if len(ds) >= 2:
            mean = sum(ds) / len(ds)
            se = math.sqrt(sum((d - mean) ** 2 for d in ds) / (len(ds) - 1) / len(ds))
        else:
            se = 0.0
        t = median * scale
        per_axis[axis] = (t, max(se * scale, spacing / math.sqrt(12.0) * scale, floor * t))
    n = sum(len(d) for _, d in ramps.values())
    group = sorted(per_axis)
    mean, error, shared = _shared_time(per_axis, group)
    odd: Optional[int] = None
    if not shared and len(group) >= 4:
        # one joint off the others (a mis-fitted joint, or one that really ramps in its own time):
        # the rest share theirs, that joint keeps its own figure
        odd = max(group, key=lambda axis: abs(per_axis[axis][0] - mean))
        rest = [axis for axis in group if axis != odd]
        mean, error, shared = _shared_time(per_axis, rest)
        group = rest
        if not shared:
            odd, group = None, sorted(per_axis)
    if shared:
        acc = {axis: (vmax[axis] / mean, vmax[axis] / mean * error / mean) for axis in group}
        words = "one ramp time for joints %s: the weighted mean of their %d ramps" % (
            ", ".join(str(a) for a in group), sum(len(ramps[a][1]) for a in group))
        if odd is None:
            return RampTimes(mean, error, True, per_axis, acc, words)
        t_odd, se_odd = per_axis[odd]
        acc[odd] = (vmax[odd] / t_odd, vmax[odd] / t_odd * se_odd / t_odd)
        if t_odd <= mean:
            words += "; joint_%d faster, on its own (%.3f +- %.3f s)" % (odd, t_odd, se_odd)
            return RampTimes(mean, error, True, per_axis, acc, words)
        words = "joint_%d's, the slowest, on its own (%.3f +- %.3f s); %s" % (odd, t_odd, se_odd, words)
        return RampTimes(t_odd, se_odd, False, per_axis, acc, words)
    acc = {axis: (vmax[axis] / t, vmax[axis] / t * se / t) for axis, (t, se) in per_axis.items()}
    slowest = max(per_axis, key=lambda axis: per_axis[axis][0])
    words = "joint_%d's, the slowest (the joints ramp in times of their own: %s s, %d ramps)" % (
        slowest, ", ".join("%d: %.3f" % (axis, per_axis[axis][0]) for axis in sorted(per_axis)), n)
    return RampTimes(per_axis[slowest][0], per_axis[slowest][1], False, per_axis, acc, words)


def _shared_time(per_axis: Mapping[int, Tuple[float, float]], axes: Sequence[int]) -> Tuple[float, float, bool]:
    """(weighted mean, its error, whether every one of ``axes`` agrees with it) of the joints' times
    to full speed: agreeing, within 2.5 of their own errors or SHARED_RAMP of the mean; the error
    then widened by their scatter about the mean where their own errors understate it."""
    weights = {axis: 1.0 / (per_axis[axis][1] ** 2) for axis in axes}
    total = sum(weights.values())
    mean = sum(weights[axis] * per_axis[axis][0] for axis in axes) / total
    error = math.sqrt(1.0 / total)
    shared = all(abs(per_axis[axis][0] - mean) <= max(2.5 * math.hypot(per_axis[axis][1], error), SHARED_RAMP * mean)
                 for axis in axes)
    if len(axes) > 1:                     # the error said: widened by the scatter (not the test above's)
        chi2 = sum(weights[axis] * (per_axis[axis][0] - mean) ** 2 for axis in axes)
        error *= math.sqrt(max(1.0, chi2 / (len(axes) - 1)))
    return mean, error, shared


def passing_times(samples: Samples, points: Sequence[float]) -> List[Optional[float]]:
    """For each value in ``points``: when the samples (a monotonic path) first pass it, interpolated
    (None if they never do)."""
    out: List[Optional[float]] = []
    for p in points:
        at = None
        for (t1, q1), (t2, q2) in zip(samples, samples[1:]):
            if (q1 - p) * (q2 - p) <= 0.0 and q1 != q2:
                at = t1 + (t2 - t1) * (p - q1) / (q2 - q1)
                break
        out.append(at)
    return out


def steady_speeds(samples: Samples) -> List[Tuple[float, float]]:
    """(time, speed) between consecutive samples, each the median of it and its two neighbours (at
    either end: of the three nearest): a sample's speed carries the timing error of both its dates,
    and one pair dated too far apart (a record late on a loaded machine) reads as a dip -- a blend
    through a point taken for a stop at every point (a fresh-clone test run: joint_1 steady at 36
    deg/s through four blended points, judged "stops at 4 of 4") -- or, the other way, as a peak (the
    last record of a stream after a bus stall: 583 deg/s for 60; the median of the last two kept it).
    A real stop's dip lasts several samples and stays."""
    raw = [((t1 + t2) / 2.0, abs(q2 - q1) / (t2 - t1)) for (t1, q1), (t2, q2) in zip(samples, samples[1:])
           if t2 > t1]
    out = []
    n = len(raw)
    for i, (t, v) in enumerate(raw):
        lo = min(max(0, i - 1), max(0, n - 3))
        near = sorted(x for _, x in raw[lo:lo + 3])
        out.append((t, near[len(near) // 2]))
    return out


def min_speed_near(samples: Samples, points: Sequence[float], window: float) -> List[Optional[float]]:
    """For each value in ``points`` (a monotonic path's passing values): the lowest speed
    (:func:`steady_speeds`) within ``window`` seconds of when the samples pass it (None if they
    never do)."""
    speeds = steady_speeds(samples)
    out: List[Optional[float]] = []
    for at in passing_times(samples, points):
        near = [v for t, v in speeds if at is not None and abs(t - at) <= window]
        out.append(min(near) if near else None)
    return out


def cruise_move(distance: float, peak: float, cruise_speed: float, room: float, cruise_time: float,
                margin: float = 1.3, slowest: float = 0.1) -> Optional[Tuple[float, float]]:
    """(distance, speed) of a move from rest to rest that reaches ``cruise_speed`` and holds it
    ``cruise_time``, sized from one that went ``distance`` and peaked at ``peak`` without a cruise.

    A move that never reached its cruise ramped up and straight back down: with the mean
    acceleration ``a`` of its ramps, ``peak ** 2 = a * distance`` (either ramp shape: the distance of
    a ramp is its mean speed times its time). The new move needs ``speed ** 2 / a`` for its two
    ramps and ``speed * cruise_time`` at cruise, times ``margin``. Where that is longer than
    ``room``, the speed is lowered until it fits in ``room`` (the G2 accelerates the same to a lower
    speed: the constant-acceleration assumption the ramps step measures by). None when the peak says
    nothing (not above 0) or the speed that fits is under ``slowest`` times ``cruise_speed``."""
    values = (distance, peak, cruise_speed, room, cruise_time, margin)
    if not all(math.isfinite(v) for v in values) or min(distance, cruise_speed, room, margin) <= 0.0 or peak <= 0.0:
        return None
    a = peak * peak / distance
    need = margin * (cruise_speed * cruise_speed / a + cruise_speed * cruise_time)
    if need <= room:
        return need, cruise_speed
    # margin * (v^2 / a + v T) = room, for v > 0
    t = max(0.0, cruise_time)
    v = a * (-t + math.sqrt(t * t + 4.0 * room / (margin * a))) / 2.0
    if v < slowest * cruise_speed:
        return None
    return room, v
