"""Per-block measured properties: one code path for measurements and for time-domain model runs.

The numbers come from `rubber_rig.analysis.harmonic_properties` (first-harmonic K_dyn and loss
angle, loop-area energy, D, C_eq), so measured data and simulated model output are evaluated by
the same code. A window [start, stop) of whole cycles is passed with its closing sample (stop
inclusive), so that the loop closes on itself and all its cycles are used.
"""
from __future__ import annotations

import numpy as np

from rubber_rig.analysis import harmonic_properties as _shared


def window_properties(x, force, dt, start, stop, frequency) -> dict:
    """Properties of the whole cycles in samples [start, stop) of x and force (SI)."""
    end = min(stop + 1, len(x))
    return _shared(np.asarray(x[start:end], float), np.asarray(force[start:end], float), dt,
                   frequency=frequency).as_dict()
