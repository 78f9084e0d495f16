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

"""The ROS-free signing core (rubber_rig.security): key files, canonical encoding, signatures, the replay window
and refusal counting, on simulated time.
"""
import os
import stat

import numpy as np
import pytest

from rubber_rig.cli.main import main as cli
from rubber_rig.security import KeyFileError, Signer, Verifier, canonical, init_key, load_key
from rubber_rig.security.signing import MAX_CHANNELS

KEY, OTHER_KEY = bytes(range(32)), bytes(range(1, 33))
NOW = 1.8e9      # [s] simulated Unix time


def batch(seq=1000, x=(0.0, 1e-3, 2e-3), stream_id=7, end=False):
    return [('stream_id', stream_id), ('first_sequence', seq), ('displacement', np.array(x)), ('end_of_stream', end)]


class Clock:
    def __init__(self, t=NOW):
        self.t = t

    def __call__(self):
        return self.t


def test_key_file_created_private_and_refused_when_others_can_read_it(tmp_path):
    path = init_key(tmp_path / 'keys' / 'rig.key')
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert len(load_key(path)) == 32
    with pytest.raises(FileExistsError, match='exists'):
        init_key(path)
    assert load_key(init_key(path, overwrite=True)) != b''
    os.chmod(path, 0o640)
    with pytest.raises(KeyFileError, match=r'mode 0640.*chmod 600'):
        load_key(path)
    with pytest.raises(KeyFileError, match='no key file at .*rubber-rig keys init'):
        load_key(tmp_path / 'missing.key')
    bad = tmp_path / 'bad.key'
    bad.write_text('not hex')
    os.chmod(bad, 0o600)
    with pytest.raises(KeyFileError, match='does not hold a key'):
        load_key(bad)


def test_canonical_encoding_tells_apart_what_differs():
    base = canonical('setpoint_stream', '/ns/excitation', 5, batch())
    assert base == canonical('setpoint_stream', '/ns/excitation', 5, batch())           # deterministic
    others = [canonical('setpoints', '/ns/excitation', 5, batch()),                      # purpose
              canonical('setpoint_stream', '/ns/intruder', 5, batch()),                  # link
              canonical('setpoint_stream', '/ns/excitation', 6, batch()),                # counter
              canonical('setpoint_stream', '/ns/excitation', 5, batch(seq=1001)),        # content
              canonical('setpoint_stream', '/ns/excitation', 5, batch(stream_id=8)),     # stream id
              canonical('setpoint_stream', '/ns/excitation', 5, batch(end=True)),        # end of stream
              canonical('setpoint_stream', '/ns/excitation', 5, batch(x=(0.0, 1e-3))),   # length
              canonical('setpoint_stream', '/ns/excitation', 5, batch(x=(0.0, 1e-3, 2.0000000000000004e-3)))]
    assert len({base, *others}) == len(others) + 1
    # a float array and the same numbers as a list or array.array encode alike (rclpy gives either)
    assert canonical('p', 'l', 1, [('x', [1.0, 2.0])]) == canonical('p', 'l', 1, [('x', np.array([1.0, 2.0]))])
    with pytest.raises(TypeError, match='cannot sign'):
        canonical('p', 'l', 1, [('x', {'a': 1})])


def test_valid_signature_accepted_forgery_alteration_and_other_key_refused():
    clock = Clock()
    signer, verifier = Signer(KEY, '/ns/excitation', clock), Verifier(KEY, clock=clock)
    link, counter, tag = signer.sign('setpoint_stream', batch())
    assert verifier.verify('setpoint_stream', '/ch', link, counter, tag, batch()) == ''
    link, counter, tag = signer.sign('setpoint_stream', batch(seq=1003))
    assert 'bad signature' in verifier.verify('setpoint_stream', '/ch', link, counter, tag, batch(seq=1006))
    assert 'bad signature' in verifier.verify('setpoints', '/ch', link, counter, tag, batch(seq=1003))
    _, c2, forged = Signer(OTHER_KEY, link, clock).sign('setpoint_stream', batch(seq=1003))
    assert 'bad signature' in verifier.verify('setpoint_stream', '/ch', link, c2, forged, batch(seq=1003))
    assert 'unsigned' in verifier.verify('setpoint_stream', '/ch', '', 0, b'', batch())
    assert verifier.verify('setpoint_stream', '/ch', link, counter, tag, batch(seq=1003)) == ''   # the real one
    assert verifier.accepted == 2 and verifier.refused == {('setpoint_stream', '/ch'): 3, ('setpoints', '/ch'): 1}


def test_replay_window():
    clock = Clock()
    signer, verifier = Signer(KEY, '/ns/excitation', clock), Verifier(KEY, clock=clock, window=10.0)
    first = signer.sign('heartbeat', batch())
    second = signer.sign('heartbeat', batch())
    assert second[1] == first[1] + 1           # the clock stood still: the counter still grows
    assert verifier.verify('heartbeat', '/hb', *second, batch()) == ''
    assert 'replayed' in verifier.verify('heartbeat', '/hb', *first, batch())      # older than the last accepted
    assert 'replayed' in verifier.verify('heartbeat', '/hb', *second, batch())     # the same one again
    # the first message of a link must be fresh: a copy signed 11 s ago does not open a link ...
    clock.t += 11.0
    old = Signer(KEY, '/ns/recorder', Clock(NOW)).sign('heartbeat', batch())
    assert 'stale' in verifier.verify('heartbeat', '/hb', *old, batch())
    # ... while a link already open takes a delayed message (a busy receiver) as long as its counter grows
    clock.t += 60.0
    late = signer.sign('heartbeat', batch())
    clock.t += 60.0
    assert verifier.verify('heartbeat', '/hb', *late, batch()) == ''
    # replay state is kept per purpose: a setpoint batch after a later heartbeat is not a replay
    sp = signer.sign('setpoint_stream', batch())
    hb = signer.sign('heartbeat', batch())
    assert verifier.verify('heartbeat', '/hb', *hb, batch()) == ''
    assert verifier.verify('setpoint_stream', '/ch', *sp, batch()) == ''


def test_refusals_counted_by_channel_named_and_bounded():
    verifier = Verifier(KEY, clock=Clock())
    for i in range(3):
        verifier.verify('samples', '/rig/samples', '/rig/rig_driver', i, b'\0' * 32, batch())
    verifier.verify('open_stream', '/rig/rig_driver/open_stream', '', 0, b'', batch())
    lines = verifier.lines()
    assert lines['auth_refused'] == '4'
    assert lines['auth_refused_by_channel'] == ('open_stream on /rig/rig_driver/open_stream: 1, '
                                                'samples on /rig/samples: 3')
    assert lines['auth_last_refusal'].startswith('open_stream on /rig/rig_driver/open_stream (signer none) refused: '
                                                 'unsigned')
    for i in range(2 * MAX_CHANNELS):            # a forger inventing channel names cannot grow the table unbounded
        verifier.verify('heartbeat', f'/hb of /fake{i}', '', 0, b'', batch())
    assert len(verifier.refused) <= MAX_CHANNELS + 1
    assert verifier.refused_total == 4 + 2 * MAX_CHANNELS


def test_development_mode_without_key_accepts_unsigned_and_says_so():
    verifier = Verifier(None, required=False, clock=Clock())
    assert verifier.verify('samples', '/s', '', 0, b'', batch()) == ''
    assert verifier.unsigned_accepted == 1
    assert verifier.lines()['auth'].startswith('OFF')
    # a key, not required: an unsigned message passes, a forged one still does not
    lax = Verifier(KEY, required=False, clock=Clock())
    assert lax.verify('samples', '/s', '', 0, b'', batch()) == ''
    assert 'bad signature' in lax.verify('samples', '/s', '/x', int(NOW * 1e6), b'\1' * 32, batch())


def test_refusals_are_said_once_a_second_per_channel():
    clock = Clock()
    verifier = Verifier(KEY, clock=clock)
    assert verifier.due_to_say('samples', '/a') and not verifier.due_to_say('samples', '/a')
    assert verifier.due_to_say('open_stream', '/b')      # a flood on /a does not hide /b
    clock.t += 1.0
    assert verifier.due_to_say('samples', '/a')


def test_keys_command_creates_checks_and_refuses(tmp_path, capsys):
    path = tmp_path / 'rig.key'
    assert cli(['keys', 'init', '--path', str(path)]) == 0
    assert f'key written to {path} (mode 0600)' in capsys.readouterr().out
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    key = load_key(path)
    assert cli(['keys', 'init', '--path', str(path)]) == 2            # an existing key is kept
    assert 'exists' in capsys.readouterr().err and load_key(path) == key
    assert cli(['keys', 'check', '--path', str(path)]) == 0
    os.chmod(path, 0o604)
    assert cli(['keys', 'check', '--path', str(path)]) == 2
    assert 'mode 0604' in capsys.readouterr().err
    assert cli(['keys', 'init', '--path', str(path), '--force']) == 0 and load_key(path) != key
