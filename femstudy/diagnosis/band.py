"""The analysis band: Gaussian smoothing, decimation and the recording's own noise level.

The missing mechanisms act below about 3 Hz; the spindle ripple (N/60 Hz and harmonics) and
white sensor noise are nuisance. The recording and every candidate model are compared through
one linear operator, the Gaussian-weighted mean at decimated instants t_j,

    ȳ(t_j) = Σ_i q_i w(t_j − t_i) y_i / Σ_i q_i w(t_j − t_i),      w(u) = exp(−u² / 2σ_g²),

with q_i the trapezoid weights of the samples. Because w is a continuous kernel, the recording
at its own samples and a model on any finer grid pass through the same low-pass, gain
exp(−2π² σ_g² f²). σ_g = max(35 ms, 0.6 / f_spindle) makes the gain ≤ 1e-3 at the spindle
frequency. The instants are Δ = ``STEP_SIGMAS`` σ_g apart; smoothed white noise correlates by
exp(−Δ²/4σ_g²) between neighbours (without the fitted noise model they count as
n_eff = n / (1 + 2ρ) independent samples).

Noise level: the white part of the raw residual (recording − simulation) is the level of its
Welch power spectral density between ``NOISE_BAND_LOW_HZ`` and 0.4 × the sampling rate:
segments averaged by their median (which ignores the transients at contact and retraction),
then the mean over frequencies of the bins below three times their median (which leaves out
the narrow spindle lines; on white noise the estimate is within 1 %). σ_raw² = PSD · f_s / 2, and each smoothed
sample has σ_j = σ_raw (Σ_i w̃_ji²)^½ with w̃ its normalised weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal, sparse

#: Smallest Gaussian width [s]: keeps the band up to ~3 Hz (gain 0.8 at 3 Hz).
MIN_SIGMA_S = 0.035
#: Decimation step in Gaussian widths. At the instants' Nyquist frequency 1/2Δ the smoothing passes
#: exp(−π²/2(Δ/σ)²): 0.29 at 2σ (at 3.5σ it passed 0.67, so a sharp periodic load's harmonics
#: aliased onto slow trends). Neighbours correlate by exp(−Δ²/4σ²) = 0.37; the noise model's
#: whitening takes that into account.
STEP_SIGMAS = 2.0
#: Width of an independent step [Gaussian widths], for the shortest window that can be diagnosed.
INDEPENDENT_SIGMAS = 3.5
#: Fewest analysis instants of a window.
MIN_INSTANTS = 40
#: Kernel support in Gaussian widths (weights beyond are below 4e-6 of the peak).
SUPPORT_SIGMAS = 5.0
#: Model grid spacing in Gaussian widths (about 85 Hz at the smallest width; the smoothed
#: model then differs from the same model sampled at 1 kHz by under 0.15 noise units).
MODEL_STEP_SIGMAS = 1 / 3
#: Lowest frequency of the band where the noise level is read [Hz].
NOISE_BAND_LOW_HZ = 10.0


def kernel_width_s(spindle_rpm: float) -> float:
    """σ_g [s]: gain exp(−2π²σ_g²f²) ≤ 1e-3 at the spindle frequency N/60, at least 35 ms."""
    return max(MIN_SIGMA_S, 0.6 / (spindle_rpm / 60.0))


def _trapezoid_weights(t: np.ndarray) -> np.ndarray:
    q = np.empty_like(t)
    q[1:-1] = 0.5 * (t[2:] - t[:-2])
    q[0], q[-1] = 0.5 * (t[1] - t[0]), 0.5 * (t[-1] - t[-2])
    return q


def gaussian_operator(t_samples: np.ndarray, t_centres: np.ndarray, sigma_s: float) -> sparse.csr_matrix:
    """Sparse rows of normalised weights q_i w(t_j − t_i) (each row sums to one)."""
    half = SUPPORT_SIGMAS * sigma_s
    lo = np.searchsorted(t_samples, t_centres - half, side="left")
    hi = np.searchsorted(t_samples, t_centres + half, side="right")
    counts = hi - lo
    rows = np.repeat(np.arange(t_centres.size), counts)
    cols = np.concatenate([np.arange(a, b) for a, b in zip(lo, hi)])
    q = _trapezoid_weights(t_samples)
    w = q[cols] * np.exp(-0.5 * ((t_centres[rows] - t_samples[cols]) / sigma_s) ** 2)
    sums = np.bincount(rows, weights=w, minlength=t_centres.size)
    return sparse.csr_matrix((w / sums[rows], (rows, cols)), shape=(t_centres.size, t_samples.size))


@dataclass(frozen=True)
class Band:
    """Decimated instants, the operator on the recording's samples and on the model grid."""

    sigma_s: float
    t_dec: np.ndarray           # decimated instants [s]
    t_model: np.ndarray         # uniform grid on which models are evaluated [s]
    on_samples: sparse.csr_matrix
    on_model: sparse.csr_matrix
    noise_gain: np.ndarray      # (Σ_i w̃_ji²)^½ per instant, on the recording's samples
    correlation: float          # correlation of smoothed white noise between neighbours

    @property
    def n_eff_factor(self) -> float:
        """Effective independent samples per decimated sample, 1 / (1 + 2ρ)."""
        return 1.0 / (1.0 + 2.0 * self.correlation)

    def smooth(self, y: np.ndarray) -> np.ndarray:
        """The recording's samples (last axis) at the decimated instants."""
        return (self.on_samples @ np.atleast_2d(y).T).T.reshape(np.shape(y)[:-1] + (self.t_dec.size,))

    def smooth_model(self, y: np.ndarray) -> np.ndarray:
        """A model on ``t_model`` (last axis) at the decimated instants."""
        return (self.on_model @ np.atleast_2d(y).T).T.reshape(np.shape(y)[:-1] + (self.t_dec.size,))

    def smooth_columns(self, x: np.ndarray) -> np.ndarray:
        """Columns of a model on ``t_model`` (instants on axis 0, e.g. its derivatives) at the
        decimated instants: the same sums as :meth:`smooth_model`, without transposing."""
        return self.on_model @ x


def make_band(t: np.ndarray, spindle_rpm: float, start_s: float, end_s: float) -> Band:
    """The band for recording times ``t`` restricted to [start_s, end_s]. A short window gets
    closer instants (at least ``MIN_INSTANTS``); their stronger correlation is the noise
    model's business (:mod:`.noise`)."""
    sigma = kernel_width_s(spindle_rpm)
    step = min(STEP_SIGMAS * sigma, (end_s - start_s) / MIN_INSTANTS)
    n = int(math.floor((end_s - start_s) / step))
    t_dec = start_s + (end_s - start_s - n * step) / 2 + step * np.arange(n + 1)
    h = MODEL_STEP_SIGMAS * sigma
    m = int(math.ceil((end_s - start_s) / h))
    t_model = np.linspace(start_s, end_s, m + 1)
    inside = (t >= start_s) & (t <= end_s)
    first = int(np.argmax(inside))
    on_samples = gaussian_operator(t[inside], t_dec, sigma)
    # embed in the full sample index space so the operator applies to whole channels
    on_samples = sparse.csr_matrix((on_samples.data, on_samples.indices + first, on_samples.indptr),
                                   shape=(t_dec.size, t.size))
    gain = np.sqrt(np.asarray(on_samples.multiply(on_samples).sum(axis=1)).ravel())
    return Band(sigma, t_dec, t_model, on_samples, gaussian_operator(t_model, t_dec, sigma), gain,
                float(math.exp(-(step / sigma) ** 2 / 4)))


def white_noise_sigma(t: np.ndarray, residual: np.ndarray) -> float:
    """σ_raw of the white noise in a raw residual, from its median Welch spectrum (see module)."""
    fs = 1.0 / float(np.median(np.diff(t)))
    nperseg = int(2 ** round(math.log2(max(fs, 64.0))))
    nperseg = max(32, min(nperseg, residual.size // 4))
    f, psd = signal.welch(residual, fs=fs, nperseg=nperseg, detrend="linear", average="median")
    lo = min(NOISE_BAND_LOW_HZ, 0.2 * fs)
    band = (f >= lo) & (f <= 0.4 * fs)
    if not np.any(band):
        band = f > 0
    level = psd[band]
    lines = level >= 3 * np.median(level)  # the spindle lines
    if not np.all(lines):  # (a residual without noise has a flat zero spectrum: all of it "lines")
        level = level[~lines]
    return float(math.sqrt(np.mean(level) * fs / 2))
