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

"""Authenticated commands and samples, in the manner of MAVLink 2 message signing (ROS-free).

Everyone on a DDS domain can publish on any topic and call any service; a node name is not an identity (ROS 2
allows duplicates). What the rig trusts instead is knowledge of the rig's secret key (keys.py: a file readable by
the rig's operators only, never on the wire): a command or a sample batch carries an HMAC-SHA256 tag over a
canonical encoding of its content (signing.py), and a receiver that does not find the tag it computes refuses it.

- keys.py: create (``rubber-rig keys init``) and load the key file; a group- or world-readable one is refused.
- signing.py: the canonical encoding, Signer (per-link monotonic counter) and Verifier (replay window, refusals
  counted by purpose and by the channel they came on).
"""
from .keys import KEY_ENV, KeyFileError, default_key_path, init_key, load_key
from .signing import Refusal, Signer, Verifier, canonical

__all__ = ['KEY_ENV', 'KeyFileError', 'default_key_path', 'init_key', 'load_key', 'Refusal', 'Signer', 'Verifier',
           'canonical']
