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

"""Full ROS 2 message definitions (the ``ros2msg`` schema text) for any installed message type.

rosbag2 and Foxglove expect a schema to carry the type's own ``.msg`` text followed by every type it
depends on, each introduced by a line of 80 ``=`` and ``MSG: pkg/Type``. The texts come from the
``.msg`` files that rosidl installs under ``<prefix>/share/<pkg>/msg/`` (ament index prefixes), so
this works for msg_defs, std_msgs, diagnostic_msgs, ... without importing rclpy.
"""
import json
import os
import re
import sys
from functools import lru_cache
from pathlib import Path

PRIMITIVES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring'})
SEPARATOR = '=' * 80


class MessageDefinitionError(ValueError):
    """A message type whose definition cannot be found or parsed."""


def normalize_type(msg_type: str) -> str:
    """'pkg/Type' or 'pkg/msg/Type' -> 'pkg/msg/Type' (the form ROS 2 graph and rosbag2 use)."""
    parts = msg_type.strip().split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3 and parts[0] and parts[2]:
        return msg_type.strip()
    raise MessageDefinitionError(f'not a ROS 2 message type name: {msg_type!r} (expected pkg/msg/Type)')


def type_of(msg) -> str:
    """'pkg/msg/Type' of a rosidl-generated Python message instance (no rclpy import needed)."""
    cls = type(msg)
    module = cls.__module__.split('.')  # e.g. msg_defs.msg._rig_sample_batch
    if len(module) < 2:
        raise MessageDefinitionError(f'cannot tell the ROS type of a {cls.__name__}')
    return f'{module[0]}/{module[1]}/{cls.__name__}'


def _prefixes():
    seen = []
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix and prefix not in seen:
            seen.append(prefix)
    for prefix in (os.environ.get('VIRTUAL_ENV', ''), sys.prefix):
        if prefix and prefix not in seen:
            seen.append(prefix)
    return seen


def _find_interface_file(msg_type: str, suffix: str):
    pkg, sub, name = normalize_type(msg_type).split('/')
    for prefix in _prefixes():
        candidate = Path(prefix) / 'share' / pkg / sub / f'{name}{suffix}'
        if candidate.is_file():
            return candidate
    return None


_registered: dict = {}


def register_definition(msg_type: str, text: str) -> None:
    """Make a type's own .msg text known without an installed interface package."""
    _registered[normalize_type(msg_type)] = text
    full_definition.cache_clear()


def own_definition(msg_type: str) -> str:
    """The .msg text of one type (without its dependencies)."""
    msg_type = normalize_type(msg_type)
    if msg_type in _registered:
        return _registered[msg_type]
    path = _find_interface_file(msg_type, '.msg')
    if path is None:
        raise MessageDefinitionError(
            f'no .msg file for {msg_type} under share/ of {", ".join(_prefixes()) or "(no prefix)"}; '
            'is its interface package installed and AMENT_PREFIX_PATH set?')
    return path.read_text()


def dependencies(msg_type: str, text: str):
    """Types used by the fields of ``text`` (in field order), as 'pkg/msg/Type'."""
    pkg = normalize_type(msg_type).split('/')[0]
    deps = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        tokens = line.split()
        if len(tokens) < 2:
            raise MessageDefinitionError(f'{msg_type}: cannot parse line {line!r}')
        field_type = re.sub(r'\[.*?\]$', '', tokens[0])      # arrays: T[], T[3], T[<=5]
        field_type = re.sub(r'<=\d+$', '', field_type)       # bounded strings: string<=10
        if field_type in PRIMITIVES:
            continue
        if field_type == 'Header':                           # ROS 1 style shorthand
            field_type = 'std_msgs/Header'
        dep = normalize_type(field_type if '/' in field_type else f'{pkg}/{field_type}')
        if dep not in deps:
            deps.append(dep)
    return deps


@lru_cache(maxsize=None)
def full_definition(msg_type: str) -> str:
    """The concatenated ros2msg schema text: the type's definition, then each dependency once."""
    msg_type = normalize_type(msg_type)
    parts = [own_definition(msg_type).rstrip('\n')]
    seen = {msg_type}
    stack = list(reversed(dependencies(msg_type, parts[0])))
    while stack:                                              # depth first, like rosbag2
        dep = stack.pop()
        if dep in seen:
            continue
        seen.add(dep)
        text = own_definition(dep).rstrip('\n')
        pkg, _, name = dep.split('/')
        parts.append(f'{SEPARATOR}\nMSG: {pkg}/{name}\n{text}')
        stack.extend(reversed(dependencies(dep, text)))
    return '\n'.join(parts) + '\n'


@lru_cache(maxsize=None)
def type_hash(msg_type: str) -> str:
    """The RIHS01 type description hash rosidl generated for the type, or '' if not installed."""
    msg_type = normalize_type(msg_type)
    path = _find_interface_file(msg_type, '.json')
    if path is None:
        return ''
    try:
        for entry in json.loads(path.read_text()).get('type_hashes', []):
            if entry.get('type_name') == msg_type:
                return entry.get('hash_string', '')
    except (OSError, ValueError):
        return ''
    return ''
