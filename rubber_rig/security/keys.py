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

"""The rig's secret key: one file of 64 hex digits (32 random bytes from ``secrets``), mode 0600.

Where it is: the path given (node parameter ``auth.key_file``, CLI option ``--key-file``), else the environment
variable RUBBER_RIG_KEY_FILE, else ``$XDG_CONFIG_HOME/rubber_rig/rig.key`` (``~/.config/rubber_rig/rig.key``).
Everyone who may command the rig needs read access to it; nobody else may have it. A key file that its group or
other users can read is refused (like ssh refuses such a private key): the key would not identify the operators.
"""
from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path

KEY_ENV = 'RUBBER_RIG_KEY_FILE'
KEY_BYTES = 32


class KeyFileError(ValueError):
    """The key file is missing, readable by others, or not a key; the message names the file and the remedy."""


def default_key_path(environ=None) -> Path:
    """RUBBER_RIG_KEY_FILE if set (and not empty), else ``$XDG_CONFIG_HOME/rubber_rig/rig.key``."""
    environ = os.environ if environ is None else environ
    if environ.get(KEY_ENV):
        return Path(environ[KEY_ENV]).expanduser()
    config_home = Path(environ.get('XDG_CONFIG_HOME') or Path.home() / '.config')
    return config_home / 'rubber_rig' / 'rig.key'


def init_key(path: str | os.PathLike | None = None, overwrite: bool = False) -> Path:
    """Create a new random key file at `path` (default: default_key_path()), mode 0600, and return its path.

    An existing key is kept unless `overwrite` (every node and client of the rig must then be given the new one):
    raises FileExistsError naming it. The directory is created with mode 0700 if it does not exist.
    """
    path = Path(path).expanduser() if path else default_key_path()
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    if path.exists() and not overwrite:
        raise FileExistsError(f'key file {path} exists (keep it, or overwrite it with --force: every node and client '
                              'of the rig then needs the new one)')
    tmp = path.with_name(path.name + '.new')
    tmp.unlink(missing_ok=True)
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)   # never readable by others, not even briefly
    with os.fdopen(fd, 'w') as f:
        f.write(secrets.token_hex(KEY_BYTES) + '\n')
    os.replace(tmp, path)
    return path


def load_key(path: str | os.PathLike | None = None) -> bytes:
    """The key (32 bytes) in `path` (default: default_key_path()).

    Raises KeyFileError if the file is missing, not a regular file, readable or writable by group or others
    (mode & 0o077), or not 64 hex digits.
    """
    path = Path(path).expanduser() if path else default_key_path()
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise KeyFileError(f'no key file at {path}: create one with `rubber-rig keys init --path {path}` '
                           '(or run with auth.required false, for development only)') from None
    if not stat.S_ISREG(st.st_mode):
        raise KeyFileError(f'key file {path} is not a regular file')
    if st.st_mode & 0o077:
        raise KeyFileError(f'key file {path} has mode {stat.S_IMODE(st.st_mode):04o}: its group or other users can '
                           f'read or change it, so it does not identify the rig\'s operators; `chmod 600 {path}` '
                           '(and make a new key with `rubber-rig keys init --force` if others may have read it)')
    with open(path, encoding='ascii', errors='replace') as f:
        text = f.read(4 * KEY_BYTES).strip()
    try:
        key = bytes.fromhex(text)
    except ValueError:
        key = b''
    if len(key) != KEY_BYTES:
        raise KeyFileError(f'key file {path} does not hold a key ({2 * KEY_BYTES} hex digits); make one with '
                           '`rubber-rig keys init --force`')
    return key
