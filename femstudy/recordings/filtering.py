"""Zero-phase low-pass filtering of the isolated cut (thesis §4.5.3, Table 4-4).

Table 4-4 gives, per feed f, a pass frequency of 0.05 Hz and a stop frequency that falls
linearly with the feed: f_stop = 2.6 − 0.4 f [Hz] reproduces all four rows exactly (2.2, 2.0,
1.9, 1.8 Hz at 1.0, 1.5, 1.75, 2.0 mm/s); outside 1–2 mm/s the end values are held. The
thesis does not say how the Simulink filter placed its cut-off between the two edges. The
edge that matters for the trend is the cut-off, so femstudy uses a 4th-order Butterworth
filter whose attenuation reaches 40 dB exactly at f_stop (80 dB after the forward and
backward passes), which puts the −3 dB cut-off as high as the table allows:

    f_c = f_stop / 10^(40 / (20·4)) = f_stop / √10     (0.63 Hz at 1.5 mm/s)

and the pass edge 0.05 Hz is met with a loss below 1e-8 dB. ``scipy.signal.sosfiltfilt``
runs the filter forwards and backwards, so the phase shift is zero. Beyond the ends of the
cut the signal is continued by a quadratic fitted to its last 1/f_c seconds plus the
residuals mirrored point-symmetrically, so an exponential rise keeps its curvature up to the
last sample (reflecting about the end sample or a straight line flattens it there by up to
5 %). No filter can tell a slow feed pulsation from the trend at the very ends of a cut:
within 1/f_c of an end, a 20 % pulsation just above the cut-off leaves errors of up to 20 %.
The calibration therefore fits the unfiltered cut (:meth:`ProcessedRun.for_fitting`); the
filtered signal is for figures and for reading the trend.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from femstudy import thesis
from femstudy.errors import require

#: Table 4-4: feed [mm/s] -> stop frequency [Hz] (pass frequency 0.05 Hz, sampling 500 Hz).
TABLE_4_4_STOP_HZ = thesis.TABLE_4_4_STOP_HZ
PASS_HZ = 0.05
ORDER = 4
STOP_ATTENUATION_DB = 40.0


def stop_frequency_hz(feed_mm_s: float) -> float:
    """Table 4-4's stop frequency, 2.6 − 0.4 f [Hz], held at its end values outside 1–2 mm/s."""
    return 2.6 - 0.4 * float(np.clip(feed_mm_s, 1.0, 2.0))


def default_cutoff_hz(feed_mm_s: float) -> float:
    """−3 dB cut-off [Hz] of the default filter: f_stop / 10^(40/(20·4))."""
    return stop_frequency_hz(feed_mm_s) / 10 ** (STOP_ATTENUATION_DB / (20 * ORDER))


def _extend(x: np.ndarray, n_pad: int, n_fit: int, at_start: bool) -> np.ndarray:
    """n_pad samples continuing x beyond one end: a quadratic fitted to the last n_fit samples,
    extrapolated, plus the residuals mirrored point-symmetrically (so noise continues too)."""
    seg = x[:n_fit][::-1] if at_start else x[-n_fit:]
    k = np.arange(-seg.size + 1, 1, dtype=float)  # 0 at the end sample, negative inside
    coef = np.polyfit(k, seg, min(2, seg.size - 1))
    inside = x[1:n_pad + 1] if at_start else x[-2:-n_pad - 2:-1]  # nearest first
    j = np.arange(1, n_pad + 1, dtype=float)
    ext = np.polyval(coef, j) - (inside - np.polyval(coef, -j))
    return ext[::-1] if at_start else ext


def lowpass(values, sample_rate_hz: float, cutoff_hz: float, order: int = ORDER) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``values`` sampled at ``sample_rate_hz`` [Hz]."""
    x = np.asarray(values, float)
    require(cutoff_hz > 0, f"filter cut-off must be positive, got {cutoff_hz} Hz")
    require(cutoff_hz < sample_rate_hz / 2, f"filter cut-off {cutoff_hz:g} Hz must lie below half the "
                                            f"sampling rate ({sample_rate_hz / 2:g} Hz)")
    if x.size < 3:
        return x.copy()
    sos = signal.butter(order, cutoff_hz, fs=sample_rate_hz, output="sos")
    n_pad = min(x.size - 1, int(round(3 * sample_rate_hz / cutoff_hz)))
    n_fit = max(2, min(x.size, int(round(sample_rate_hz / cutoff_hz))))
    extended = np.concatenate([_extend(x, n_pad, n_fit, True), x, _extend(x, n_pad, n_fit, False)])
    return signal.sosfiltfilt(sos, extended, padtype=None)[n_pad:n_pad + x.size]
