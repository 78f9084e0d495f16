# Copyright 2026 rubber_rig developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The online model beside a running rig, ROS-free: which parameters it runs with (:class:`ModelChoice`), the
prediction of each sample batch (:class:`OnlinePredictor`), the program block of each sample
(:class:`BlockIndex`) and the per-cycle comparison of measurement and model (:class:`CyclePairer`).
The element_model node wires these to topics and parameters.
"""
from .cycles import PROPERTY_FIELDS, CyclePairer, PairedCycle, cycle_properties
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
           'OnlinePredictor', 'PROPERTY_FIELDS', 'PairedCycle', 'SOURCES', 'batch_problem',
           'cycle_properties']
