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

"""Errors of the recording package: one clear message naming the file and the problem."""


class RecordingError(ValueError):
    """A recording cannot be read or written (malformed, truncated, unwritable, ...)."""


class RecordingWriteError(RecordingError):
    """Writing failed (disk full, file too large, path not writable); what was flushed stays readable."""

    def __init__(self, message: str, errno: int = 0):
        super().__init__(message)
        self.errno = errno
