"""The catalogue of mechanisms a simulation may leave out: one module each, registered where defined.

Every mechanism acts on the forward model (:mod:`femstudy.diagnosis.model`) through one *role*:

    y_c(t) = g_c · H_c(t) · P_c(t) · U_c(τ'(t)) + A_c(t) + tare_c

- ``LOAD``: adds to the cutting load, U_c = S_c(τ') + ΔU_c (chip clogging);
- ``FEED``: modulates the feed: the loads by P_c = 1 + m_c(t) in contact and the depth by a lead
  δ(t) = ∫ m dt, so the simulation is read at τ' = t − Δt + δ (feed pulsation);
- ``GAIN``: multiplies the loads in contact, H_c = 1 − s_c(t) (thermal softening);
- ``SENSOR``: adds to a channel over the whole record, A_c (sensor drift).

A mechanism object (:class:`Mechanism`) says which role it plays, which parameters it has
(bounds, starting values, which count against it only when active), its term and the term's
derivatives at given parameters, its size in the units of its floor, the signature tests that tell
it from the other mechanisms and from causes outside the catalogue, and its physical reading.
Adding a mechanism is one new module in this package that calls :func:`register`; the modules are
imported when the package is.
"""

from femstudy.diagnosis.catalogue.registry import (FRICTION_STAYS, MECHANISMS, Check, Layout, Mechanism, Parameter,
                                                   Reading, Role, Term, Variant, in_order, names, register)
from femstudy.plugins import import_modules

__all__ = ["FRICTION_STAYS", "MECHANISMS", "Check", "Layout", "Mechanism", "Parameter", "Reading", "Role", "Term",
           "Variant", "in_order", "names", "register"]

import_modules(__name__, __path__, skip=("registry",))
