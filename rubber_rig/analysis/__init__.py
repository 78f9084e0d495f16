"""Signal analysis of force-displacement records (pure numpy; never imports rclpy).

* :func:`harmonic_properties`: first-harmonic K_dyn and loss angle, loop energy, D (seed 000 Eq. 3),
  C_eq (Eq. 27) over whole cycles.
* :class:`CycleDetector`: streaming per-cycle metrics from chunks of (x, force).
"""
from .cycles import CycleDetector
from .harmonic import HarmonicProperties, estimate_frequency, harmonic_properties

__all__ = ['CycleDetector', 'HarmonicProperties', 'estimate_frequency', 'harmonic_properties']
