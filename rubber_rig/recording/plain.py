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

"""plain(): rosidl messages, numpy arrays and array.array as dicts, lists and Python numbers.

Those are the forms both the dynamic CDR encoder (messages given as objects or dicts) and JSON (metadata
values) accept, so the channel table and the metadata codec share this one conversion.
"""


def plain(value):
    """``value`` with rosidl messages as dicts, arrays as lists; rosidl's byte fields (bytes objects) become
    ints/bytes.
    """
    fields = getattr(value, 'get_fields_and_field_types', None)
    if fields is not None:
        out = {}
        for name, ftype in fields().items():
            v = getattr(value, name)
            if ftype == 'octet' and isinstance(v, (bytes, bytearray)):
                v = v[0] if v else 0
            elif ftype.startswith(('sequence<octet', 'octet[')) and isinstance(v, (list, tuple)):
                v = b''.join(v)
            out[name] = plain(v)
        return out
    if isinstance(value, (bytes, bytearray)):
        return bytes(value)
    if hasattr(value, 'tolist'):
        return value.tolist()
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value
