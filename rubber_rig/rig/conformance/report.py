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


"""Conformance results: one Result per requirement, as Markdown for people and JUnit XML for a lab's CI."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace

from .requirements import BY_ID, REQUIREMENTS

PASS, FAIL, NOT_TESTED = 'pass', 'fail', 'not tested'


@dataclass(frozen=True)
class Stretch:
    """The stretch [t0, t1] of the run [s, the trace's time base] a verdict judged, in `scenario`. `excess` [s]:
    for a violation that is itself a time (a ramp too long), how far it went beyond its bound; `tolerance` [s]:
    the time the requirement gives, where it is not the fixed one of host_excuse.TIME_TOLERANCE (the stated host
    timeout). A FAIL in a stretch where this host was late enough is not judged (host_excuse).
    """

    t0: float
    t1: float
    scenario: str = ''
    excess: float | None = None
    tolerance: float | None = None


@dataclass
class Result:
    """The verdict on one requirement: status (pass, fail, not tested), what was measured and why."""

    id: str
    status: str
    measured: str = ''
    detail: str = ''


def verdict(ok: bool, measured: str, detail: str = '') -> tuple:
    return (PASS if ok else FAIL, measured, detail)


class Results(dict):
    """Requirement id -> Result. A requirement judged twice keeps the worse verdict (fail over pass over not
    tested), with both measurements.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # requirement id -> the Stretch of each FAIL put (None: a FAIL that names no stretch, never excused)
        self.stretches = {}
        # callable returning the Stretch of a FAIL put without one (the scenario so far; set by the run), or None
        self.stamp = None

    def put(self, rid: str, status: str, measured: str = '', detail: str = '', stretch: Stretch | None = None):
        """Judge `rid`; a FAIL keeps `stretch` (default: self.stamp()) for host_excuse."""
        if rid not in BY_ID:
            raise KeyError(f'no requirement {rid}')
        if status == FAIL:
            if self.stamp is not None:       # the scenario so far, or the name of the scenario it is in
                default = self.stamp()
                stretch = default if stretch is None else stretch if stretch.scenario else \
                    replace(stretch, scenario=default.scenario)
            self.stretches.setdefault(rid, []).append(stretch)
        old = self.get(rid)
        new = Result(rid, status, measured, detail)
        if old is None or old.status == NOT_TESTED:
            self[rid] = new
        elif status == FAIL and old.status == PASS:
            self[rid] = Result(rid, FAIL, '; '.join(x for x in (measured, old.measured) if x), detail)
        elif status != NOT_TESTED:
            old.measured = '; '.join(x for x in (old.measured, measured) if x)

    def complete(self, scope, why: str) -> 'Results':
        """Every requirement of `scope` (ids) has a result: those never judged are 'not tested' with `why`."""
        for r in REQUIREMENTS:
            if r.id in scope and r.id not in self:
                self[r.id] = Result(r.id, NOT_TESTED, '', why)
        return self

    def ordered(self) -> list:
        return [self[r.id] for r in REQUIREMENTS if r.id in self]

    def count(self, status: str) -> int:
        return sum(1 for r in self.values() if r.status == status)

    @property
    def passed(self) -> bool:
        """True when nothing failed (requirements not tested do not fail a run; the report lists them)."""
        return self.count(FAIL) == 0


def to_markdown(results: Results, title: str, facts: list = ()) -> str:
    """A Markdown report: the facts of the run (controller identity, bus, envelope), then one row per
    requirement.
    """
    lines = [f'# {title}', '']
    lines += [f'- {fact}' for fact in facts]
    lines += [f'- **{results.count(PASS)} pass, {results.count(FAIL)} fail, {results.count(NOT_TESTED)} not '
              f'tested** of {len(results)} requirements', '',
              '| requirement | title | result | measured | detail |', '| --- | --- | --- | --- | --- |']
    for r in results.ordered():
        mark = {PASS: 'pass', FAIL: '**FAIL**', NOT_TESTED: 'not tested'}[r.status]
        cells = (r.id, BY_ID[r.id].title, mark, r.measured, r.detail)
        lines.append('| ' + ' | '.join(c.replace('|', '/') for c in cells) + ' |')
    return '\n'.join(lines) + '\n'


def to_junit(results: Results, suite: str, elapsed: float = 0.0) -> str:
    """JUnit XML: one testcase per requirement (failure / skipped elements), for a CI server."""
    root = ET.Element('testsuites')
    ts = ET.SubElement(root, 'testsuite', name=suite, tests=str(len(results)), failures=str(results.count(FAIL)),
                       skipped=str(results.count(NOT_TESTED)), errors='0', time=f'{elapsed:.3f}')
    for r in results.ordered():
        case = ET.SubElement(ts, 'testcase', classname=f'rubber_rig.protocol.{BY_ID[r.id].party}', name=r.id,
                             time='0')
        text = f'{BY_ID[r.id].title}. measured: {r.measured or "-"}. {r.detail}'.strip()
        if r.status == FAIL:
            ET.SubElement(case, 'failure', message=r.detail or r.measured or 'failed').text = text
        elif r.status == NOT_TESTED:
            ET.SubElement(case, 'skipped', message=r.detail or 'not tested')
        else:
            ET.SubElement(case, 'system-out').text = text
    ET.indent(root)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding='unicode') + '\n'
