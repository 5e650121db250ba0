"""Feed pulsation: the feed drive pulses, modulating both cutting loads in proportion and in phase.

Signature (any waveform of a binding slide, a stick-slip or a pulsing drive, thesis §4.5.3): the
feed is f(1 + m(t)) with m periodic at a frequency a feed drive can have, so

- the cutting loads, which follow the feed per revolution, are modulated **in both channels, in
  phase and nearly in proportion** (the torque's relative swing κ times the thrust's, κ within
  :data:`KAPPA_RANGE`: the loads' feed exponents differ little);
- the depth runs ahead of and behind the nominal one by f·∫m dt (visible on the entry and exit
  ramps);
- **only in contact**: in air the loads are zero and nothing pulses;
- **steadily through the cut** and at least :data:`MIN_PERIODS` period within it (a slower change
  of the feed is a feed-rate error, not a pulsation), by less than :data:`MAX_SWING` (the feed
  cannot run backwards); with :data:`REPEAT_PERIODS` or more the wave repeats, with fewer both
  its parts must show: the depth's lead (the ramps moving by f∫m), which a slow trend does not
  make, and the loads' modulation, which a timing misfit at the ramps does not.

Fit: m(t) = Σ_h a_h sin hφ + b_h cos hφ, h = 1 … H (harmonics for a sawtooth, a pulse, an
intermittent stall), φ = 2π f_p (t − t_m) + π r f_p (t − t_m)²/(T/2) (a sweep of the frequency by
±r over half the cut, centred at the cut's middle t_m, tried only where the slowest part of the
cut still holds :data:`REPEAT_PERIODS` periods, harmonics only where the cut holds that many); thrust × (1 + m), torque × (1 + κm), the
simulation read at τ' = t − Δt + ∫m. H and starting values of f_p and r are found by a scan of the linearised model
(:meth:`FeedPulsation.variants`; the best line is also tried as a harmonic of a slower wave,
:data:`SUBHARMONICS`); f_p (within ±:data:`FREQUENCY_RANGE`) and r are then fitted
with the rest. The scanned frequency costs its parameter and the look-elsewhere allowance
(:func:`look_elsewhere`).
Size: the thrust's relative swing, √2 × the rms of m over the cut.

Tests (:meth:`FeedPulsation.checks`): a smooth, non-periodic modulation of as many coefficients
(``periodic``: a slow misfit of another mechanism's form is not a pulsation), per-channel
modulations instead of one (``proportional``),
the same oscillation in air (``absent_in_air``), the swing's size (``feed_can_do``), and the same
wave, of a similar size, in each half of the cut (``repeats``) or, below two periods, the lead
(``depth_leads``). The frequency stays below :data:`NYQUIST_SHARE` of the analysis
instants' Nyquist frequency (:func:`highest_hz`), harmonics below that frequency itself
(:func:`nyquist_hz`; the instants are close enough, :data:`..band.STEP_SIGMAS`, that what the
band passes above it is small).
"""

from __future__ import annotations

import math

import numpy as np

from femstudy.diagnosis.catalogue.registry import (Check, Layout, Parameter, Reading, Role, Term, Variant, carried,
                                                   carried_jacobian, register)

NAME = "feed_pulsation"
#: Frequencies a feed drive's pulsation can have [Hz] (above, the analysis band attenuates).
HIGHEST_HZ = 3.5
LOWEST_HZ = 0.15
#: Fewest periods within the cut.
MIN_PERIODS = 1.0
#: From this many periods in the cut the wave must be seen to repeat; below, the depth's lead must show.
REPEAT_PERIODS = 2.0
#: Least χ² the depth's lead must gain for a pulsation of fewer than REPEAT_PERIODS periods.
LEAD_GAIN = 25.0
#: The fitted frequency stays within this fraction of the scan's.
FREQUENCY_RANGE = 0.1
#: Harmonics tried, and the sweeps (relative change over half the cut) scanned at the best frequency.
HARMONICS = (1, 2, 3, 4, 5)
SWEEPS = np.linspace(-0.6, 0.6, 13)
#: Scan grid size and how many of its local minima are tried as frequencies.
SCAN_POINTS = 240
CANDIDATES = 3
#: The scan's best frequency is also tried as these harmonics of a slower wave, which has at least
#: MIN_WAVE_HARMONICS harmonics (and as many as the line's number).
SUBHARMONICS = (2, 3, 4)
MIN_WAVE_HARMONICS = 3
#: A variant's setting: the harmonic number of the scan's line it was found as (a slower wave's).
FUNDAMENTAL_OF = "fundamental_of"
#: The torque's relative swing over the thrust's.
KAPPA_RANGE = (0.6, 1.5)
FLOOR = 0.03
#: Per-channel modulation instead of one: BIC gain beyond which the pulsation is not one feed, or
#: beyond this share of what the pulsation itself gains (the simulation's loads may include a
#: friction the feed modulates less than the cutting: the channels' swings then differ a little).
SEPARATE_GAIN = 10.0
SEPARATE_SHARE = 0.15
#: An oscillation at the pulsation's frequencies in air with this BIC gain is not the feed.
AIR_GAIN = 10.0
#: What the pulsation must gain over a smooth, non-periodic modulation of as many coefficients (χ²).
PERIODIC_MARGIN = 10.0
#: Ratio of the swings in the two halves of the cut beyond which it is not a steady pulsation, and
#: the least similarity of the two halves' waveforms.
STEADY_RATIO = 2.5
MIN_SIMILARITY = 0.5


#: Highest frequency component, as a fraction of the analysis instants' Nyquist frequency.
NYQUIST_SHARE = 0.8
#: Largest relative swing of the loads a feed drive makes (the feed cannot run backwards).
MAX_SWING = 0.7


def highest_hz(problem) -> float:
    """The highest pulsation frequency [Hz]: ``HIGHEST_HZ``, or less where the analysis instants
    (Δ apart) could not resolve it: ``NYQUIST_SHARE`` of 1/2Δ."""
    return min(HIGHEST_HZ, NYQUIST_SHARE * nyquist_hz(problem))


def nyquist_hz(problem) -> float:
    """The analysis instants' Nyquist frequency 1/2Δ [Hz]: harmonics are modelled up to it."""
    return 0.5 / float(np.median(np.diff(problem.band.t_dec)))


def lowest_hz(problem) -> float:
    return min(max(LOWEST_HZ, MIN_PERIODS / problem.cut_s), 0.5 * highest_hz(problem))


def look_elsewhere(problem) -> float:
    """The look-elsewhere allowance of a scanned frequency, in parameters: 2 ln m / ln n for m
    independent frequencies in the range ((f_max − f_min) × cut duration)."""
    m = max((highest_hz(problem) - lowest_hz(problem)) * problem.cut_s, 2.0)
    return 2 * math.log(m) / math.log(max(problem.n, 3))


def phase(problem, t: np.ndarray, frequency_hz: float, sweep: float) -> np.ndarray:
    half = problem.cut_s / 2
    centre = problem.contact_t + half
    return 2 * math.pi * frequency_hz * (t - centre) + math.pi * sweep * frequency_hz / half * (t - centre) ** 2


def waveforms(problem, t: np.ndarray, frequency_hz: float, sweep: float, harmonics: int) -> np.ndarray:
    """sin hφ, cos hφ for h = 1 … harmonics: instants × 2·harmonics."""
    phi = phase(problem, t, frequency_hz, sweep)
    return np.column_stack([f(h * phi) for h in range(1, harmonics + 1) for f in (np.sin, np.cos)])


def _integral(t: np.ndarray, x: np.ndarray, origin: float) -> np.ndarray:
    """∫_origin^t x dt (trapezoid on the grid), columns of x."""
    cum = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t)[:, None], axis=0)])
    k = int(np.clip(np.searchsorted(t, origin), 1, t.size - 1))
    at = cum[k - 1] + (cum[k] - cum[k - 1]) * (origin - t[k - 1]) / (t[k] - t[k - 1])
    return cum - at


def slower_wave_holds(fit) -> bool:
    """Whether a fit whose pulsation was offered as a slower wave (:data:`FUNDAMENTAL_OF`) is that
    wave: its fundamental is its largest line. A feed drive's waves have it so: |sin kx| ≤ k|sin x|
    makes the fundamental the largest line of any train of rectangular pulses, a sawtooth's lines
    fall as 1/k, a triangle's as 1/k². A fit whose fundamental is weaker than a harmonic is that
    harmonic's own wave (a swept one, say) with a spare slow component. True for every other fit."""
    variant = fit.spec.variant(NAME) if NAME in fit.subset else None
    if variant is None or variant.get(FUNDAMENTAL_OF) is None:
        return True
    h = variant.get("harmonics")
    coef = fit.block(NAME)[:2 * h]
    lines = np.hypot(coef[0::2], coef[1::2])
    return bool(lines[0] >= lines[1:].max())


class FeedPulsation:
    name = NAME
    role = Role.FEED
    floor = FLOOR
    scans = True

    def available(self, problem) -> bool:
        return problem.cut_s * highest_hz(problem) >= MIN_PERIODS

    def variants(self, problem, residual, base) -> list[Variant]:
        """The best few frequencies of a scan: at each, the linearised pulsation (load × m plus the
        lead's S'·∫m, one sine and cosine shared by both channels) is fitted to ``residual`` (the
        residual of the model without it, channels × instants, smoothed) by GLS; the local minima
        of χ² are refined in sweep and harmonics at the best one."""
        t = problem.band.t_model
        loads, slopes, cutting = base.loads, base.slopes, base.frame.cutting
        rows = problem.usable
        target = np.concatenate([problem.whiten(c, residual[c], rows) for c in range(len(problem.channels))])

        def columns(frequency, sweep, harmonics):
            w = waveforms(problem, t, frequency, sweep, harmonics) * cutting[:, None]
            lead = _integral(t, w, problem.contact_t)
            blocks = []
            for c in range(len(problem.channels)):
                x = loads[c][:, None] * w + slopes[c][:, None] * lead
                blocks.append(problem.whiten(c, problem.band.smooth_model(x.T).T, rows))
            return np.vstack(blocks)

        def gain(frequency, sweep=0.0, harmonics=1):
            A = columns(frequency, sweep, harmonics)
            coef, *_ = np.linalg.lstsq(A, target, rcond=None)
            return float(target @ (A @ coef)), coef

        top = highest_hz(problem)
        grid = np.geomspace(lowest_hz(problem), top, SCAN_POINTS)
        gains = np.array([gain(f)[0] for f in grid])
        peaks = [k for k in range(grid.size) if (k == 0 or gains[k] >= gains[k - 1])
                 and (k == grid.size - 1 or gains[k] >= gains[k + 1])]
        peaks = sorted(peaks, key=lambda k: -gains[k])[:CANDIDATES]
        out = []
        for rank, k in enumerate(peaks):
            frequency = float(grid[k])
            lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
            fine = np.linspace(lo, hi, 9)
            frequency = float(fine[int(np.argmax([gain(f)[0] for f in fine]))])
            sweep, harmonics = 0.0, 1
            if rank == 0:
                # a sweep is seen only over enough periods: the slowest part of the cut holds REPEAT_PERIODS
                sweeps = [s for s in SWEEPS if frequency * (1 + abs(s)) <= top
                          and frequency * (1 - abs(s)) * problem.cut_s >= REPEAT_PERIODS]
                values = [gain(frequency, s)[0] for s in sweeps]
                n = math.log(max(problem.n, 3))
                if values and max(values) - gain(frequency)[0] > 2 * n:
                    sweep = float(sweeps[int(np.argmax(values))])
                # a waveform is seen only over enough periods: harmonics from REPEAT_PERIODS on
                limit = nyquist_hz(problem)
                allowed = [h for h in HARMONICS if (h == 1 or h * frequency * (1 + abs(sweep)) <= limit)
                           and (h == 1 or frequency * problem.cut_s >= REPEAT_PERIODS)]
                scores = [gain(frequency, sweep, h)[0] - 2 * h * n for h in allowed]
                harmonics = int(allowed[int(np.argmax(scores))])
            out.append(Variant((("frequency_hz", frequency), ("sweep", sweep), ("harmonics", harmonics)),
                               f"{frequency:.3g} Hz"))
            if rank == 0 and harmonics == 1 and 3 in allowed:   # a pulse or a stick-slip the scan underrates
                out.append(Variant((("frequency_hz", frequency), ("sweep", sweep), ("harmonics", 3)),
                                   f"{frequency:.3g} Hz, 3 harmonics"))
            if rank == 0:
                out += self._fundamentals(problem, frequency, gain, grid[1] / grid[0])
        return out

    def _fundamentals(self, problem, frequency: float, gain, step: float) -> list[Variant]:
        """The slower waves whose k-th harmonic (k in :data:`SUBHARMONICS`) is the scan's best line
        at ``frequency`` [Hz]: a slow wave's fundamental is what the other mechanisms' flexible
        shapes take up first, so a sawtooth's or a pulse's higher harmonic can stand out in the
        residual instead (and the scan cannot tell which harmonic: it sees the fundamental only
        weakly). Each has max(k, :data:`MIN_WAVE_HARMONICS`) harmonics, at least
        :data:`REPEAT_PERIODS` periods in the cut (its waveform must be seen to repeat) and no
        sweep; its frequency is refined over one scan step (the ratio ``step``) either side by
        ``gain``."""
        out = []
        for k in SUBHARMONICS:
            f, h = frequency / k, max(k, MIN_WAVE_HARMONICS)
            if f < lowest_hz(problem) or f * problem.cut_s < REPEAT_PERIODS or h * f > nyquist_hz(problem):
                continue
            fine = np.linspace(f / step, f * step, 9)
            f = float(fine[int(np.argmax([gain(x, 0.0, h)[0] for x in fine]))])
            out.append(Variant((("frequency_hz", f), ("sweep", 0.0), ("harmonics", h), (FUNDAMENTAL_OF, k)),
                               f"{f:.3g} Hz, {h} harmonics (1/{k} of {frequency:.3g} Hz)"))
        return out

    def layout(self, problem, variant: Variant) -> Layout:
        """The harmonics' sines and cosines, κ (with torque), the frequency (within ±``FREQUENCY_RANGE``
        of the scan's) and, for a swept variant, the sweep."""
        h = variant.get("harmonics", 1)
        names = [f"{f}{k}" for k in range(1, h + 1) for f in ("a", "b")]
        lower, upper, start, counted = [-0.8] * (2 * h), [0.8] * (2 * h), [0.0] * (2 * h), [False] * (2 * h)
        if problem.has_torque:
            names.append("kappa")
            lower.append(KAPPA_RANGE[0]), upper.append(KAPPA_RANGE[1]), start.append(1.0), counted.append(False)
        f = variant.get("frequency_hz")
        names.append("frequency_hz")
        lower.append(f * (1 - FREQUENCY_RANGE)), upper.append(f * (1 + FREQUENCY_RANGE)), start.append(f)
        counted.append(False)
        if variant.get("sweep", 0.0):
            most = min(SWEEPS[-1], max(1 - REPEAT_PERIODS / (f * problem.cut_s), abs(variant.get("sweep"))))
            names.append("sweep")
            lower.append(-most), upper.append(most), start.append(variant.get("sweep")), counted.append(False)
        return Layout(tuple(names), np.array(lower), np.array(upper), np.array(start), np.array(counted),
                      look_elsewhere(problem))

    def _settings(self, problem, variant, theta) -> tuple[int, float, float]:
        h = variant.get("harmonics", 1)
        k = 2 * h + (1 if problem.has_torque else 0)
        return h, float(theta[k]), float(theta[k + 1]) if variant.get("sweep", 0.0) else 0.0

    def term(self, problem, frame, variant, theta) -> Term:
        """m(t), κm(t) and the lead ∫m dt (zero for the ``without_lead`` variant of the signature
        test), with their derivatives in the coefficients, κ, the frequency and the sweep."""
        t = frame.t
        h, frequency, sweep = self._settings(problem, variant, theta)
        phi = phase(problem, t, frequency, sweep)
        harmonics = np.arange(1, h + 1)
        w = np.column_stack([f(k * phi) for k in harmonics for f in (np.sin, np.cos)])
        k = 2 * h
        m = w @ theta[:k]
        value = carried(problem, m, theta[k] if problem.has_torque else 0.0)
        without_lead = bool(variant.get("without_lead"))
        lead_w = None if without_lead else _integral(t, w, frame.contact_t_s)

        def derivatives() -> tuple[np.ndarray, np.ndarray]:
            # ∂m/∂φ, and φ's derivatives in the frequency and the sweep
            dm = np.column_stack([k_ * w[:, 2 * i + 1] * theta[2 * i] - k_ * w[:, 2 * i] * theta[2 * i + 1]
                                  for i, k_ in enumerate(harmonics)]).sum(axis=1)   # w holds sin kφ, cos kφ
            half = problem.cut_s / 2
            u = t - (problem.contact_t + half)
            extra = [dm * (2 * math.pi * u + math.pi * sweep * u ** 2 / half)]
            if variant.get("sweep", 0.0):
                extra.append(dm * math.pi * frequency * u ** 2 / half)
            columns = np.column_stack([w] + [e[:, None] for e in extra])
            first = k + (1 if problem.has_torque else 0)
            index = list(range(k)) + list(range(first, first + len(extra)))
            jac = carried_jacobian(problem, columns, index, m, theta, k)
            lead_jac = np.zeros((t.size, theta.size))
            if not without_lead:   # the columns' integrals, each on its own: those of w are lead_w's
                lead_jac[:, index] = np.column_stack([lead_w, _integral(t, columns[:, k:], frame.contact_t_s)])
            return jac, lead_jac

        lead = np.zeros(t.size) if without_lead else lead_w @ theta[:k]
        return Term(value, derivatives, lead)

    def frequency(self, problem, fit) -> tuple[float, float, int]:
        """The fitted frequency [Hz], sweep and number of harmonics."""
        v = fit.spec.variant(NAME)
        h, frequency, sweep = self._settings(problem, v, fit.block(NAME))
        return frequency, sweep, h

    def modulation(self, problem, fit, t: np.ndarray) -> np.ndarray:
        frequency, sweep, h = self.frequency(problem, fit)
        return waveforms(problem, t, frequency, sweep, h) @ fit.block(NAME)[:2 * h]

    def size(self, problem, fit) -> float:
        t = problem.band.t_model
        cut = (t >= problem.contact_t) & (t <= problem.contact_t + problem.cut_s)
        m = self.modulation(problem, fit, t[cut])
        return float(math.sqrt(2 * np.mean(m ** 2))) if m.size else 0.0

    def checks(self, problem, fit, refit) -> list[Check]:
        """``refit(kind, fit)`` returns the Δχ² figures of the alternatives (:mod:`..signatures`)."""
        out = []
        if problem.has_torque:
            gain = refit("separate_channels", fit)
            allowed = max(SEPARATE_GAIN, SEPARATE_SHARE * refit("gain", fit))
            kappa = fit.value(f"{NAME}.kappa")
            inside = KAPPA_RANGE[0] * 1.02 < kappa < KAPPA_RANGE[1] / 1.02
            out.append(Check("proportional", gain < allowed and inside, gain,
                             f"the torque swings {kappa:.2f} times the thrust's share (a feed's: "
                             f"{KAPPA_RANGE[0]:g}-{KAPPA_RANGE[1]:g}, not at either end), and a separate modulation of each "
                             f"channel gains {gain:.1f} over one feed modulation (BIC; at most {allowed:.1f}, "
                             f"{100 * SEPARATE_SHARE:g} % of what the pulsation gains)"))
        gain = refit("in_air", fit)
        if gain is not None:
            out.append(Check("absent_in_air", gain < AIR_GAIN, gain,
                             f"the same oscillation in the load-free stretches gains {gain:.1f} (BIC; at most "
                             f"{AIR_GAIN:g})"))
        margin = refit("periodic", fit)
        out.append(Check("periodic", margin >= PERIODIC_MARGIN, margin,
                         f"it gains {margin:.1f} more than a smooth, non-periodic modulation with as many "
                         f"coefficients (at least {PERIODIC_MARGIN:g})"))
        swing = self.size(problem, fit)
        out.append(Check("feed_can_do", swing <= MAX_SWING, swing,
                         f"the loads swing by ±{100 * swing:.0f} % (a feed drive's pulsation at most "
                         f"±{100 * MAX_SWING:.0f} %: the feed cannot run backwards)"))
        halves = refit("halves", fit) if problem.cut_s * self.frequency(problem, fit)[0] >= REPEAT_PERIODS else None
        if halves is None:
            lead = refit("lead", fit)
            loads = refit("gain", fit) - lead
            out.append(Check("depth_leads", min(lead, loads) >= LEAD_GAIN, min(lead, loads),
                             f"with fewer than {REPEAT_PERIODS:g} periods in the cut the wave cannot be seen to repeat: "
                             f"both its parts must show, the depth running ahead and behind (the ramps moving) gains "
                             f"{lead:.1f} and the loads' modulation beside it {loads:.1f} (each at least {LEAD_GAIN:g})"))
        else:
            ratio, similarity = halves
            out.append(Check("repeats", ratio < STEADY_RATIO and similarity >= MIN_SIMILARITY, similarity,
                             f"fitted in each half of the cut, the wave repeats with a similarity of {similarity:.2f} "
                             f"(at least {MIN_SIMILARITY:g}) and swings {ratio:.2f} times as much in one half (at most "
                             f"{STEADY_RATIO:g})"))
        return out

    def reading(self, problem, fit, context) -> Reading:
        f_p, sweep, h = self.frequency(problem, fit)
        coef = fit.block(NAME)
        A = math.hypot(coef[0], coef[1])
        amplitude = self.size(problem, fit)
        t = np.linspace(0.0, 1.0 / f_p, 400)
        w = np.column_stack([f(k * 2 * math.pi * f_p * t) for k in range(1, h + 1) for f in (np.sin, np.cos)])
        m = w @ coef[:2 * h]
        lead = np.concatenate([[0.0], np.cumsum(0.5 * (m[1:] + m[:-1]) * np.diff(t))])
        depth = problem.geometry.feed_mm_s * float(np.ptp(lead)) / 2
        harmonic_share = math.sqrt(max(np.sum(coef[2:2 * h] ** 2), 0.0)) / max(A, 1e-12) if h > 1 else 0.0
        waveform = "sine" if harmonic_share < 0.15 else ("pulse-shaped (odd harmonics)" if np.sum(coef[4:2 * h:4] ** 2 + coef[5:2 * h:4] ** 2) > np.sum(coef[2:2 * h:4] ** 2 + coef[3:2 * h:4] ** 2) else "asymmetric (stick-slip)")
        params = [Parameter("amplitude", round(amplitude, 4)), Parameter("fundamental_amplitude", round(A, 4)),
                  Parameter("frequency_hz", round(f_p, 4)), Parameter("period_s", round(1 / f_p, 4)),
                  Parameter("phase_rad", round(math.atan2(coef[1], coef[0]), 4)), Parameter("harmonics", h),
                  Parameter("waveform", waveform), Parameter("depth_amplitude_mm", round(depth, 4)),
                  Parameter("thrust_amplitude_N", round(amplitude * problem.initial_force_N, 4))]
        sweep_text = ""
        if sweep:
            rate = sweep * f_p / (problem.cut_s / 2)
            params.append(Parameter("sweep_hz_per_s", round(rate, 4)))
            sweep_text = (f", its frequency drifting by {rate:+.3g} Hz/s ({f_p * (1 - abs(sweep)):.3g}-"
                          f"{f_p * (1 + abs(sweep)):.3g} Hz over the cut)")
        if problem.has_torque:
            params.append(Parameter("torque_to_thrust_swing", round(fit.value(f"{NAME}.kappa"), 3)))
        text = (f"The loads in contact oscillate together at {f_p:.3g} Hz (period {1 / f_p:.3g} s) by ±{100 * amplitude:.0f} % "
                f"(±{amplitude * problem.initial_force_N:.3g} N of thrust), {waveform}{sweep_text}: the feed pulsates, "
                f"so the drill runs up to {1000 * depth:.0f} µm ahead of and behind the nominal depth. This is the "
                f"pulse-type feeding of a drive or slide that binds (thesis §4.5.3), not a property of the bone.")
        return Reading(tuple(params), text)


register(FeedPulsation())
