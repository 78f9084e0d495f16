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

"""Identification of rubber-element parameters from recordings (pure Python, no rclpy).

data            recordings as arrays: MCAP (rubber_rig.recording), rig runs, plain arrays; missing channels
blocks          split a recording into blocks (block index channel, or detected steady periodic segments),
                skip settling cycles, measure frequency, amplitude, mean, K_dyn, loss angle, D, energy, C_eq
modelfit        any model (rubber_rig.models.modelfile): first-harmonic global search, time-domain least
                squares against the load-cell noise, noise and block-jackknife covariances
timefit         the displacement the time-domain fit runs its model on (low-pass, Berg deadband)
identification  recordings -> one fit per temperature: calibration, quasi-static windows, block quality,
                model comparison (BIC, AIC beside it)
noise           the white noise of a channel with the blocks' excitation harmonics removed (every band, every rate)
misfit          the two-sided chi^2 test against that noise and its one statement (CLI, JSON, model file, report)
verdict         the warnings and notes of a fit (misfit, per-block errors, trends, identifiability, delay)
extrapolation   the measured band as a limit: which parameters the model's shape carries beyond it
temperature     metadata, temperature channel and model temperature compared; which one the fit used
diagnoses       non-stationarity, outliers and saturation, each named
table           fits from a CSV of K_dyn / C_eq; blocktrend: seed 004's per-block fit and its trend
paramfile       seed-000 parameter tables (the shipped sets, older fit output) for reports
report          PNG figures + self-contained HTML (seed 000 Fig. 4-7 style)
simulate        simulated-rig MCAP recordings for tests, benchmarks and demos

Design decisions (the figures behind them: benchmarks/bench_fitting.py and the README's fitting section):
* Eq. 24 is not what a rig measures. Seed 000 combines Berg's element through an equal-peak,
  equal-energy ellipse (Eq. 19-22); the first harmonic of the real Berg loop has a different storage
  stiffness (the energy, C_eq, is exact either way). The difference grows as the temperature falls and
  fitting first-harmonic data with Eq. 24 would bias K0, x2 and F_fmax, so the objective uses the
  exact first harmonic of the Berg loop (rubber_rig.models.catalogue), by quadrature.
* Eq. 29 alone (method 'harmonic') identifies all six parameters from K_dyn and C_eq at two
  amplitudes; x2 and F_fmax are the most correlated pair (their ratio, the initial friction stiffness,
  is what the data pin down). The time-domain refinement (method 'time', default) then runs the model
  over the measured displacement, so it sees exactly what the specimen saw (history across blocks,
  unsettled friction, actuator distortion) instead of ideal steady sines, and it runs the same
  fractional scheme as the node suite's online model, so its parameters are the ones that make that
  model reproduce the rig.
* The time-domain fit needs care with the input: displacement noise makes Berg's element see spurious
  reversals (a large bias in x2, F_fmax); `timefit.model_input` low-passes and sets the model's Berg
  reversal deadband at the noise-sized reversals.
* `rubber_rig.analysis.harmonic_properties` includes a linear drift column; over N cycles of a
  non-sinusoidal loop it leaks odd harmonics into F1 in proportion to 1/N. Measured and simulated
  blocks go through the same function, so the comparison is consistent.
"""
