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

"""A raw CAN log against the MCAP recording of the same run (``rubber-rig canlog LOG --recording DIR``).

The samples are joined on their sequence number: the ones in both must agree to the DBC's resolution; the ones
only in the log are missing from the recording (recorder loss, a missing part), the ones only in the recording
are missing from the log (a skipped line, a truncated log). The log's time is compared with the recording's
sample stamps: the offset between them and its spread; where the log's own time steps back or jumps
(canlog_time), the comparison says so and names the place, rather than reporting it as a clock offset of the rig.
"""
from __future__ import annotations

import numpy as np

DISPLACEMENT_RESOLUTION = 1e-7   # [m] the DBC's displacement resolution (0.1 um)
FORCE_RESOLUTION = 0.01          # [N] the DBC's force resolution


def compare_with_recording(log, rec) -> dict:
    """The comparison of a CanLog ``log`` and a Recording ``rec`` (see module doc), JSON-able. Displacements and
    forces [m, N]; times [s].
    """
    common, in_log, in_rec = np.intersect1d(log.sequence, rec.sequence, return_indices=True)
    only_log = np.setdiff1d(log.sequence, rec.sequence)
    only_rec = np.setdiff1d(rec.sequence.astype(np.int64), log.sequence)
    out = {'samples_log': int(len(log)), 'samples_recording': int(len(rec)), 'samples_both': int(common.size),
           'only_in_log': int(only_log.size), 'only_in_recording': int(only_rec.size),
           'first_only_in_log': int(only_log[0]) if only_log.size else None,
           'first_only_in_recording': int(only_rec[0]) if only_rec.size else None,
           'time_ok': bool(log.time_ok), 'time_backwards': int(log.time_backwards), 'time_jumps': int(log.time_jumps),
           'time_anomalies': [a.as_dict() for a in log.time_anomalies]}
    if common.size:
        dx = np.abs(log.displacement[in_log] - rec.displacement[in_rec])
        df = np.abs(log.force[in_log] - rec.force[in_rec])
        offset = (rec.time_ns[in_rec] - log.time_ns[in_log]) * 1e-9     # recording stamp - log time [s]
        out.update(max_displacement_difference=float(dx.max()), max_force_difference=float(df.max()),
                   values_agree=bool(dx.max() <= DISPLACEMENT_RESOLUTION and df.max() <= FORCE_RESOLUTION),
                   time_offset_median=float(np.median(offset)),
                   time_offset_spread=float(np.percentile(offset, 99) - np.percentile(offset, 1)))
    return out


def comparison_lines(c: dict) -> list:
    """The comparison in words, one finding per line."""
    lines = [f"samples:    {c['samples_both']} in both, {c['only_in_log']} only in the log"
             + (f" (from sequence {c['first_only_in_log']}: missing from the recording)" if c['only_in_log'] else '')
             + f", {c['only_in_recording']} only in the recording"
             + (f" (from sequence {c['first_only_in_recording']}: missing from the log)" if c['only_in_recording']
                else '')]
    if c['samples_both']:
        agree = 'agree' if c['values_agree'] else 'DIFFER'
        lines.append(f"values:     {agree}: displacement up to {c['max_displacement_difference'] * 1e6:.3f} um, force "
                     f"up to {c['max_force_difference']:.3f} N apart")
        lines.append(f"time:       recording stamps - log time: median {c['time_offset_median'] * 1e3:.3f} ms, "
                     f"spread (99th - 1st percentile) {c['time_offset_spread'] * 1e3:.3f} ms")
    if not c['time_ok']:
        places = '; '.join(f"frame {a['frame']}" + (f" (line {a['line']})" if a['line'] is not None else '')
                           + f": {a['kind']} {a['step']:+.6g} s" for a in c['time_anomalies'][:3])
        lines.append(f"WARNING:    the log's time goes backwards {c['time_backwards']} times and jumps "
                     f"{c['time_jumps']} times ({places}): the offset and spread measured across these places are "
                     "the log's damage, not the rig's clock")
    return lines
