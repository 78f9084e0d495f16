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

"""Reading a user's YAML file (parameter table, model file) with one-line errors.

A file named in a parameter may be anything: missing, a directory, unreadable, a binary file (which
``Path.read_text`` answers with a bare UnicodeDecodeError) or text that is not YAML (PyYAML's message runs over
several lines with a caret drawing). :func:`read_yaml_file` turns each into a one-line ValueError that starts
with the path, so a node can log it as one line and refuse a parameter with it.
"""
from __future__ import annotations

from pathlib import Path

import yaml


def yaml_problem(exc: yaml.YAMLError) -> str:
    """PyYAML's error as one line: 'line L, column C: problem' (its own text flattened when it has no mark)."""
    mark = getattr(exc, 'problem_mark', None)
    problem = getattr(exc, 'problem', None)
    if mark is not None and problem:
        context = getattr(exc, 'context', None)
        return f'line {mark.line + 1}, column {mark.column + 1}: {problem}' + (f' ({context})' if context else '')
    return ' '.join(str(exc).split())


def read_yaml_file(path):
    """The YAML document of the file at ``path`` (``~`` expanded; the caller says how a missing file is named).

    Raises ValueError('<path>: why') when it cannot be read, is not UTF-8 text or is not YAML; one line each.
    """
    p = Path(str(path)).expanduser()
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise ValueError(f'{p}: cannot be read ({exc.strerror or exc})') from None
    try:
        text = raw.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise ValueError(f'{p}: not a YAML text file (byte 0x{raw[exc.start]:02x} at offset {exc.start} is not '
                         'UTF-8; a binary file?)') from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f'{p}: not valid YAML ({yaml_problem(exc)})') from None
