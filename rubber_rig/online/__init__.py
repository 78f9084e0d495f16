"""The online model beside a running rig, ROS-free: which parameters it runs with (:class:`ModelChoice`), the
prediction of each sample batch (:class:`OnlinePredictor`), the program block of each sample
(:class:`BlockIndex`) and the per-cycle comparison of measurement and model (:class:`CyclePairer`).
The element_model node wires these to topics and parameters.
"""
from .cycles import CyclePairer, PairedCycle
from .predictor import (
                        DEFAULT_REVERSAL_THRESHOLD,
                        SOURCES,
                        BlockIndex,
                        ChoiceError,
                        ModelChoice,
                        OnlinePredictor,
                        batch_problem,
)

__all__ = ['BlockIndex', 'ChoiceError', 'CyclePairer', 'DEFAULT_REVERSAL_THRESHOLD', 'ModelChoice',
           'OnlinePredictor', 'PairedCycle', 'SOURCES', 'batch_problem']
