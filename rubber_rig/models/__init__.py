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

"""Rubber-element models (pure numpy/scipy; never imports rclpy).

* :func:`build_model` -> a :class:`ParallelModel` with ``step`` (streaming), ``run`` (batch), state
  save/restore and per-branch forces; ready models 'fractional_zener_berg' (seed 000: fractional Zener + Berg,
  6 parameters), 'tangent_maxwell_berg' (seed 001: tangent spring + 2 Maxwell + Berg), 'kelvin_voigt', or any
  parallel composition. One model system: every source (parameter set, temperature, values, model file) is
  built through the :class:`.modelfile.ModelSpec` it describes, from the element catalogue (:mod:`.catalogue`);
  the parameter dataclasses are the tables' data. REFERENCES.md names the papers ("seed 000" ...).
* :func:`steady_state_properties`: analytic K_dyn, loss angle, D, C_eq, E, R_K, R_E (seed 000 Eq. 11-30).
* Parameter sets: :func:`load_parameter_set`, :func:`parameter_set_info`, :func:`list_parameter_sets`,
  :func:`parameters_at_temperature`.

The fractional operator's default scheme and its error bound are documented in :mod:`.fractional`.
"""
from .composite import (
                        ParallelModel,
                        build_model,
                        resolve_params,
                        tangent_maxwell_berg_model,
                        zener_berg_model,
)
from .elements import (
                       Dashpot,
                       FractionalZener,
                       FractionalZenerGL,
                       LinearSpring,
                       Maxwell,
                       PolynomialSpring,
                       TangentSpring,
                       TwoOrderFractional,
                       Zener,
)
from .fractional import gl_complex_stiffness, two_order_complex_stiffness, zener_complex_stiffness, zener_storage_loss
from .friction import BergFriction, SmoothCoulomb, berg_force, berg_steady_state
from .params import (
                       MODEL_ALIASES,
                       PARAM_CLASSES,
                       KelvinVoigtParams,
                       TangentMaxwellBergParams,
                       ZenerBergParams,
                       canonical_model,
                       list_parameter_sets,
                       load_parameter_set,
                       model_class,
                       parameter_set_info,
                       parameters_at_temperature,
                       read_parameter_file,
                       sets_with_aliases,
)
from .simulate import sine_displacement, time_domain_properties
from .steady_state import steady_state_properties

__all__ = [
    'ParallelModel', 'build_model', 'resolve_params', 'zener_berg_model', 'tangent_maxwell_berg_model',
    'Dashpot', 'FractionalZener', 'FractionalZenerGL', 'LinearSpring', 'Maxwell', 'PolynomialSpring',
    'TangentSpring', 'TwoOrderFractional', 'Zener', 'BergFriction', 'SmoothCoulomb',
    'gl_complex_stiffness', 'two_order_complex_stiffness', 'zener_complex_stiffness', 'zener_storage_loss',
    'berg_force', 'berg_steady_state',
    'KelvinVoigtParams', 'ZenerBergParams', 'TangentMaxwellBergParams',
    'PARAM_CLASSES', 'MODEL_ALIASES', 'canonical_model', 'model_class', 'list_parameter_sets', 'load_parameter_set',
    'parameter_set_info', 'sets_with_aliases', 'parameters_at_temperature', 'read_parameter_file',
    'steady_state_properties', 'sine_displacement', 'time_domain_properties',
]
