"""Signal analysis of force-displacement records (pure numpy; never imports rclpy).

* :func:`harmonic_properties`: first-harmonic K_dyn and loss angle, loop energy, D (seed 000 Eq. 3),
  C_eq (Eq. 27) over whole cycles.
* :class:`CycleCutter`, :func:`cut_cycles`: the one cycle cut (upward mean crossings with hysteresis), streaming
  or over a whole array; :class:`CycleDetector`: streaming per-cycle metrics from chunks of (x, force).
"""
from .cycles import Cycle, CycleCutter, CycleDetector, cut_cycles
from .harmonic import HarmonicProperties, estimate_frequency, harmonic_properties

__all__ = ['Cycle', 'CycleCutter', 'CycleDetector', 'HarmonicProperties', 'cut_cycles', 'estimate_frequency',
           'harmonic_properties']
