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

"""Which topics the recorder records, from whom, and how it subscribes to them (ROS-free: the recorder node passes
the graph's topics and publishers as plain values).

- Topics: the configured ones (fully qualified), or, with none configured, every topic under the recorder's
  namespace except /rosout, /parameter_events, a driver's command channel (``ros2 bag play`` of the recording must
  not command a rig; the same batches are recorded on ``setpoints``) and hidden topics (a name part starting with
  ``_``, e.g. actions) unless asked for.
- Publishers: every one but the recorder itself; with no topics configured only those of its namespace (a recorder
  in the root namespace would otherwise record every other suite on the domain).
- QoS: reliable only if every publisher is, transient-local only if every one is (as rosbag2 adapts its request),
  a history at least ``history_depth`` deep and as deep as any publisher's.
- Reading: the node reads all its topics at once, every ``read_period`` (one wake-up, not one per message), and
  writes what arrived in the order it arrived (:func:`in_arrival_order`), as a recorder woken per message would.
"""
from __future__ import annotations

IGNORED_TOPICS = ('/rosout', '/parameter_events')
COMMAND_CHANNEL = 'setpoint_stream'   # a name part of the drivers' command channels (nodes.topics.SETPOINT_STREAM)


def recorded_topics(graph, namespace: str, configured=(), include_hidden: bool = False) -> list:
    """The (topic, types) of ``graph`` (the graph's (topic, types) pairs) to record; ``configured``: fully qualified
    topic names (empty: the namespace's topics, see the module doc).
    """
    if configured:
        names = set(configured)
        return [(n, t) for n, t in graph if n in names]
    ns = namespace.rstrip('/') + '/'
    return [(n, t) for n, t in graph if n.startswith(ns) and n not in IGNORED_TOPICS
            and COMMAND_CHANNEL not in n.split('/')
            and (include_hidden or not any(part.startswith('_') for part in n.split('/')))]


def recorded_publishers(publishers, me: tuple, namespace: str, configured: bool) -> list:
    """The ``publishers`` (each with ``node_name`` and ``node_namespace``) whose messages are recorded: not the
    recorder ``me`` ((name, namespace)), and with no topics ``configured`` only those of its ``namespace``.
    """
    out = [p for p in publishers if (p.node_name, p.node_namespace) != tuple(me)]
    return out if configured else [p for p in out if p.node_namespace == namespace]


def subscription_qos(offered: list, history_depth: int) -> tuple[bool, bool, int]:
    """(reliable, transient_local, depth) of the subscription to a topic whose publishers offer ``offered``
    (qos.qos_entry dicts, one per publisher).
    """
    reliable = all(q['reliability'] == 'reliable' for q in offered)
    latched = all(q['durability'] == 'transient_local' for q in offered)
    return reliable, latched, max([int(history_depth)] + [int(q['depth']) for q in offered])


def in_arrival_order(per_topic) -> list:
    """``per_topic``: (key, [(message, info), ...]) per topic, each list oldest first, ``info`` a dict with the
    middleware's ``received_timestamp`` [ns]. Returns [(key, (message, info)), ...] of all topics by receive time
    (stable: a topic's own order is kept, also where its times are equal or missing).
    """
    arrived = [(info.get('received_timestamp') or 0, topic, n, key, (message, info))
               for topic, (key, taken) in enumerate(per_topic) for n, (message, info) in enumerate(taken)]
    arrived.sort(key=lambda item: item[:3])
    return [(key, taken) for *_, key, taken in arrived]
