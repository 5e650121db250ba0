"""The noise model's slowest noise against known spectra (femstudy.diagnosis.noise).

Two load-free stretches of 3 s at either end of a 20 s recording at 1 kHz carry white noise plus
an AR(1) part (σ 0.5 N, τ 0.15 s: corner 1.06 Hz) or a 1/f part (σ 0.5 N above 0.02 Hz), whose
two-sided spectra are known in closed form. Below the frequencies the stretches resolve (~1 Hz)
the model must not underrate the noise (slow mechanisms would look significant) and must not
overrate it by orders of magnitude (real drifts would be hidden).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from femstudy.diagnosis.noise import fit_noise

RATE_HZ, DURATION_S, SIGMA_G = 1000.0, 20.0, 0.1
WHITE_N, COLOURED_N, TAU_S = 0.5, 0.5, 0.15
SEEDS = range(6)
t = np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)
AIR = (t < 3.0) | (t > DURATION_S - 3.0)
SLOW_HZ = np.array([0.1, 0.3])


def ar1(rng) -> tuple[np.ndarray, object]:
    phi = math.exp(-1.0 / RATE_HZ / TAU_S)
    e = rng.normal(0.0, COLOURED_N * math.sqrt(1 - phi * phi), t.size)
    x = signal.lfilter([1.0], [1.0, -phi], e, zi=[phi * rng.normal(0.0, COLOURED_N)])[0]
    return x, lambda f: 2 * COLOURED_N ** 2 * TAU_S / (1 + (2 * math.pi * f * TAU_S) ** 2)


def flicker(rng) -> tuple[np.ndarray, object]:
    f_all = np.fft.rfftfreq(t.size, 1.0 / RATE_HZ)
    spectrum = (rng.normal(size=f_all.size) + 1j * rng.normal(size=f_all.size)) / np.sqrt(np.maximum(f_all, 0.02))
    spectrum[0] = 0.0
    x = np.fft.irfft(spectrum, t.size)
    level = COLOURED_N ** 2 / (2 * np.sum(1.0 / np.maximum(f_all[1:], 0.02)) / DURATION_S)
    return COLOURED_N * x / np.std(x), lambda f: level / np.maximum(f, 0.02)


def ratios(process) -> np.ndarray:
    """Model over true two-sided spectrum at the floor of the window and at SLOW_HZ, per seed."""
    out = []
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        coloured, true = process(rng)
        x = rng.normal(0.0, WHITE_N, t.size) + coloured
        model = fit_noise(t, {"thrust_N": x}, AIR, SIGMA_G).models["thrust_N"]
        f = np.concatenate([[1.01 * model.floor_hz], SLOW_HZ])
        out.append(model.spectrum(f) / (WHITE_N ** 2 / RATE_HZ + true(f)))
    return np.array(out)


@pytest.fixture(scope="module")
def ar1_ratios() -> np.ndarray:
    return ratios(ar1)


@pytest.fixture(scope="module")
def flicker_ratios() -> np.ndarray:
    return ratios(flicker)


def test_slowest_ar1_noise_is_overrated_but_not_by_orders_of_magnitude(ar1_ratios):
    # the AR(1) spectrum is flat below 1 Hz; the model cannot see that from 3 s stretches and
    # keeps rising as 1/f: above the truth, but within two orders of magnitude (a 1/f^2
    # extrapolation gave a median of ~900 at the floor)
    assert ar1_ratios.min() >= 1.0
    assert np.median(ar1_ratios[:, 0]) <= 100.0
    assert np.median(ar1_ratios[:, 2]) <= 10.0


def test_slowest_flicker_noise_is_rated_about_right(flicker_ratios):
    # 1/f noise is what the model assumes below f_r: its median is within a factor 2 of the
    # truth, and no draw underrates it more than threefold
    assert np.all(np.abs(np.log2(np.median(flicker_ratios, axis=0))) <= 1.0)
    assert flicker_ratios.min() >= 1 / 3
