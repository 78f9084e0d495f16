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

"""Detector events from the detector to the message, into a recording and back out for the report: what an event
is put down to (cause) and the finer code are fields of DetectorEvent, also in recordings made before they were
(whose message carries them as its "[cause CAUSE/CODE]" label).
"""
import math

from mcap_ros2.writer import Writer as Ros2McapWriter

from rubber_rig.excitation.detector_specs import DEFAULTS, parse_detectors
from rubber_rig.excitation.detectors import Monitor
from rubber_rig.excitation.program import read_program
from rubber_rig.fitting.events import recorded_events
from rubber_rig.fitting.report_events import events_html
from rubber_rig.nodes import conversions as conv
from rubber_rig.recording import RecordingWriter, full_definition, load_recording
from rubber_rig.rig.sim.load_cell import LoadCellFault
from rubber_rig.session.cycle_stream import simulate

TYPE = 'msg_defs/msg/DetectorEvent'
TOPIC = '/rig/events'
PROGRAM = "name: events\nblocks:\n  - {name: sine, waveform: sine, amplitude: 0.3 mm, frequency: 10 Hz, cycles: 60}\n"


def sensor_events():
    """The events the default detectors raise on a 500 N load-cell offset jump at cycle 40 (the nodes' pipeline
    without ROS, as test_detector_diagnosis): cause sensor, code offset_jump.
    """
    program, _ = read_program(yaml_text=PROGRAM)
    _, _, stream = simulate(program, noise=20.0, load_cell=LoadCellFault('offset_jump', 4.0055, 500.0))
    monitor = Monitor(parse_detectors(list(DEFAULTS), 'default_detectors'))
    for c in stream:
        monitor.on_cycle(c)
    return monitor.events


def test_an_event_carries_its_cause_and_code_as_fields_of_the_message():
    events = sensor_events()
    assert events, 'a stuck load cell raises an event'
    e = events[0]
    assert (e.cause, e.code) == ('sensor', 'offset_jump'), e.message
    msg = conv.detector_event_msg(e, 'durability', 'block A', 12.5)
    assert (msg.cause, msg.code, msg.kind, msg.action) == ('sensor', 'offset_jump', 'load_cell', 'hold')
    assert msg.message.startswith('[cause sensor/offset_jump] ')     # people read the same in the message
    assert conv.detector_event_dict(msg)['cause'] == 'sensor'


def write_events(path, messages):
    with RecordingWriter(path, metadata={'specimen': 'events'}) as writer:
        for k, msg in enumerate(messages):
            writer.write_message(TOPIC, TYPE, msg, log_time_ns=1_000 + k)


def test_a_recording_gives_back_the_cause_and_code_and_the_report_shows_them(tmp_path):
    events = sensor_events()
    path = tmp_path / 'events.mcap'
    write_events(path, [conv.detector_event_msg(e, 'durability', 'block A', 1.0) for e in events])
    out = recorded_events(load_recording(path))
    assert [(e['cause'], e['code'], e['detector']) for e in out] == [(e.cause, e.code, e.detector) for e in events]
    page = '\n'.join(events_html(out))
    assert '<th>cause</th>' in page and '<td>sensor/offset_jump</td>' in page


def test_a_recording_from_before_the_fields_reads_them_from_the_message_label(tmp_path):
    # the schema DetectorEvent had before: the same fields but cause and code, written by an independent writer
    old_schema = '\n'.join(line for line in full_definition(TYPE).splitlines()
                           if not line.startswith(('string cause', 'string code')))
    assert 'string cause' not in old_schema and 'string message' in old_schema
    path = tmp_path / 'old.mcap'
    fields = dict(program='p', detector='load_cell', kind='load_cell', block_index=0, block_name='b', cycle=3,
                  program_cycle=3, elapsed=0.3, sequence=300, value=1.0, reference=math.nan, threshold=0.5,
                  units='N', action='hold')
    with open(path, 'wb') as f:
        writer = Ros2McapWriter(f)
        schema = writer.register_msgdef(TYPE, old_schema)
        for k, message in enumerate(("[cause sensor/offset_jump] detector 'load_cell' (load_cell) ...",
                                     "[cause specimen] detector 'residual' (residual) ...",
                                     'a message with no label')):
            stamp = {'sec': 0, 'nanosec': k}
            writer.write_message(TOPIC, schema, {'header': {'stamp': stamp, 'frame_id': ''}, **fields,
                                                 'message': message}, log_time=1_000 + k)
        writer.finish()
    out = recorded_events(load_recording(path))
    assert [(e['cause'], e['code']) for e in out] == [('sensor', 'offset_jump'), ('specimen', ''), ('', '')]
