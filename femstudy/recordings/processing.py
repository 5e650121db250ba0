"""Thesis §4.5, automated: isolate the cut, remove the sensor drift, normalise, filter.

For one recording, :func:`process` returns the cut from full engagement to breakthrough (or
retraction) as a :class:`ProcessedRun`:

- samples on a uniform time grid (linear interpolation when the recording's steps vary by
  more than 1 %);
- the sensor baselines found by :mod:`femstudy.recordings.isolation` subtracted from thrust
  and torque;
- depth past full engagement in drill diameters, z = depth / D: from the ``depth_mm`` column
  when there is one, else f·(t − t_full) (§4.5.2);
- the zero-phase low-pass of :mod:`femstudy.recordings.filtering`, applied to the isolated
  cut as in the thesis (isolate, normalise, filter), cut-off from the feed unless given.

The filtered signal is for reading the trend and for figures. The calibration fits the
unfiltered, de-drifted cut (:meth:`ProcessedRun.for_fitting`): noise, ripple and pulsation
have zero mean, while any filter must guess the signal beyond the ends of the cut.
Normalising the thrust by the initial cutting force (§4.5.2) needs F_o, which the Eq 4.8 fit
provides: :meth:`ProcessedRun.normalised_thrust`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from femstudy.drilling.drill import Drill
from femstudy.errors import require
from femstudy.recordings.filtering import default_cutoff_hz, lowpass
from femstudy.recordings.isolation import CutPhase, isolate
from femstudy.recordings.reader import Recording


@dataclass(frozen=True)
class ProcessedRun:
    """The isolated, drift-free, filtered cut of one recording.

    Arrays cover full engagement → end of cut: ``time_s`` [s], ``z`` [-], filtered
    ``thrust_N`` [N] and ``torque_Nmm`` [N·mm] (None without torque), and the unfiltered
    ``raw_thrust_N`` and ``raw_torque_Nmm`` after drift removal.
    """

    name: str
    feed_mm_s: float
    spindle_rpm: float
    drill: Drill
    phase: CutPhase
    cutoff_hz: float
    time_s: np.ndarray
    z: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray | None
    raw_thrust_N: np.ndarray
    raw_torque_Nmm: np.ndarray | None
    metadata: Mapping[str, Any] = field(default_factory=dict)

    @property
    def condition(self) -> tuple[float, float]:
        """(f [mm/s], N [rpm]) rounded to 6 significant figures, for grouping replicates."""
        return float(f"{self.feed_mm_s:.6g}"), float(f"{self.spindle_rpm:.6g}")

    def normalised_thrust(self, initial_force_N: float) -> np.ndarray:
        """F / F_o (§4.5.2)."""
        return self.thrust_N / initial_force_N

    def for_fitting(self, rate_hz: float = 50.0) -> "ProcessedRun":
        """The unfiltered cut as block means at about ``rate_hz``: what the calibration fits.

        Noise, ripple and pulsation have zero mean, so least squares needs no filter, and a
        filter's end effects (it must guess the signal beyond breakthrough) would bias the
        exponent; block means only thin the samples. ``thrust_N``/``torque_Nmm`` hold them.
        """
        n = max(1, int(round(1.0 / (rate_hz * float(np.median(np.diff(self.time_s)))))))
        m = self.time_s.size // n
        if m < 5:
            n, m = 1, self.time_s.size

        def blocks(a):
            return None if a is None else a[: m * n].reshape(m, n).mean(axis=1)

        return ProcessedRun(self.name, self.feed_mm_s, self.spindle_rpm, self.drill, self.phase, self.cutoff_hz,
                            blocks(self.time_s), blocks(self.z), blocks(self.raw_thrust_N),
                            blocks(self.raw_torque_Nmm), blocks(self.raw_thrust_N), blocks(self.raw_torque_Nmm),
                            self.metadata)


def uniform(rec: Recording) -> tuple[np.ndarray, dict[str, np.ndarray | None]]:
    """The recording on a uniform grid at its median rate (unchanged when already uniform)."""
    t = rec.time_s
    dt = float(np.median(np.diff(t)))
    channels = {"thrust": rec.thrust_N, "torque": rec.torque_Nmm, "depth": rec.depth_mm}
    if np.max(np.abs(np.diff(t) - dt)) <= 0.01 * dt:
        return t, channels
    grid = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 1)
    return grid, {k: None if v is None else np.interp(grid, t, v) for k, v in channels.items()}


def process(rec: Recording, cutoff_hz: float | None = None, contact_s: float | None = None,
            cut_end_s: float | None = None) -> ProcessedRun:
    """Isolate, de-drift, normalise the depth and filter one recording (see module docstring).

    Cut times come from the arguments, else the header's ``contact_s``/``cut_end_s``, else
    automatic detection.
    """
    drill = rec.drill
    t, ch = uniform(rec)
    fs = 1.0 / float(t[1] - t[0])
    contact_s = rec.metadata.get("contact_s") if contact_s is None else contact_s
    cut_end_s = rec.metadata.get("cut_end_s") if cut_end_s is None else cut_end_s
    phase = isolate(t, ch["thrust"], ch["torque"], rec.feed_mm_s, rec.spindle_rpm, drill.cone_length_mm,
                    contact_s=contact_s, cut_end_s=cut_end_s, name=rec.name)
    cutoff = default_cutoff_hz(rec.feed_mm_s) if cutoff_hz is None else float(cutoff_hz)
    inside = (t >= phase.full_engagement_s) & (t <= phase.end_s)
    require(np.count_nonzero(inside) >= 10, f"recording {rec.name}: fewer than 10 samples between full "
                                            f"engagement and the end of the cut")
    ts = t[inside]
    thrust = ch["thrust"][inside] - (phase.thrust_baseline[0] + phase.thrust_baseline[1] * ts)
    torque = None
    if ch["torque"] is not None:
        torque = ch["torque"][inside] - (phase.torque_baseline[0] + phase.torque_baseline[1] * ts)
    if ch["depth"] is not None:
        depth0 = np.interp(phase.full_engagement_s, t, ch["depth"])
        z = (ch["depth"][inside] - depth0) / drill.diameter_mm
    else:
        z = rec.feed_mm_s * (ts - phase.full_engagement_s) / drill.diameter_mm
    return ProcessedRun(
        name=rec.name, feed_mm_s=rec.feed_mm_s, spindle_rpm=rec.spindle_rpm, drill=drill, phase=phase,
        cutoff_hz=cutoff, time_s=ts, z=z, thrust_N=lowpass(thrust, fs, cutoff),
        torque_Nmm=None if torque is None else lowpass(torque, fs, cutoff),
        raw_thrust_N=thrust, raw_torque_Nmm=torque, metadata=dict(rec.metadata))
