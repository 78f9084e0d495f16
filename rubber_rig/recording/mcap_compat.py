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

"""The private parts of mcap_ros2 this package relies on, in one place, with the version they were checked on.

mcap-ros2-support has no public API for these two jobs, so they are used from ``mcap_ros2._dynamic``:

* ``serialize_dynamic(name, text)``: a CDR encoder from a ros2msg definition, for writing messages given as
  rosidl objects or dicts. The public ``mcap_ros2.writer.Writer`` wraps it, but it also owns the file (the
  recording writer must own it to flush, split and survive write errors) and registers its channels without
  the metadata rosbag2 needs (``offered_qos_profiles``, ``topic_type_hash``);
* ``_for_each_msgdef(name, text, fn)``: the parser of a full definition (the type, then ``MSG:`` sections)
  into ``rosidl_adapter`` specifications, which the numpy CDR decoder (:mod:`.cdr`) walks. The public
  ``rosidl_adapter`` package parses one section only and is a ROS package, which the recording core must not
  need.

Checked against mcap-ros2-support :data:`CHECKED_VERSION` (with mcap 1.6.0). :func:`check_version` runs at
import and warns, without failing, when another major.minor version is installed (the names may have moved);
test/test_compat.py exercises each function against the installed package. The reference decoder comes from
the public ``mcap_ros2.decoder.DecoderFactory`` (:func:`reference_decoder`), which replaced
``_dynamic.generate_dynamic``.
"""
from __future__ import annotations

from mcap_ros2._dynamic import _for_each_msgdef, serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from rubber_rig.versions import CheckedVersion
from rubber_rig.versions import version_matches as _version_matches

PACKAGE = 'mcap-ros2-support'
CHECKED_VERSION = '0.6.0'


VERSION = CheckedVersion(PACKAGE, CHECKED_VERSION, 'rubber_rig/recording/mcap_compat.py')
installed_version = VERSION.installed
check_version = VERSION.check


def version_matches(installed: str, checked: str = CHECKED_VERSION) -> bool:
    """True when ``installed`` has the major.minor of ``checked``."""
    return _version_matches(installed, checked)


check_version()


def encoder(type_name: str, definition: str):
    """CDR encoder (message object or dict -> bytes) of ``type_name`` from its full ros2msg ``definition``."""
    return serialize_dynamic(type_name, definition)[type_name]


def reference_decoder(schema):
    """The reference decoder of an ``mcap.records.Schema`` through the public DecoderFactory (None if the
    schema is not ros2msg).
    """
    return DecoderFactory().decoder_for('cdr', schema)


def for_each_msgdef(type_name: str, definition: str, fn) -> None:
    """Call ``fn(full_name, short_name, MessageSpecification)`` for the type and each of its dependencies."""
    _for_each_msgdef(type_name, definition, fn)
