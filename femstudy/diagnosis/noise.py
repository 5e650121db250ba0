"""The recording's noise, fitted rather than assumed: a coloured spectrum per channel.

A load cell's amplifier adds coloured noise (1/f, or AR(1) with a correlation time of tens to
hundreds of milliseconds) on top of white noise. In the analysis band (below a few hertz) that
coloured part dominates, and smoothed samples a decimation step apart are correlated. So the
noise of each channel is modelled as a stationary process, fitted on the recording itself:

1. **Where**: the stretches where the drill is surely in air (:mod:`.air`: more than half a second
   from any load of the aligned simulation, with the events found there left out), each
   detrended by a straight line (a drift is a mechanism, not noise). With less than ``MIN_FREE_S`` of them, the raw residual of the
   aligned simulation over the whole compared span is used instead, high-passed by a
   running median of ``FALLBACK_WINDOW_S`` (which keeps the noise and removes the slow
   mismatch), and a note says so.
2. **Pre-smoothing**: each stretch is smoothed by the band's Gaussian of width σ_p = σ_g/3 at
   steps h = σ_p (:func:`femstudy.diagnosis.band.gaussian_operator`): the spectrum keeps
   everything the analysis band can see and loses the spindle lines' aliases.
3. **Spectrum**: the two-sided power spectral density
       S(f) = W + A (f_c² + f²)^(−α/2)
   — white, plus a coloured part that is AR(1)/Ornstein–Uhlenbeck for α = 2 (correlation
   time 1/2πf_c) and 1/f^α above f_c otherwise — is fitted by Whittle's likelihood,
   Σ_k ln S_p(f_k) + I_k/S_p(f_k), to the Hann-tapered periodograms I_k of the stretches,
   with S_p(f) = S(f) exp(−4π²σ_p²f²) the pre-smoothed spectrum.
   Below the lowest frequency the stretches resolve, f_r, the slowest noise is what decides whether
   a slow mechanism (a drift, a softening) is significant, and the few seconds of load-free data
   pin it poorly (a fitted corner there is as often the detrending's or the white part's as the
   noise's): the coloured part keeps rising as 1/f (an amplifier's flicker, :data:`FLICKER`) from
   its fitted level at f_r down to half the inverse of the compared window, flat below, unless the
   fitted form lies higher. Not the steeper slope often fitted above f_r: that is an AR(1) part
   above its corner, and carried two decades down it rated the slowest AR(1) noise ~900 times
   above the truth at the window's floor (median of 20 draws of 6 s of air; with 1/f ~30 times,
   and above the truth in every draw below 0.3 Hz: tests/test_diagnose_noise.py), which hid
   drifts of a tenth of the load. The result is raised by the standard error of the level it
   was fitted to, a factor 1 + 1/√m with m the periodogram ordinates in the lowest octave
   [f_r, 2f_r], reached an octave below f_r: underrating the slowest noise would make slow
   mechanisms look significant.
4. **Covariance of the analysis samples**: the band smooths with σ_g, so between two instants
   Δ apart C(Δ) = 2 ∫₀^∞ S(f) exp(−4π²σ_g²f²) cos(2πfΔ) df, integrated numerically. Near the
   window's edges the kernel is truncated; each sample's standard deviation is scaled by its
   own noise gain. For white noise this reduces to the band's σ_raw (Σ w̃²)^½ and
   correlation exp(−Δ²/4σ_g²).

The diagnosis then whitens every residual with the Cholesky factor of C (generalised least
squares): fit, model selection, mismatch location and the residual test all use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import linalg, ndimage, optimize, signal
from scipy.linalg import blas

from femstudy.diagnosis.band import gaussian_operator

#: Least total load-free time [s] from which the noise is fitted.
MIN_FREE_S = 1.0
#: Shortest load-free stretch used [s].
MIN_STRETCH_S = 0.4
#: Running-median window that removes slow mismatch from the fallback residual [s].
FALLBACK_WINDOW_S = 0.6
#: Pre-smoothing width as a fraction of the band's Gaussian width.
PRE_FRACTION = 1.0 / 3.0
#: Bounds of the spectral exponent α (2: AR(1) or a random walk; 1: flicker noise).
ALPHA_RANGE = (0.3, 2.0)
#: Below the lowest frequency the data resolve, an unresolved corner is not assumed: the coloured
#: part keeps rising as 1/f^FLICKER (an amplifier's flicker) down to half the window's inverse.
FLICKER = 1.0
#: A stretch of length L detrended by a line loses the power of its lowest periodogram bins: only
#: frequencies from this many times 1/L are used (else a flattening that is not the noise's is fitted).
DETRENDED_BINS = 3.0
#: Frequencies where the pre-smoothing keeps less than this share of the power are not used.
MIN_PRE_GAIN = 0.05


@dataclass(frozen=True)
class NoiseSpectrum:
    """A channel's fitted noise: S(f) = W + A (f_c² + f²)^(−α/2), two-sided [unit²/Hz]."""

    white: float                      #: W [unit²/Hz]
    amplitude: float                  #: A [unit² Hz^(α−1)]
    corner_hz: float                  #: f_c [Hz]
    exponent: float                   #: α
    source: str                       #: where it was fitted
    seconds: float                    #: how much data [s]
    resolved_hz: float = 0.0          #: f_r, the lowest frequency the data resolved [Hz]
    low_margin: float = 1.0           #: 1 + 1/√m, the factor on the fit below f_r
    floor_hz: float = 0.0             #: below this the spectrum is flat: half the inverse of the window [Hz]

    def fitted(self, f: np.ndarray) -> np.ndarray:
        """The fitted form W + A (f_c² + f²)^(−α/2) [unit²/Hz]."""
        return self.white + self.amplitude * (self.corner_hz ** 2 + f ** 2) ** (-self.exponent / 2)

    def spectrum(self, f: np.ndarray) -> np.ndarray:
        """S(f) of the raw noise [unit²/Hz], extrapolated below ``resolved_hz`` (module docstring)."""
        f = np.asarray(f, dtype=float)
        below = f < self.resolved_hz
        out = self.fitted(f)
        if self.amplitude > 0:
            at = self.amplitude * (self.corner_hz ** 2 + self.resolved_hz ** 2) ** (-self.exponent / 2)
            ratio = self.resolved_hz / np.maximum(f, max(self.floor_hz, 1e-6))
            flicker = self.white + at * ratio ** FLICKER
            out = np.where(below, np.maximum(out, flicker), out)
        octaves = np.clip(np.log2(self.resolved_hz / np.maximum(f, 1e-12)), 0.0, 1.0)
        return out * (1.0 + (self.low_margin - 1.0) * octaves)

    def smoothed_autocovariance(self, lags_s: np.ndarray, sigma_g: float) -> np.ndarray:
        """C(Δ) of the noise after a Gaussian smoothing of width ``sigma_g`` [s]."""
        f = np.concatenate([[0.0], np.geomspace(1e-4, 6.0 / sigma_g, 3000)])
        weight = self.spectrum(f) * np.exp(-4 * math.pi ** 2 * f ** 2 * sigma_g ** 2)
        integrand = weight[None, :] * np.cos(2 * math.pi * np.outer(np.abs(lags_s), f))
        return 2 * np.trapezoid(integrand, f, axis=1)

    @property
    def correlation_time_s(self) -> float:
        """1/2πf_c: the coloured part's correlation time when it is AR(1)-like (α ≈ 2) [s]."""
        return 1.0 / (2 * math.pi * self.corner_hz)

    def to_json(self, unit: str, sigma_g: float) -> dict:
        return {"model": "S(f) = W + A (fc^2 + f^2)^(-alpha/2)", "white_per_hz": float(f"{self.white:.4g}"),
                "amplitude": float(f"{self.amplitude:.4g}"), "corner_hz": float(f"{self.corner_hz:.4g}"),
                "alpha": round(self.exponent, 3), "correlation_time_s": float(f"{self.correlation_time_s:.4g}"),
                "resolved_from_hz": float(f"{self.resolved_hz:.4g}"),
                "sd_per_compared_sample": float(f"{math.sqrt(self.smoothed_autocovariance(np.zeros(1), sigma_g)[0]):.4g}"),
                "fitted_on": self.source, "seconds_used": round(self.seconds, 2), "unit": unit}


def _periodograms(series: list[np.ndarray], step_s: float, low_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies and Hann-tapered periodograms (two-sided PSD) of the series, pooled."""
    freqs, values = [], []
    for x in series:
        n = x.size
        window = np.hanning(n)
        spectrum = np.abs(np.fft.rfft(x * window)) ** 2 * step_s / np.sum(window ** 2)
        f = np.fft.rfftfreq(n, step_s)
        keep = (f >= max(low_hz, DETRENDED_BINS / (n * step_s))) & (f < 0.5 / step_s)
        freqs.append(f[keep])
        values.append(spectrum[keep])
    return np.concatenate(freqs), np.concatenate(values)


def fit_spectrum(series: list[np.ndarray], step_s: float, pre_sigma_s: float, source: str,
                 low_hz: float = 0.0, floor_hz: float = 0.0) -> NoiseSpectrum:
    """Whittle fit of S(f) (see the module docstring) to pre-smoothed, detrended ``series``
    sampled every ``step_s``, using frequencies above ``low_hz``.

    Parameters
    ----------
    series : load-free stretches of the noise, pre-smoothed by a Gaussian of ``pre_sigma_s``.
    step_s : their sampling step [s].
    pre_sigma_s : the pre-smoothing width σ_p [s].
    source : where they come from (reported).
    low_hz : lowest frequency used [Hz].
    floor_hz : below it the extrapolated spectrum is flat [Hz].

    Returns
    -------
    NoiseSpectrum

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> fit_spectrum([rng.normal(size=4000)], 0.01, 1e-4, "white").exponent >= 0.3
    True
    """
    usable = [x for x in series if x.size >= 16]
    f, periodogram = _periodograms(usable, step_s, low_hz)
    gain = np.exp(-4 * math.pi ** 2 * pre_sigma_s ** 2 * f ** 2)
    keep = gain >= MIN_PRE_GAIN
    f, periodogram, gain = f[keep], periodogram[keep], gain[keep]
    if not np.any(periodogram > 0):  # a noise-free recording (a simulation compared with itself)
        return NoiseSpectrum(0.0, 0.0, float(f.min()), 2.0, source + ", no noise found",
                             sum(x.size for x in usable) * step_s, float(f.min()), 1.0, floor_hz)
    lowest = max(float(f.min()) / 4, 1e-3)  # a corner just below the data is still seen
    highest = float(f.max())

    def unpack(theta):
        return math.exp(theta[0]), math.exp(theta[1]), math.exp(theta[2]), theta[3]

    def nll(theta):
        w, a, fc, alpha = unpack(theta)
        model = (w + a * (fc ** 2 + f ** 2) ** (-alpha / 2)) * gain
        return float(np.sum(np.log(model) + periodogram / model))

    level = float(np.mean(periodogram / gain))
    white0 = float(np.median((periodogram / gain)[f > 0.3 * highest])) if np.any(f > 0.3 * highest) else level
    bounds = [(math.log(level) - 40, math.log(level) + 10), (math.log(level) - 60, math.log(level) + 40),
              (math.log(lowest), math.log(highest)), ALPHA_RANGE]
    best = None
    for alpha0, fc0 in ((2.0, 1.0), (1.0, lowest * 2), (2.0, lowest * 4)):
        a0 = max(level - white0, 1e-3 * level) * (fc0 ** 2 + 1.0) ** (alpha0 / 2)
        theta0 = [math.log(max(white0, 1e-12 * level)), math.log(a0), math.log(np.clip(fc0, lowest, highest)), alpha0]
        theta0 = [float(np.clip(v, lo, hi)) for v, (lo, hi) in zip(theta0, bounds)]
        sol = optimize.minimize(nll, theta0, method="L-BFGS-B", bounds=bounds)
        if best is None or sol.fun < best.fun:
            best = sol
    w, a, fc, alpha = unpack(best.x)
    resolved = float(f.min())
    octave = int(np.count_nonzero(f <= 2 * resolved))
    return NoiseSpectrum(w, a, fc, float(alpha), source, sum(x.size for x in usable) * step_s,
                         resolved, 1.0 + 1.0 / math.sqrt(octave), floor_hz)


def _presmooth(t: np.ndarray, x: np.ndarray, sigma_p: float) -> np.ndarray:
    """The stretch smoothed by a Gaussian of width σ_p at steps σ_p, trimmed of its edges."""
    centres = np.arange(t[0] + 3 * sigma_p, t[-1] - 3 * sigma_p, sigma_p)
    if centres.size < 4:
        return np.empty(0)
    return gaussian_operator(t, centres, sigma_p) @ x


def runs(t: np.ndarray, mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [i, j) of the runs of ``mask`` at least ``MIN_STRETCH_S`` long."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [(int(i), int(j)) for i, j in zip(edges[::2], edges[1::2]) if t[j - 1] - t[i] >= MIN_STRETCH_S]


@dataclass(frozen=True)
class NoiseFit:
    """The noise model of each channel, and notes on how they were obtained."""

    models: dict[str, NoiseSpectrum]
    notes: tuple[str, ...] = ()


def fit_noise(t: np.ndarray, residuals: dict, air: np.ndarray, sigma_g: float) -> NoiseFit:
    """Noise spectrum per channel from the raw ``residuals`` (recording − aligned simulation) on the
    samples ``t``; ``air`` marks the samples surely in air with nothing but noise (:mod:`.air`)."""
    sigma_p = PRE_FRACTION * sigma_g
    stretches = runs(t, air)
    free_s = sum(t[j - 1] - t[i] for i, j in stretches)
    notes = []
    models = {}
    for channel, r in residuals.items():
        if free_s >= MIN_FREE_S:
            series = [signal.detrend(x) for i, j in stretches if (x := _presmooth(t[i:j], r[i:j], sigma_p)).size]
            source = f"{len(stretches)} load-free stretch(es), {free_s:.1f} s"
            low = 0.0
        else:
            window = max(int(round(FALLBACK_WINDOW_S / float(np.median(np.diff(t))))), 3)
            high = r - ndimage.median_filter(r, size=window, mode="nearest")
            series = [_presmooth(t, high, sigma_p)]
            source = f"the residual of the aligned simulation, high-passed at {FALLBACK_WINDOW_S:g} s"
            low = 2.0 / FALLBACK_WINDOW_S
        models[channel] = fit_spectrum(series, sigma_p, sigma_p, source, low, 0.5 / max(float(t[-1] - t[0]), 1e-3))
    if free_s < MIN_FREE_S:
        notes.append(f"only {free_s:.1f} s of the recording is surely load-free: the noise model comes from the "
                     f"residual of the aligned simulation, high-passed, and may miss the slowest noise")
    return NoiseFit(models, tuple(notes))


class Whitener:
    """Generalised least squares for one channel: C = L Lᵀ, residuals whitened by L⁻¹.

    ``rows`` restricts to a subset of instants (held-out folds); its factor is cached. L⁻¹ is
    formed once (a few hundred instants) and applied as a matrix product, which is far faster
    than a triangular solve per residual evaluation; to many columns at once (a model's
    derivatives) as a triangular one (BLAS trmm), half the work of a dense product."""

    def __init__(self, covariance: np.ndarray):
        self.covariance = covariance
        self.sd = np.sqrt(np.diag(covariance))
        self._inverse_factors: dict = {}

    def _inverse_factor(self, rows: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """L⁻¹ over ``rows``, and the same in Fortran order for BLAS."""
        key = None if rows is None else rows.tobytes()
        if key not in self._inverse_factors:
            c = self.covariance if rows is None else self.covariance[np.ix_(rows, rows)]
            jitter = 1e-10 * float(np.mean(np.diag(c)))
            factor = linalg.cholesky(c + jitter * np.eye(c.shape[0]), lower=True)
            inverse = linalg.solve_triangular(factor, np.eye(c.shape[0]), lower=True)
            self._inverse_factors[key] = (inverse, np.asfortranarray(inverse))
        return self._inverse_factors[key]

    def whiten(self, x: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """L⁻¹ x over ``rows`` (boolean mask, default all); ``x`` has instants on axis 0."""
        x = x if rows is None else x[rows]
        inverse, fortran = self._inverse_factor(rows)
        if x.ndim == 2 and x.shape[1] > 1 and x.shape[0] > 0 and x.dtype == np.float64:
            return blas.dtrmm(1.0, fortran, x, lower=1)
        return inverse @ x


def smoothed_covariance(model: NoiseSpectrum, t_dec: np.ndarray, sigma_g: float, gain: np.ndarray) -> np.ndarray:
    """Covariance of the noise at the decimated instants (uniformly spaced): Toeplitz in the
    lag, each row and column scaled by the instant's noise gain relative to the interior's."""
    step = float(t_dec[1] - t_dec[0]) if t_dec.size > 1 else 1.0
    acov = model.smoothed_autocovariance(step * np.arange(t_dec.size), sigma_g)
    c = linalg.toeplitz(acov)
    interior = float(np.median(gain))
    scale = gain / interior if interior > 0 else np.ones_like(gain)
    return c * np.outer(scale, scale)
