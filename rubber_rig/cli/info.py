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

"""Show what a recording holds: topics, message counts, duration, metadata, sample gaps and losses."""
import json

from rubber_rig.recording import load_recording
from rubber_rig.recording.qos import parse_offered_qos

LONG = 200   # metadata values longer than this (program YAML, ...) are shortened unless --full


def add_arguments(parser):
    parser.add_argument('file', help='MCAP file, or directory of split files')
    parser.add_argument('--full', action='store_true', help='print long metadata values in full')
    parser.add_argument('--json', action='store_true', help='machine-readable output')


def _short(value, full):
    text = value if isinstance(value, str) else json.dumps(value)
    if not full and len(text) > LONG:
        return text[:LONG].replace('\n', ' ') + f'... ({len(text)} chars)'
    return text


def run(args) -> int:
    rec = load_recording(args.file, allow_truncated=True)
    info = {
        'files': rec.files, 'complete': rec.complete, 'duration_s': rec.duration,
        'start_ns': rec.start_ns, 'end_ns': rec.end_ns,
        'topics': {t: {'type': v['type'], 'count': v['count'],
                       'qos': [{k: q.get(k) for k in ('history', 'depth', 'reliability', 'durability')}
                               for q in parse_offered_qos(v['qos'])]}
                   for t, v in sorted(rec.topics.items())},
        'samples': len(rec.sequence), 'sample_period_s': rec.sample_period,
        # the loss ledger (the recorder's close record and `recover` count the same way: gaps.LossLedger)
        'sequence_gaps': rec.sequence_gaps, 'samples_lost': rec.samples_lost, 'loss': rec.loss, 'gaps': rec.gaps[:20],
        'tail_unaccounted': bool(getattr(rec, 'unclosed', None)), 'unclosed': getattr(rec, 'unclosed', []),
        'metadata': rec.metadata, 'closing': rec.closing, 'other_metadata': rec.other_metadata,
        'parts': rec.parts.as_dict() if rec.parts is not None else None,
    }
    if args.json:
        print(json.dumps(info, indent=2, default=str))
        return 0
    print(f'files:      {", ".join(rec.files)}')
    if rec.unclosed:
        print('WARNING:    truncated (writer killed?): showing what is readable; '
              'run `rubber-rig recover FILE`')
    if rec.parts is not None and not rec.parts.complete:
        print(f'WARNING:    parts of this recording are MISSING ({rec.parts.samples_missing} samples'
              f'{" and more" if rec.parts.samples_unknown else ""}): see parts below')
    print(f'duration:   {rec.duration:.3f} s')
    print(f'messages:   {sum(v["count"] for v in rec.topics.values())}')
    print('topics:')
    for topic, v in info['topics'].items():
        qos = v['qos'][0] if v['qos'] else {}
        qos_text = f'  [{qos.get("reliability")}, {qos.get("durability")}, depth {qos.get("depth")}]' \
            if qos else ''
        print(f'  {topic:<28} {v["type"]:<36} {v["count"]:>8} msgs{qos_text}')
    if len(rec.sequence):
        print(f'samples:    {len(rec.sequence)} at {1 / rec.sample_period:.1f} Hz, '
              f'sequence {int(rec.sequence[0])}..{int(rec.sequence[-1])}')
    jumps = rec.loss.get('sequence_jumps', 0)
    print(f'gaps:       {rec.sequence_gaps} sequence gaps, {rec.samples_lost} samples lost'
          + (f' ({jumps} sequence jumps between programs, not loss)' if jumps else '')
          + (f' [{rec.loss["sample_topic"]}]' if rec.loss.get('sample_topic') else ''))
    if getattr(rec, 'unclosed', None):    # never a bare '0 lost' for a file whose tail is unaccounted
        for line in rec.loss_text().splitlines():
            if rec.parts is None or line not in rec.parts.lines():
                print(f'loss:       {line.strip()}')
    for line in (rec.parts.lines() if rec.parts is not None else []):   # as `recover` prints them
        print(f'parts:      {line}')
    for gap in rec.gaps[:20]:
        print(f'  expected {gap["expected"]}, got {gap["received"]} ({gap["lost"]} lost)')
    refused = [c for c in rec.closing if int(c.get('messages_refused') or 0)]
    if refused:    # forged or unsigned batches the recorder did not write (README "Who may move the rig")
        print(f'refused:    {sum(int(c["messages_refused"]) for c in refused)} messages without the rig key\'s '
              f'signature, not recorded ({"; ".join(c.get("messages_refused_by_topic", "") for c in refused)})')
    if rec.metadata:
        print('metadata:')
        for key, value in rec.metadata.items():
            print(f'  {key}: {_short(value, args.full)}')
    for i, closing in enumerate(rec.closing):
        part = closing.get('part_index', i)
        print(f'closing report of part {part}: written {closing.get("messages_written")}, '
              f'dropped {closing.get("messages_dropped")} {closing.get("dropped_by_reason") or ""}, '
              f'gaps {closing.get("sequence_gaps")} ({closing.get("samples_lost")} samples lost)')
    for name, values in rec.other_metadata.items():
        print(f'metadata record {name}: {_short(values, args.full)}')
    return 0
