"""What the load cell, its amplifier and the spindle add to the true loads.

- spindle ripple: loads × (1 + r1 sin φ + r2 sin 2φ), φ the spindle's own phase (the second
  harmonic is the two-flute drill's tooth-passing line);
- tare offsets: constants on each channel (a load cell that was not zeroed);
- warm-up drift: b(1 − e^{−(t + t_on)/τ_w}) on each channel, an amplifier warming up since
  it was switched on t_on before the recording started;
- noise: white, plus an AR(1) process (correlation time τ_c) or 1/f (pink) noise above
  0.05 Hz, each with its own standard deviation;
- quantisation: rounding to the converter's step in the unit the file is written in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from bench.independent.physics import History


@dataclass(frozen=True)
class Sensor:
    rate_hz: float
    white: tuple[float, float]                 #: σ thrust [N], torque [N·mm]
    ripple: tuple[float, float, float, float]  #: r1, r2, φ1, φ2
    tare: tuple[float, float] = (0.0, 0.0)
    coloured: str = "none"                     #: "none", "ar1" or "pink"
    coloured_sigma: tuple[float, float] = (0.0, 0.0)
    ar1_time_s: float = 0.05
    warmup: tuple[float, float, float, float] | None = None  #: b_F [N], b_T [N·mm], τ_w, t_on
    quantum: tuple[float, float] = (0.0, 0.0)  #: step in the written unit: N, and N·mm or N·m
    torque_unit: str = "Nmm"


def ar1_noise(rng: np.random.Generator, n: int, sigma: float, phi: float) -> np.ndarray:
    """Stationary AR(1): x_k = φ x_{k−1} + e_k, with standard deviation σ."""
    e = rng.normal(0.0, sigma * math.sqrt(1 - phi * phi), n)
    x0 = rng.normal(0.0, sigma)
    return lfilter([1.0], [1.0, -phi], e, zi=[phi * x0])[0]


def pink_noise(rng: np.random.Generator, n: int, sigma: float, rate_hz: float, low_hz: float = 0.05) -> np.ndarray:
    """1/f noise (power ∝ 1/f above ``low_hz``, flat below), scaled to standard deviation σ."""
    f = np.fft.rfftfreq(n, 1.0 / rate_hz)
    shape = 1.0 / np.sqrt(np.maximum(f, low_hz))
    spectrum = (rng.normal(size=f.size) + 1j * rng.normal(size=f.size)) * shape
    spectrum[0] = 0.0
    x = np.fft.irfft(spectrum, n)
    return sigma * x / np.std(x)


def warmup_drift(t: np.ndarray, amplitude: float, tau_s: float, on_s: float) -> np.ndarray:
    return amplitude * (1 - np.exp(-(t + on_s) / tau_s))


def record(h: History, s: Sensor, rng: np.random.Generator, duration_s: float,
           time_scale: float = 1.0) -> dict[str, np.ndarray]:
    """Sample the history as the rig records it. ``time_scale`` ≠ 1 stamps the samples with a
    clock that runs fast or slow (a decoy): a sample taken at true time t is stamped t·scale."""
    t_true = np.arange(0.0, duration_s, 1.0 / s.rate_hz)
    thrust = np.interp(t_true, h.time_s, h.thrust_N)
    torque = np.interp(t_true, h.time_s, h.torque_Nmm)
    phase = np.interp(t_true, h.time_s, h.spindle_phase_rad)
    r1, r2, p1, p2 = s.ripple
    ripple = 1 + r1 * np.sin(phase + p1) + r2 * np.sin(2 * phase + p2)
    thrust = thrust * ripple + s.tare[0]
    torque = torque * ripple + s.tare[1]
    t = t_true * time_scale
    if s.warmup is not None:
        b_f, b_t, tau, on = s.warmup
        thrust = thrust + warmup_drift(t, b_f, tau, on)
        torque = torque + warmup_drift(t, b_t, tau, on)
    n = t.size
    thrust = thrust + rng.normal(0, s.white[0], n)
    torque = torque + rng.normal(0, s.white[1], n)
    if s.coloured == "ar1":
        phi = math.exp(-1.0 / (s.rate_hz * s.ar1_time_s))
        thrust = thrust + ar1_noise(rng, n, s.coloured_sigma[0], phi)
        torque = torque + ar1_noise(rng, n, s.coloured_sigma[1], phi)
    elif s.coloured == "pink":
        thrust = thrust + pink_noise(rng, n, s.coloured_sigma[0], s.rate_hz)
        torque = torque + pink_noise(rng, n, s.coloured_sigma[1], s.rate_hz)
    if s.torque_unit == "Nm":
        torque = torque / 1000.0
    if s.quantum[0] > 0:
        thrust = np.round(thrust / s.quantum[0]) * s.quantum[0]
    if s.quantum[1] > 0:
        torque = np.round(torque / s.quantum[1]) * s.quantum[1]
    return {"time_s": t, "thrust_N": thrust, "torque": torque}
