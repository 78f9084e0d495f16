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

"""Settings described once: a dataclass field says its default, meaning, unit and range, and a node declares
its parameters from that description instead of repeating it.

    @dataclass
    class RigConfig:
        sample_rate: float = setting(1000.0, 'rig sample rate', units='Hz', range=(10.0, 20000.0))

settings_of(RigConfig) lists every such field (nested dataclasses marked with ``nested=`` included, with
dotted names); a field without ``setting()`` is not a parameter (a mapping built in code, a callable).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Optional

import yaml


def setting(default: Any = dataclasses.MISSING, doc: str = '', *, units: str = '', range: Optional[tuple] = None,
            choices: Optional[tuple] = None, name: str = '', yaml_text: bool = False, empty_is_none: bool = False,
            nested: Optional[type] = None, default_factory: Any = dataclasses.MISSING):
    """A dataclass field with its description. name: the parameter's dotted name where it differs from the
    field path (e.g. field 'channel' is parameter 'can.channel'); yaml_text: the parameter is a YAML string
    (a mapping or a list); empty_is_none: the parameter '' means None; nested: the field is a dataclass whose
    own settings are parameters '<field>.<name>'.
    """
    meta = {'doc': doc, 'units': units, 'range': range, 'choices': choices, 'name': name,
            'yaml_text': yaml_text, 'empty_is_none': empty_is_none, 'nested': nested}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


@dataclass(frozen=True)
class Setting:
    """One parameter: its dotted name, the field path in the dataclass tree, default (as a parameter value:
    YAML text for yaml_text settings, '' for None), description, units, range and choices.
    """

    name: str
    path: str
    default: Any
    doc: str
    units: str = ''
    range: Optional[tuple] = None
    choices: Optional[tuple] = None
    yaml_text: bool = False
    empty_is_none: bool = False

    def description(self) -> str:
        return self.doc + (f' [{self.units}]' if self.units else '')

    def value(self, parameter_value: Any) -> Any:
        """The field value for a parameter value (YAML parsed, '' -> None). ValueError names the setting."""
        if self.yaml_text:
            try:
                return yaml.safe_load(parameter_value)
            except yaml.YAMLError as exc:
                raise ValueError(f"'{self.name}': not valid YAML: {exc}") from None
        if self.empty_is_none and parameter_value == '':
            return None
        return parameter_value


def settings_of(cls: type, prefix: str = '', path: str = '') -> list[Setting]:
    """Every field of dataclass `cls` declared with setting(), depth first, nested dataclasses included."""
    out = []
    for f in dataclasses.fields(cls):
        meta = f.metadata
        if 'doc' not in meta:
            continue
        fpath = f'{path}{f.name}'
        if meta['nested'] is not None:
            out += settings_of(meta['nested'], f'{prefix}{meta["name"] or f.name}.', f'{fpath}.')
            continue
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        if meta['yaml_text']:
            default = yaml.safe_dump(default, default_flow_style=True).strip()
        elif meta['empty_is_none'] and default is None:
            default = ''
        out.append(Setting(meta['name'] or f'{prefix}{f.name}', fpath, default, meta['doc'], meta['units'],
                           meta['range'], meta['choices'], meta['yaml_text'], meta['empty_is_none']))
    return out


def nest(values: dict) -> dict:
    """{'a.b': 1, 'c': 2} -> {'a': {'b': 1}, 'c': 2}: field paths to the mapping from_dict() takes."""
    out: dict = {}
    for key, value in values.items():
        *parents, leaf = key.split('.')
        d = out
        for p in parents:
            d = d.setdefault(p, {})
        d[leaf] = value
    return out


def setting_for(settings: list[Setting], field_path: str) -> Optional[Setting]:
    """The setting a (possibly deeper, e.g. 'sim.faults[1].type') field path belongs to, or None."""
    best = None
    for s in settings:
        if field_path == s.path or field_path.startswith(s.path + '.') or field_path.startswith(s.path + '['):
            if best is None or len(s.path) > len(best.path):
                best = s
    return best


def violations(obj, path: str = '') -> list[tuple[str, str]]:
    """What in dataclass instance `obj` breaks its own description: (field path, why) for every setting whose
    value lies outside its `range` or is not one of its `choices`, nested settings included, in field order.
    The one generic check behind RigConfig.check and the nodes' parameter callbacks: a range or a set of
    choices is written once, in setting().
    """
    out = []
    for f in dataclasses.fields(obj):
        meta = f.metadata
        if 'doc' not in meta:
            continue
        value, fpath = getattr(obj, f.name), f'{path}{f.name}'
        if meta['nested'] is not None:
            out += violations(value, fpath + '.')
            continue
        why = describe_violation(meta['range'], meta['choices'], meta['units'], value)
        if why:
            out.append((fpath, why))
    return out


def describe_violation(range_: Optional[tuple], choices: Optional[tuple], units: str, value: Any) -> str:
    """Why `value` breaks a setting's range (lo, hi) or choices ('' if it does not)."""
    if choices is not None and value not in choices:
        return f"{value!r} is not one of: {', '.join(repr(c) for c in choices)}"
    if range_ is not None and value is not None and not isinstance(value, bool) and isinstance(value, (int, float)):
        lo, hi = range_
        if not lo <= value <= hi:
            unit = f' {units}' if units else ''
            return f'{value!r}{unit} outside {lo:g}..{hi:g}{unit}'
    return ''


def described(cls: type, field_path: str) -> Setting:
    """The setting of dataclass `cls` at `field_path` ('sample_rate', 'limits.velocity_max'), e.g. for a command
    line option that takes the same value and must accept the same range.
    """
    for s in settings_of(cls):
        if s.path == field_path:
            return s
    raise KeyError(f'{cls.__name__} has no setting {field_path!r}')
