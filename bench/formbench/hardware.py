"""What the load cell, its amplifier, the converter and the logger do to the true loads.

On the fine grid of the pass (8 kHz or four times the sampling rate, whichever is higher):

1. spindle ripple: loads × (1 + r₁ sin φ + r₂ sin 2φ), φ the spindle's own angle;
2. amplifier noise: white, plus AR(1) (τ 20–400 ms), 1/f (pink above 0.02 Hz) or a slow random
   walk, each channel on its own;
3. mains interference: 50 or 60 Hz (±0.2 Hz) and its third harmonic, a fraction of a percent to a
   few percent of the load;
4. the anti-alias filter: a causal Butterworth (order 2–6) or Bessel (order 4) low-pass at
   0.2–0.45 of the sampling rate;
5. sampling at k/f_s plus a clock jitter of up to 20 µs;
6. the converter: clipping at its range and quantisation to 12–16 bits of it;
7. the logger's stamps: ideal, or jittered by up to a quarter of a sample, or rounded to a
   coarse resolution (so that some repeat), with a few rows written twice, and in some cases an
   epoch clock (1.7e9 s + t).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal


@dataclass(frozen=True)
class Hardware:
    rate_hz: float
    ripple: tuple[float, float, float, float]          #: r1, r2, phase1, phase2
    white: tuple[float, float]                         #: σ thrust [N], torque [N·mm] at the sampling rate
    coloured: str                                      #: "none", "ar1", "pink", "walk"
    coloured_sigma: tuple[float, float]
    ar1_time_s: float
    mains_hz: float
    mains: tuple[float, float]                         #: amplitude thrust [N], torque [N·mm]
    filter_kind: str                                   #: "butter" or "bessel"
    filter_order: int
    filter_fraction: float                             #: cut-off / sampling rate
    bits: int
    range_factor: tuple[float, float]                  #: converter range / the channel's largest value
    tare: tuple[float, float]
    stamps: str                                        #: "ideal", "jitter", "coarse", "duplicates"
    stamp_resolution_s: float = 0.0
    epoch_s: float = 0.0
    clock_scale: float = 1.0                           #: stamped time / true time (a decoy)


def draw_hardware(rng: np.random.Generator, thrust_N: float, torque_Nmm: float, long: bool) -> Hardware:
    """A random acquisition chain for loads of the size F_o, T_o."""
    rate = 1000.0 if long else float(rng.choice([500.0, 1000.0, 1000.0, 2000.0, 2500.0]))
    coloured = str(rng.choice(["none", "ar1", "ar1", "pink", "pink", "walk"]))
    level = rng.uniform(0.004, 0.02)
    stamps = str(rng.choice(["ideal", "ideal", "jitter", "coarse", "duplicates"]))
    resolution = 0.0
    if stamps == "coarse":
        resolution = float(rng.choice([1e-3, 2e-3])) if rate >= 1000 else 4e-3
        if resolution * rate < 1.2:
            resolution = 1.5 / rate
    return Hardware(
        rate_hz=rate,
        ripple=(float(rng.uniform(0.01, 0.08)), float(rng.uniform(0.0, 0.04)), float(rng.uniform(0, 6.28)),
                float(rng.uniform(0, 6.28))),
        white=(float(rng.uniform(0.004, 0.03) * thrust_N), float(rng.uniform(0.004, 0.03) * torque_Nmm)),
        coloured=coloured, coloured_sigma=(float(level * thrust_N), float(level * torque_Nmm)),
        ar1_time_s=float(rng.uniform(0.02, 0.4)),
        mains_hz=float(rng.choice([50.0, 60.0]) + rng.uniform(-0.2, 0.2)),
        mains=(float(rng.uniform(0.0, 0.03) * thrust_N), float(rng.uniform(0.0, 0.03) * torque_Nmm)),
        filter_kind=str(rng.choice(["butter", "butter", "bessel"])), filter_order=int(rng.choice([2, 4, 6])),
        filter_fraction=float(rng.uniform(0.2, 0.45)), bits=int(rng.choice([12, 14, 16, 16])),
        range_factor=(float(rng.uniform(1.5, 6.0)), float(rng.uniform(1.5, 6.0))),
        tare=(float(rng.uniform(-3, 3)), float(rng.uniform(-10, 10))),
        stamps=stamps, stamp_resolution_s=resolution,
        epoch_s=float(1.7e9 + rng.uniform(0, 1e8)) if rng.random() < 0.2 else 0.0,
    )


def coloured_noise(rng: np.random.Generator, kind: str, n: int, sigma: float, step_s: float, ar1_time_s: float) -> np.ndarray:
    if kind == "none" or sigma == 0:
        return np.zeros(n)
    if kind == "ar1":
        phi = math.exp(-step_s / ar1_time_s)
        e = rng.normal(0.0, sigma * math.sqrt(1 - phi * phi), n)
        return signal.lfilter([1.0], [1.0, -phi], e, zi=[phi * rng.normal(0.0, sigma)])[0]
    if kind == "pink":
        f = np.fft.rfftfreq(n, step_s)
        spectrum = (rng.normal(size=f.size) + 1j * rng.normal(size=f.size)) / np.sqrt(np.maximum(f, 0.02))
        spectrum[0] = 0.0
        x = np.fft.irfft(spectrum, n)
        return sigma * x / np.std(x)
    if kind == "walk":   # a slow random walk, band-limited below 0.5 Hz
        x = np.cumsum(rng.normal(size=n))
        x = signal.sosfiltfilt(signal.butter(2, 0.5, fs=1 / step_s, output="sos"), x - np.linspace(x[0], x[-1], n))
        return sigma * x / np.std(x)
    raise ValueError(kind)


def acquire(hw: Hardware, rng: np.random.Generator, t: np.ndarray, thrust: np.ndarray, torque: np.ndarray,
            spindle_angle: np.ndarray, drift: tuple | None, extra_thrust=None, extra_torque=None) -> dict:
    """Sample the loads (fine grid ``t``) as the chain above records them: stamps [s], thrust [N],
    torque [N·mm], and the true sampling instants [s]."""
    step = float(t[1] - t[0])
    r1, r2, p1, p2 = hw.ripple
    ripple = 1 + r1 * np.sin(spindle_angle + p1) + r2 * np.sin(2 * spindle_angle + p2)
    channels = []
    for c, load in enumerate((thrust, torque)):
        x = load * ripple + hw.tare[c]
        # white noise given at the sampling rate: the fine grid's variance is scaled so that the
        # band below f_s/2 carries σ²
        x = x + rng.normal(0.0, hw.white[c] * math.sqrt((0.5 / step) / (hw.rate_hz / 2)), t.size)
        x = x + coloured_noise(rng, hw.coloured, t.size, hw.coloured_sigma[c], step, hw.ar1_time_s)
        mains_phase = float(rng.uniform(0, 2 * math.pi))
        x = x + hw.mains[c] * (np.sin(2 * math.pi * hw.mains_hz * t + mains_phase)
                               + 0.3 * np.sin(6 * math.pi * hw.mains_hz * t + 2 * mains_phase))
        if drift is not None and drift[c] is not None:
            x = x + drift[c](t)
        extra = (extra_thrust, extra_torque)[c]
        if extra is not None:
            x = x + extra
        cutoff = hw.filter_fraction * hw.rate_hz
        if hw.filter_kind == "butter":
            b, a = signal.butter(hw.filter_order, cutoff, fs=1 / step)
        else:
            b, a = signal.bessel(4, cutoff, fs=1 / step, norm="mag")
        x = signal.lfilter(b, a, x - x[0]) + x[0]
        channels.append(x)
    n = int(math.floor((t[-1] - t[0]) * hw.rate_hz))
    instants = np.arange(n) / hw.rate_hz + rng.uniform(-2e-5, 2e-5, n)
    instants = np.clip(instants, t[0], t[-1])
    out = {"instants_s": instants}
    for c, name in enumerate(("thrust_N", "torque_Nmm")):
        x = np.interp(instants, t, channels[c])
        # the range is set for the largest value the channel reaches (tare and noise included), or,
        # for a range below 1 (a saturating converter), for the largest load
        reach = float(np.max(np.abs(x))) if hw.range_factor[c] >= 1 else float(np.max(np.abs((thrust, torque)[c])))
        full = hw.range_factor[c] * max(reach, 1e-6)
        x = np.clip(x, -full, full)
        q = 2 * full / 2 ** hw.bits
        out[name] = np.round(x / q) * q
        out[name + "_range"] = full
    stamps = np.arange(n) / hw.rate_hz * hw.clock_scale
    if hw.stamps == "jitter":
        stamps = stamps + rng.uniform(-0.25, 0.25, n) / hw.rate_hz
    elif hw.stamps == "coarse":
        stamps = np.floor(stamps / hw.stamp_resolution_s) * hw.stamp_resolution_s
    out["stamps_s"] = stamps
    if hw.stamps == "duplicates":   # a few buffers written twice
        rows = np.sort(rng.choice(np.arange(10, n - 10), size=int(rng.integers(2, 8)), replace=False))
        keep = np.insert(np.arange(n), rows, rows)
        for key in ("stamps_s", "thrust_N", "torque_Nmm", "instants_s"):
            out[key] = out[key][keep]
    return out
