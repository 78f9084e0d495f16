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

"""QoS profiles as rosbag2 stores them in the ``offered_qos_profiles`` channel metadata (ROS-free).

rosbag2 (Jazzy, metadata version 9) writes a YAML sequence, one entry per publisher, with policies as
the rmw strings (``keep_last``, ``reliable``, ...) and durations as ``{sec, nsec}``; ``ros2 bag play``
re-offers these profiles, so latched topics stay latched on replay.
"""
import yaml

INFINITE_NS = 9223372036854775807                       # RMW_DURATION_INFINITE = {9223372036, 854775807}
_HISTORY = {0: 'system_default', 1: 'keep_last', 2: 'keep_all', 3: 'unknown'}
_RELIABILITY = {0: 'system_default', 1: 'reliable', 2: 'best_effort', 3: 'unknown', 4: 'best_available'}
_DURABILITY = {0: 'system_default', 1: 'transient_local', 2: 'volatile', 3: 'unknown', 4: 'best_available'}
_LIVELINESS = {0: 'system_default', 1: 'automatic', 3: 'manual_by_topic', 4: 'unknown', 5: 'best_available'}


def _policy(value, names, default):
    if value is None:
        return default
    if isinstance(value, str):
        value = value.lower()
        if value not in names.values():
            raise ValueError(f'unknown QoS policy value {value!r}; expected one of {sorted(names.values())}')
        return value
    name = getattr(value, 'name', None)                  # rclpy enum members (ReliabilityPolicy.RELIABLE)
    if name is not None:
        return _policy(name, names, default)
    return names.get(int(value), 'unknown')


def _duration(ns):
    if ns is None or ns >= INFINITE_NS:
        return {'sec': 9223372036, 'nsec': 854775807}
    ns = int(ns)
    return {'sec': ns // 1_000_000_000, 'nsec': ns % 1_000_000_000}


def qos_entry(history=None, depth=0, reliability=None, durability=None, deadline_ns=None,
              lifespan_ns=None, liveliness=None, liveliness_lease_duration_ns=None,
              avoid_ros_namespace_conventions=False) -> dict:
    """One profile in rosbag2's layout; policies as rmw ints, names or enum members, durations in ns
    (None = infinite).
    """
    return {
        'history': _policy(history, _HISTORY, 'keep_last'),
        'depth': int(depth),
        'reliability': _policy(reliability, _RELIABILITY, 'reliable'),
        'durability': _policy(durability, _DURABILITY, 'volatile'),
        'deadline': _duration(deadline_ns),
        'lifespan': _duration(lifespan_ns),
        'liveliness': _policy(liveliness, _LIVELINESS, 'automatic'),
        'liveliness_lease_duration': _duration(liveliness_lease_duration_ns),
        'avoid_ros_namespace_conventions': bool(avoid_ros_namespace_conventions),
    }


def offered_qos_yaml(profiles) -> str:
    """YAML string for the channel metadata; ``profiles`` is a list of :func:`qos_entry` dicts
    (or keyword dicts for it). An empty list gives '' (rosbag2 then falls back to its defaults).
    """
    if isinstance(profiles, str):
        return profiles
    entries = [p if 'deadline' in p and isinstance(p['deadline'], dict) else qos_entry(**p)
               for p in (profiles or [])]
    if not entries:
        return ''
    return yaml.safe_dump(entries, default_flow_style=False, sort_keys=False)


def parse_offered_qos(text: str) -> list:
    """Inverse of :func:`offered_qos_yaml` (for `rubber-rig info` and tests)."""
    if not text:
        return []
    value = yaml.safe_load(text)
    return value if isinstance(value, list) else []


def _ns(duration) -> int:
    return int(getattr(duration, 'nanoseconds', 0))


def offered_qos(info) -> dict:
    """A publisher's endpoint info (rclpy's TopicEndpointInfo: ``qos_profile`` with rclpy's QoS fields) -> its
    rosbag2 offered_qos_profiles entry (:func:`qos_entry`).
    """
    q = info.qos_profile
    return qos_entry(history=q.history, depth=q.depth, reliability=q.reliability, durability=q.durability,
                     deadline_ns=_ns(q.deadline), lifespan_ns=_ns(q.lifespan), liveliness=q.liveliness,
                     liveliness_lease_duration_ns=_ns(q.liveliness_lease_duration),
                     avoid_ros_namespace_conventions=q.avoid_ros_namespace_conventions)
