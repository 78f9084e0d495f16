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


"""A process in a private mount namespace (a small tmpfs, a read-only bind): disk full and unwritable output
without touching this machine's mounts."""
import shutil
import subprocess


def private_mounts_available() -> str:
    """'' if this process may create a mount namespace and mount there (root), else why not."""
    if shutil.which('unshare') is None:
        return 'unshare(1) not installed'
    probe = subprocess.run(['unshare', '-m', '--propagation', 'private', 'sh', '-c',
                            'mount -t tmpfs -o size=64k tmpfs /mnt'], capture_output=True, text=True)
    return '' if probe.returncode == 0 else f'cannot mount in a private mount namespace: {probe.stderr.strip()}'


# The recorder runs in a private mount namespace where `mnt` is prepared by `setup`; when it ends (SIGTERM is
# passed on), what it wrote there is copied to `visible` (the mount itself vanishes with the namespace).
IN_PRIVATE_MOUNT = '''
{setup} || exit 97
"$@" &
pid=$!
trap 'kill -TERM $pid' TERM INT
wait $pid
wait $pid 2>/dev/null
cp -a {mnt}/. {visible}/ 2>/dev/null
exit 0
'''
