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

"""The rig settings a running driver takes at once: the limits (limits.*), rest_position, stream_timeout and
stream_loss_action. Every other RigConfig setting needs a new configuration (a new bus, a new rate).

A change is checked as a whole before any of it applies: new limits must be consistent, rest_position must lie
inside the displacement limits that will be in force, and a value must be one of its setting's choices (ranges
are the parameter descriptors' to check).
"""
from dataclasses import dataclass
from typing import Optional

from ..safety import LimitError, Limits
from ..settings import describe_violation, settings_of
from .config import RigConfig

RIG_SETTINGS = settings_of(RigConfig)
LIMIT_SETTINGS = tuple(s.name for s in RIG_SETTINGS if s.name.startswith('limits.'))
LIVE_SETTINGS = set(LIMIT_SETTINGS) | {'stream_timeout', 'stream_loss_action', 'rest_position'}


def apply_live(config: RigConfig, changed: dict):
    """Apply the live settings in `changed` (setting name -> value; other names are ignored) to `config`.

    Returns (why, limits): why is '' when applied, else why nothing was; limits are the new Limits the driver is
    to take at once (RigDriver.set_limits), or None when they did not change.
    """
    lim_changes = {n.split('.', 1)[1]: float(v) for n, v in changed.items() if n.startswith('limits.')}
    try:
        limits = Limits(**dict(config.limits.to_dict(), **lim_changes)) if lim_changes else None
    except LimitError as exc:
        return str(exc), None
    rest = float(changed.get('rest_position', config.rest_position))
    lim = limits or config.limits
    if not lim.displacement_min <= rest <= lim.displacement_max:
        return f'rest_position {rest:g} m outside the displacement limits', None
    for setting in RIG_SETTINGS:                     # choices (ranges: the parameter descriptors)
        why = setting.name in changed and describe_violation(None, setting.choices, '', changed[setting.name])
        if why:
            return f'{setting.name}: {why}', None
    config.rest_position = rest
    for name in ('stream_timeout', 'stream_loss_action'):
        if name in changed:
            setattr(config, name, changed[name])
    if limits is not None:
        config.limits = limits
    return '', limits


# Which way a setting weakens the rig's protection: a higher limit or a longer timeout lets more through, a lower
# displacement_min too; rest_position is where every abort ends, so any other value than the configured one is
# a change of what an abort does. (owner_timeout is rig_driver's own parameter, judged the same way.)
HIGHER_IS_WEAKER = ('limits.displacement_max', 'limits.velocity_max', 'limits.force_max', 'limits.deceleration_max',
                    'stream_timeout', 'owner_timeout')
LOWER_IS_WEAKER = ('limits.displacement_min',)
MOVED_IS_WEAKER = ('rest_position',)
PROTECTIVE_SETTINGS = HIGHER_IS_WEAKER + LOWER_IS_WEAKER + MOVED_IS_WEAKER


def _weaker(name: str, new: float, than: float) -> bool:
    if name in HIGHER_IS_WEAKER:
        return new > than
    if name in LOWER_IS_WEAKER:
        return new < than
    return new != than


def weakening(changed: dict, current: dict, configured: dict, stream_open: bool) -> str:
    """'' when the run-time change `changed` (setting name -> value) may apply, else why it is refused.

    Anyone on the DDS domain can call a node's set_parameters; the values a rig is started with (its
    configuration file: `configured`) are the authority. At run time a protective setting (PROTECTIVE_SETTINGS:
    the limits, stream_timeout, owner_timeout, rest_position) may be made stricter by anyone, at any time; it may
    be relaxed back towards its configured value only while no stream is open (never under a running program);
    beyond its configured value, never: that takes a new configuration file and a restart of rig_driver.
    `current`: the values in force now.
    """
    for name in PROTECTIVE_SETTINGS:
        if name not in changed or name not in configured:
            continue
        new, now, conf = float(changed[name]), float(current[name]), float(configured[name])
        if _weaker(name, new, conf):
            return (f'{name}: {new:g} is beyond the configured {conf:g} rig_driver was started with; a wider '
                    'envelope or weaker supervision needs the configuration file (restart rig_driver with it)')
        if stream_open and _weaker(name, new, now):
            return (f'{name}: {new:g} would relax the {now:g} in force while a stream is open; relax it back '
                    'towards the configured value when no program runs')
    return ''


@dataclass
class ChangeVerdict:
    """What becomes of a run-time parameter change: refused (``why``; ``weakening``: by the rule that protection
    relaxes only back to the configured values) or taken, with the ``limits`` the driver is to take at once (None:
    unchanged).
    """

    why: str = ''
    weakening: bool = False
    limits: Optional[Limits] = None


def review_change(changed: dict, current: dict, configured: dict, stream_open: bool, rig_configured: bool,
                  config: Optional[RigConfig], live=LIVE_SETTINGS) -> ChangeVerdict:
    """Judge a run-time change ``changed`` (name -> value) of rig_driver's parameters (``live``: those that apply
    while the rig is configured, the node's own among them): limits and stream settings
    apply at once (tighter limits: the rig ramps into them if it must; ``config`` takes them), everything else needs
    configure, so it is refused while the rig is configured (``rig_configured``). ``current``, ``configured``: the
    protective settings now and as started; ``stream_open``: a stream runs (rig.live.weakening). ``config`` None:
    no configuration in force (configure checks all parameters together).
    """
    why = weakening(changed, current, configured, stream_open)
    if why:
        return ChangeVerdict(why, weakening=True)
    fixed = sorted(n for n in changed if n not in live)
    if fixed and rig_configured:
        return ChangeVerdict(f"{', '.join(fixed)}: applied at configure; the rig is configured (deactivate and clean "
                             'up first)')
    if config is None:
        return ChangeVerdict()
    why, limits = apply_live(config, changed)
    return ChangeVerdict(why, limits=limits)
