"""Named distributions and the uncertain inputs a case may name: the vocabulary the case file
(``[uncertainty]``, :class:`femstudy.casefile.UncertaintySpec`) and the uncertainty study
(:mod:`femstudy.uncertainty.inputs`, which gives each input its default) share.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Distribution:
    """A named distribution: ``normal`` (mean, sd), ``lognormal`` (median, sigma_ln: the SD of
    the logarithm), ``uniform`` (low, high), ``discrete`` (equally likely values) or ``fixed``
    (value); ``source`` says where it comes from."""

    kind: str
    params: tuple
    source: str

    def frozen(self):
        """The scipy.stats distribution (None for ``fixed``). scipy.stats is imported here, not
        at module level: every case file reads this module's INPUTS, and scipy.stats costs
        ~0.5 s of start-up that only an uncertainty study needs."""
        from scipy import stats

        if self.kind == "normal":
            return stats.norm(self.params[0], self.params[1])
        if self.kind == "lognormal":
            return stats.lognorm(self.params[1], scale=self.params[0])
        if self.kind == "uniform":
            return stats.uniform(self.params[0], self.params[1] - self.params[0])
        return None

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Values at the quantiles ``u`` in (0, 1): how a unit-cube sample becomes inputs."""
        if self.kind == "fixed":
            return np.full(np.shape(u), float(self.params[0]))
        if self.kind == "discrete":
            k = np.minimum((np.asarray(u) * len(self.params)).astype(int), len(self.params) - 1)
            return np.asarray(self.params, float)[k]
        return self.frozen().ppf(np.clip(u, 1e-12, 1 - 1e-12))

    def describe(self) -> str:
        """One line: kind and parameters."""
        if self.kind == "discrete":
            return "discrete(" + ", ".join(f"{p:.4g}" for p in self.params) + ")"
        names = {"normal": ("mean", "sd"), "lognormal": ("median", "sigma_ln"), "uniform": ("low", "high"),
                 "fixed": ("value",)}[self.kind]
        return f"{self.kind}(" + ", ".join(f"{n}={p:.4g}" for n, p in zip(names, self.params)) + ")"

    def as_dict(self) -> dict:
        return {"distribution": self.kind, "parameters": [float(p) for p in self.params],
                "description": self.describe(), "source": self.source}


@dataclass(frozen=True)
class Input:
    """An uncertain input: its name (with its unit), kind ("load" or "stiffness") and what it is."""

    name: str
    kind: str
    label: str


INPUTS = {i.name: i for i in (
    Input("mu_f_factor", "load", "flute-chip friction mu_f / law value"),
    Input("mu_w_factor", "load", "chip-wall friction mu_w / law value"),
    Input("cutting_force_factor", "load", "initial cutting force F_o / nominal"),
    Input("feed_mm_s", "load", "feed [mm/s]"),
    Input("spindle_rpm", "load", "spindle speed [rpm]"),
    Input("depth_mm", "load", "drilled cortex [mm]"),
    Input("cortical_modulus_factor", "stiffness", "cortical modulus / Table 3-1"),
    Input("cancellous_modulus_factor", "stiffness", "cancellous modulus / Table 3-1"),
    Input("clamp_length_mm", "stiffness", "clamped length at each end [mm]"),
)}
LOAD_INPUTS = tuple(n for n, i in INPUTS.items() if i.kind == "load")
STIFFNESS_INPUTS = tuple(n for n, i in INPUTS.items() if i.kind == "stiffness")
