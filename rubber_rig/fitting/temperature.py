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

"""Which temperature the specimen really had: the metadata, the temperature channel and the model compared.

A recording can state its temperature three ways: the metadata (a label someone typed, or the chamber's set
point), the temperature channel (a sensor on the specimen, standard uncertainty ``temperature_u`` from the rig
configuration) and, for a model with fixed parameters, the temperature those values belong to (the model
file's ``temperature``). Rubber moves about 1.5 %/K (seed 000 Table 1: tau -28 %, alpha +21 % from 20 to
0 degC), so a wrong label publishes the right numbers under the wrong temperature.

Rules (:func:`resolve`):

* the channel is the measurement and wins when it has samples: its value is the median over the record, its
  standard uncertainty the root sum of squares of the declared sensor uncertainty and the channel's own
  standard deviation over the record (a specimen heating during the test is not at one temperature);
* the metadata's standard uncertainty is its ``temperature_u`` if the metadata states one, else
  ``LABEL_U`` (a label to the nearest degree or so);
* two statements disagree when they differ by more than ``COVERAGE`` combined standard uncertainties (and by
  more than ``MIN_DIFFERENCE``, below which no rubber parameter moves measurably): a warning
  ``temperature_disagrees`` names both values and says which one the fit used;
* ``--temperature`` on the command line overrides both and is said to.
"""
from __future__ import annotations

import math

import numpy as np

LABEL_U = 0.5            # [K] standard uncertainty of a metadata temperature that states none
COVERAGE = 3.0           # combined standard uncertainties before two statements disagree
MIN_DIFFERENCE = 1.0     # [K] smaller differences are not worth a warning


def channel_statistics(channel) -> tuple:
    """(median [degC], standard deviation [K], samples) of a temperature channel; (None, None, 0) if empty."""
    if channel is None:
        return None, None, 0
    c = np.asarray(channel, float)
    c = c[np.isfinite(c)]
    if not c.size:
        return None, None, 0
    return float(np.median(c)), float(np.std(c)), int(c.size)


def resolve(metadata_temperature, channel, sensor_u=None, metadata_u=None, override=None) -> dict:
    """The temperature of one recording and where it came from.

    Parameters
    ----------
    metadata_temperature : float or None
        The metadata's temperature [degC].
    channel : array_like or None
        The temperature channel's samples [degC], shape (n,).
    sensor_u : float or None
        Declared standard uncertainty of the temperature sensor [K] (rig configuration ``temperature_u``).
    metadata_u : float or None
        Standard uncertainty the metadata states for its temperature [K] (default ``LABEL_U``).
    override : float or None
        A temperature given by the user (``rubber-rig fit --temperature``), which wins.

    Returns
    -------
    dict
        {'value', 'source' ('override', 'channel', 'metadata' or None), 'u' [K], 'metadata', 'metadata_u',
        'channel', 'channel_u', 'channel_std', 'disagreement' (None or {'difference', 'sigmas', 'limit'})}.
    """
    median, std, n = channel_statistics(channel)
    channel_u = None if median is None else math.hypot(sensor_u or 0.0, std)
    meta_u = LABEL_U if metadata_u is None else float(metadata_u)
    out = {'metadata': metadata_temperature, 'metadata_u': None if metadata_temperature is None else meta_u,
           'channel': median, 'channel_u': channel_u, 'channel_std': std, 'channel_samples': n,
           'disagreement': None}
    if metadata_temperature is not None and median is not None:
        out['disagreement'] = compare(metadata_temperature, meta_u, median, channel_u)
    if override is not None:
        out.update(value=float(override), source='override', u=sensor_u)
    elif median is not None:
        out.update(value=median, source='channel', u=channel_u)
    elif metadata_temperature is not None:
        out.update(value=float(metadata_temperature), source='metadata', u=meta_u)
    else:
        out.update(value=None, source=None, u=None)
    return out


def compare(a: float, u_a: float, b: float, u_b: float) -> dict | None:
    """{'difference' [K], 'sigmas', 'limit' [K]} when ``a`` and ``b`` (standard uncertainties ``u_a``, ``u_b``)
    disagree (module docstring), else None.
    """
    combined = math.hypot(u_a or 0.0, u_b or 0.0)
    limit = max(COVERAGE * combined, MIN_DIFFERENCE)
    difference = float(a) - float(b)
    if abs(difference) <= limit:
        return None
    return {'difference': difference, 'sigmas': abs(difference) / combined if combined > 0 else math.inf,
            'limit': limit}


def temperature_sentences(record: dict, model_temperature=None, fixed=(), recording: str = '') -> list:
    """Warning sentences of one recording's temperature ``record`` (:func:`resolve`); ``model_temperature``
    [degC] of a model whose ``fixed`` parameters keep their values (those values belong to it).
    """
    out = []
    where = f'{recording}: ' if recording else ''
    used = {'channel': 'the channel', 'metadata': 'the metadata', 'override': 'the --temperature given'}
    d = record.get('disagreement')
    if d:
        out.append(f'{where}the metadata says {record["metadata"]:g} degC (+-{record["metadata_u"]:.2g} K) but the '
                   f'temperature channel reads {record["channel"]:.3g} degC (+-{record["channel_u"]:.2g} K): '
                   f'{abs(d["difference"]):.3g} K apart, beyond {d["limit"]:.2g} K; the fit used '
                   f'{used.get(record["source"], "neither")} ({record["value"]:.3g} degC); rubber moves about '
                   '1.5 %/K, so check the label and the sensor')
    if model_temperature is not None and fixed and record.get('value') is not None:
        u = record.get('u') or 0.0
        d = compare(model_temperature, 0.0, record['value'], u)
        if d:
            out.append(f'{where}the model\'s fixed parameters ({", ".join(fixed)}) belong to {model_temperature:g} '
                       f'degC, the recording to {record["value"]:.3g} degC ({used.get(record["source"])}): the fixed '
                       'values are used at the wrong temperature; free them or give the model at this temperature')
    return out
