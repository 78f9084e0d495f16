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

"""The declared sensors of a recording applied before a fit: the load cell's delay and gain, the displacement
transducer's gain, and their standard uncertainties (from the recording's rig configuration, or given).
A declared calibration is applied, not fitted: the fit's budget carries its uncertainty (fitting.budget).
"""
from __future__ import annotations

import copy
import math

import numpy as np
import yaml


def load_cell_calibration(run, delay=None, gain=None) -> tuple:
    """(delay [s], gain [-], source) for ``run``: the given values, else the recording's rig configuration
    (``load_cell_delay``, ``load_cell_gain``: the simulated rig's ``rig_config`` mapping, or the recorder's
    ``metadata.rig_configuration`` YAML/JSON text a launch file sets), else (0, 1).
    """
    cfg = _rig_config(run)
    sources = []
    if delay is None and cfg.get('load_cell_delay') is not None:
        delay = cfg['load_cell_delay']
        sources.append('recording metadata')
    if gain is None and cfg.get('load_cell_gain') is not None:
        gain = cfg['load_cell_gain']
        sources.append('recording metadata')
    given = (delay is not None or gain is not None) and not sources
    delay = 0.0 if delay is None else float(delay)
    gain = 1.0 if gain is None else float(gain)
    if not (math.isfinite(delay) and abs(delay) < 1.0):
        raise ValueError(f'{run.name}: load-cell delay must be a finite time below 1 s, got {delay!r}')
    if not (math.isfinite(gain) and gain > 0):
        raise ValueError(f'{run.name}: load-cell gain must be > 0, got {gain!r}')
    return delay, gain, 'given' if given else (sources[0] if sources else 'none')


def corrected_force(force, dt, delay, gain):
    """The specimen force from a load cell that reads gain x the force of ``delay`` s earlier:
    F(t) = F_measured(t + delay) / gain, linear interpolation; the last samples repeat the edge.
    """
    f = np.asarray(force, float)
    if delay:
        n = np.arange(f.size, dtype=float)
        f = np.interp(n + delay / dt, n, f)
    return f / gain


def declared_uncertainties(run, gain_u=None, delay_u=None, displacement_gain_u=None, temperature_u=None) -> dict:
    """{'gain_u', 'delay_u', 'displacement_gain_u', 'temperature_u'}: the standard uncertainties of the load
    cell's gain [-] and delay [s] as given, else as the recording's rig configuration declares them
    (``load_cell_gain_u``, ``load_cell_delay_u``), and of the displacement transducer's gain [-] and the
    temperature sensor [K] likewise (``displacement_gain_u``, ``temperature_u``); None where nothing is
    declared (a negative value declares nothing).
    """
    cfg = _rig_config(run)
    out = {}
    for key, given in (('gain_u', gain_u), ('delay_u', delay_u), ('displacement_gain_u', displacement_gain_u),
                       ('temperature_u', temperature_u)):
        v = given if given is not None else cfg.get(key if key.startswith(('displacement', 'temperature'))
                                                    else f'load_cell_{key}')
        try:
            v = None if v is None else float(v)
        except (TypeError, ValueError):
            v = None
        out[key] = v if v is not None and math.isfinite(v) and v >= 0 else None
    return out


def _rig_config(run) -> dict:
    meta = run.metadata or {}
    cfg = meta.get('rig_config') or meta.get('rig_configuration') or {}
    if isinstance(cfg, str):
        try:
            cfg = yaml.safe_load(cfg)
        except yaml.YAMLError:
            cfg = {}
    return cfg if isinstance(cfg, dict) else {}


def calibrate(run, delay=None, gain=None, gain_u=None, delay_u=None, **declared):
    """The run with its force divided by the known gain, and the calibration (delay, gain, their declared
    standard uncertainties or None, source). A known delay is not taken out of the data (interpolating between
    samples would filter the noise and fake a lower noise level): the fit compares the model at t - delay.
    """
    d, g, source = load_cell_calibration(run, delay, gain)
    g_x = _rig_config(run).get('displacement_gain', 1.0)
    try:
        g_x = float(g_x)
    except (TypeError, ValueError):
        g_x = math.nan
    if not (math.isfinite(g_x) and g_x > 0):
        raise ValueError(f'{run.name}: displacement gain must be > 0, got {g_x!r}')
    cal = {'delay': d, 'gain': g, 'displacement_gain': g_x, 'source': source,
           **declared_uncertainties(run, gain_u, delay_u, **declared)}
    if d == 0.0 and g == 1.0 and g_x == 1.0:
        return run, cal
    out = copy.copy(run)
    out.force = np.asarray(run.force, float) / g
    out.displacement = np.asarray(run.displacement, float) / g_x
    return out, cal
