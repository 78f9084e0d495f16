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

"""List the element types a model file may use, with their parameters, units and source equations.

Examples:
  rubber-rig models                 # the element types and the named models
  rubber-rig models --json          # the same as JSON (SI units)
  rubber-rig models --show zener_berg_cubic    # a named model as a model file (YAML, SI)
A model file lists elements acting in parallel, values with units:
  elements:
    - {type: fractional_zener, k0: 12.29 kN/mm, k_inf: 14.01 kN/mm, tau: 0.043 s, alpha: 0.659}
    - {type: berg, x2: 1.41 mm, f_fmax: 4.57 kN, fixed: [x2]}
"""
from __future__ import annotations

import json
import sys

import yaml

from rubber_rig.units import UNITS


def add_arguments(parser):
    parser.add_argument('--json', action='store_true', help='machine-readable catalogue on stdout')
    parser.add_argument('--show', metavar='NAME|FILE', default=None,
                        help='print a named model, a parameter set or a model file as a model file (SI)')


def _units(dimension):
    table = UNITS.get(dimension) or {}
    return ', '.join(table) if table else 'SI number'


def run(args) -> int:
    from rubber_rig.models.catalogue import TYPES, catalogue
    from rubber_rig.models.modelfile import NAMED_MODELS, resolve_model
    if args.show:
        sys.stdout.write(yaml.safe_dump(resolve_model(args.show).to_dict(), sort_keys=False, width=110))
        return 0
    if args.json:
        out = {'element_types': catalogue(),
               'named_models': {k: {'description': d, 'elements': e} for k, (d, e) in NAMED_MODELS.items()}}
        json.dump(out, sys.stdout, indent=1)
        sys.stdout.write('\n')
        return 0
    print('element types (elements of a model file act in parallel; F = sum of their forces, seed 000 Eq. 1)')
    for t in TYPES.values():
        alias = f' (alias {", ".join(t.aliases)})' if t.aliases else ''
        print(f'\n{t.name}{alias}: {t.summary}\n  source: {t.source}')
        for p in t.params:
            flags = ' optional' if p.optional else ''
            flags += ' signed' if p.signed else ''
            print(f'  {p.name:10s} [{p.unit}]{flags}: {p.doc}; written in {_units(p.dimension)}')
        for name, doc in t.options.items():
            print(f'  {name:10s} (option, not fitted): {doc}')
    print('\noperating_point_spring: seed 004 Eq. 5/7 odd polynomial whose coefficients follow the operating point '
          '(simulation only; rubber-rig fit identifies it per block)')
    print('\nnamed models (rubber-rig fit --model NAME, rubber-rig simulate --model NAME):')
    for name, (doc, _) in NAMED_MODELS.items():
        print(f'  {name:22s} {doc}')
    print('  and every parameter set of rubber-rig props --list (e.g. swing_arm_joint_20C)')
    return 0
