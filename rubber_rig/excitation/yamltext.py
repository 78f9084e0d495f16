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

"""YAML from outside (a goal, a service request, a file) read at a bounded cost.

``yaml.safe_load`` is safe from code execution, not from cost: a "billion laughs" document (aliases of aliases)
is a few hundred bytes that expand to 10^9 nodes for whoever walks the result, 5000 nested brackets recurse
through the composer for seconds before a RecursionError, and 16 MB of text take the parser most of a minute.
:func:`load_bounded` checks, before anything is built, the size of the text, then on the parser's event stream
(iterative, so depth costs nothing) the nesting depth and the number of nodes *with every alias expanded*;
only then does it construct the document. Each limit names itself in the error.
"""
from __future__ import annotations

import os
import stat

import yaml

MAX_BYTES = 512_000        # a program of 2000 blocks (the most accepted) is about 150 kB; parsed in < 0.5 s
MAX_DEPTH = 32             # a program nests 4 deep (program, blocks, block, grid list)
MAX_NODES = 100_000        # scalars and collections after alias expansion (2000 blocks: ~30 000)
_LOADER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)   # libyaml when PyYAML has it: 10x faster


class YAMLLimitError(ValueError):
    """A YAML text exceeds a limit of :func:`load_bounded` (the message names it)."""


_FILE_KINDS = ((stat.S_ISDIR, 'a directory'), (stat.S_ISFIFO, 'a FIFO (named pipe)'),
               (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'),
               (stat.S_ISSOCK, 'a socket'))


def read_bounded_file(path, what: str, max_bytes: int = MAX_BYTES) -> str:
    """The UTF-8 text of the regular file `path`, read at a bounded cost.

    A path from outside (a goal's ``program_path``) may name ``/dev/zero`` (endless), a FIFO (``open`` blocks
    until a writer comes, ``read`` until it leaves) or a file that grows while it is read; ``Path.read_text``
    would hang or grow without bound on each. Here the file is opened non-blocking (a FIFO's open returns at
    once), checked to be a regular file on the opened descriptor (no race with a rename), and read for at most
    `max_bytes` + 1 bytes whatever its size claims. Raises YAMLLimitError (a ValueError) naming `what` and the
    cause: not a regular file, too long, or not UTF-8 text; OSError when it cannot be opened.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, 'O_CLOEXEC', 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = next((name for test, name in _FILE_KINDS if test(mode)), 'not a regular file')
            raise YAMLLimitError(f'{what}: {os.fspath(path)!r} is {kind}; only regular files are read')
        claimed = os.fstat(fd).st_size
        if claimed > max_bytes:             # refused before it is read: a request stays cheap
            raise YAMLLimitError(f'{what}: {claimed} bytes, more than the {max_bytes} accepted')
        chunks, size = [], 0
        while size <= max_bytes:
            chunk = os.read(fd, min(65536, max_bytes + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    if size > max_bytes:
        raise YAMLLimitError(f'{what}: grew past {max_bytes} bytes while read, more than the {max_bytes} accepted')
    data = b''.join(chunks)
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise YAMLLimitError(f'{what}: not a text file ({exc.reason} at byte {exc.start})') from None


def load_bounded(text: str, what: str = 'YAML text', max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH,
                 max_nodes: int = MAX_NODES):
    """``yaml.safe_load(text)`` when the text is at most `max_bytes` long, nests at most `max_depth` deep and
    holds at most `max_nodes` nodes with every alias expanded; YAMLLimitError naming `what` and the limit
    otherwise (yaml.YAMLError for text that is not YAML). Cost: linear in the length of the text.
    """
    size = len(text.encode('utf-8', 'surrogatepass')) if isinstance(text, str) else len(text)
    if size > max_bytes:
        raise YAMLLimitError(f'{what}: {size} bytes, more than the {max_bytes} accepted')
    expanded, depth = 0, 0
    sizes = {}          # anchor -> nodes under it (aliases expanded)
    open_ = []          # per open collection: [nodes so far, anchor]
    for event in yaml.parse(text, Loader=_LOADER):
        if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            depth += 1
            if depth > max_depth:
                raise YAMLLimitError(f'{what}: nested more than {max_depth} deep (line {event.start_mark.line + 1})')
            open_.append([1, event.anchor])
            n = 1
        elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            depth -= 1
            count, anchor = open_.pop()
            if anchor is not None:
                sizes[anchor] = count
            if open_:
                open_[-1][0] += count
            continue
        elif isinstance(event, yaml.ScalarEvent):
            n = 1
            if event.anchor is not None:
                sizes[event.anchor] = 1
        elif isinstance(event, yaml.AliasEvent):
            n = sizes.get(event.anchor, 1)
        else:
            continue
        if open_ and not isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            open_[-1][0] += n
        expanded += n
        if expanded > max_nodes:
            raise YAMLLimitError(f'{what}: more than {max_nodes} nodes with its aliases expanded '
                                 f'(line {event.start_mark.line + 1})')
    return yaml.load(text, Loader=_LOADER)
