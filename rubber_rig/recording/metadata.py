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

"""The names of our MCAP metadata records and channel keys, and the codec of metadata values.

MCAP metadata values are strings, but ours carry numbers, lists and dicts too (parameters, loss reports):
those are JSON-encoded and their keys listed under ``_json_keys``, which :func:`decode_metadata` reads back.
The writer, recover and the reader share this module so that names and encoding cannot drift apart.
"""
import json

from .plain import plain

METADATA_NAME = 'rubber_rig'           # self-description record written at the start of every file
CLOSE_METADATA_NAME = 'rubber_rig.close'  # loss accounting written when a file is closed
# channel metadata key: 'publication' when the MCAP message sequence is the DDS publication sequence number
# (gaps in it are messages lost in transport), 'writer' when the writer numbered the messages itself
SEQUENCE_SOURCE_KEY = 'rubber_rig.sequence'
BOOKKEEPING_TOPIC = 'recording_info'    # the records again, as a std_msgs/String message (JSON) of this name


def bookkeeping_topic(namespace: str = "") -> str:
    """Absolute topic of the bookkeeping message of a recorder in `namespace`."""
    return f'{namespace.rstrip("/")}/{BOOKKEEPING_TOPIC}'


def bookkeeping_text(metadata: dict, close_values: dict) -> str:
    """The bookkeeping message's JSON: the ``rubber_rig`` and ``rubber_rig.close`` records of a file."""
    return json.dumps(plain({METADATA_NAME: metadata, CLOSE_METADATA_NAME: close_values}), sort_keys=True)


def bookkeeping_records(text: str) -> dict:
    """{record name: values} from a bookkeeping message's JSON ({} if it is not one)."""
    try:
        records = json.loads(text)
    except ValueError:
        return {}
    if not isinstance(records, dict):
        return {}
    return {k: v for k, v in records.items() if k in (METADATA_NAME, CLOSE_METADATA_NAME) and isinstance(v, dict)}


def encode_metadata(values: dict) -> dict:
    """MCAP metadata values are strings: keep strings, JSON-encode the rest and remember which."""
    out, json_keys = {}, []
    for key, value in (values or {}).items():
        if isinstance(value, str):
            out[str(key)] = value
        else:
            out[str(key)] = json.dumps(plain(value), sort_keys=True)
            json_keys.append(str(key))
    if json_keys:
        out['_json_keys'] = ','.join(json_keys)
    return out


def decode_metadata(values: dict) -> dict:
    """Inverse of :func:`encode_metadata` (a value that is not valid JSON stays a string)."""
    values = dict(values)
    json_keys = [k for k in values.pop('_json_keys', '').split(',') if k]
    for key in json_keys:
        try:
            values[key] = json.loads(values[key])
        except (KeyError, ValueError):
            pass
    return values
