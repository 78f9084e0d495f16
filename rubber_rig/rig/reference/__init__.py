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

"""A second controller of the rig protocol, written from the specification alone (docs/protocol.md, the DBC),
with deliberate defects behind flags: the evidence that `rubber-rig conformance` catches what a controller
written by someone else gets wrong (issue 36). Never for a rig.
"""
from .controller import ReferenceController
from .defects import REFERENCE_DEFECTS, check_reference_defects

__all__ = ['REFERENCE_DEFECTS', 'ReferenceController', 'check_reference_defects']
