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

"""element_model: predicts the element force online from the measured displacement.

Subscribes:  samples (msg_defs/RigSampleBatch), setpoints (msg_defs/SetpointBatch, only for block indices), both
             only with the rig key's signature (nodes/auth.py: refusals in /diagnostics, status ``<node>/auth``)
Publishes:   prediction (msg_defs/ModelPrediction: prediction, residual, branch forces per batch)
             cycle_metrics (msg_defs/CycleMetrics: measured and model K_dyn, loss angle, D, C_eq, energy)
             model_parameters (msg_defs/ModelParameters, latched)
QoS: see rubber_rig/nodes/topics.py.

The model is chosen by parameters (``source``): a named parameter set, a temperature, the rig's temperature
channel (re-evaluated when it moves by ``temperature_hysteresis``), or explicit values. All of them can be
changed at run time; the on-set-parameters callback validates the new choice and refuses it with a reason
naming the parameter, so a running model is never replaced by an invalid one.

``parameter_set`` may also be a model file (``parameter_set:=specimen.yaml``: a .yaml with an ``elements`` list, see
rubber_rig.models.modelfile); the node then runs that composite model, as the simulated rig runs it as its specimen
(both build every model through the element catalogue; the temperature sources and explicit values are fractional
Zener + Berg, seed 000's table, and a parameter set of another model type runs as its model file). Its prediction
carries one BranchForce per branch of the model, named as the model names it (e.g. elastic_1, viscous, friction,
elastic_2 for fractional Zener + Berg + cubic spring; their sum is the prediction), and model_parameters says
model_name = the element types ('fractional_zener + berg + polynomial_spring'), parameter_set = the file as given,
temperature = the file's ``temperature`` (NaN if none), names/values = the file's parameters in SI (bare names,
``label.param`` where a name repeats). A model file that cannot be used (missing, not YAML, unknown element type or
parameter, missing value, bad unit) is refused with a reason naming the file and the problem; the running model
stays.

``friction_reversal_threshold`` [m] is the Berg friction element's reversal deadband: the model runs on the
measured displacement, whose noise would otherwise reset the friction reference state at every wiggle and
collapse the friction loop (see rubber_rig.online.predictor). Set it to a few times the displacement noise RMS;
0 is the paper's rule. Changing it rebuilds the model (warmed up on the recent history) like a parameter change.

At start, a model choice that cannot be used (a parameter_set file that is missing, unreadable, binary, not YAML
or not a parameter table or model file; a value out of range) ends the process with one FATAL line naming the
parameter, the file and the problem, and exit status 2 - no traceback (rubber_rig.nodes.spin). The node does not
stay up without a model: it is a plain node, not a managed one, so there is no "unconfigured" state a launch file
or an operator could see or leave with a configure; a node up without a model would look healthy in ``ros2 node
list`` while predicting nothing, and the recording would silently lack the prediction. A process that dies at once,
its reason beside launch's "process has died [exit code 2]", is what a ROS user reads as "fix the parameter".

No callback takes the node down: a parameter change that cannot be resolved (a missing, binary or malformed
parameter file, values out of range) is refused through the SetParametersResult with a reason naming the
parameter (``ros2 param set`` prints it), and the running model stays - the parameter set is read in that
validating callback, and what it read is what the post-set callback installs. A
sample batch the node cannot use (array lengths differ, a sample period that is not finite and positive) is
dropped with a throttled warning; non-finite samples are skipped by the model and predicted as NaN (see
rubber_rig.online.predictor) and kept out of the cycle metrics; a sequence that goes backwards (a restarted
driver) restarts the model and the cycle detection with a log line.
"""
from __future__ import annotations

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node

from msg_defs.msg import CycleMetrics, ModelParameters, ModelPrediction, RigSampleBatch, SetpointBatch
from rubber_rig.models import load_parameter_set
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import topics
from rubber_rig.nodes.auth import SAMPLES, SETPOINTS, declare_auth, start_auth_diagnostics
from rubber_rig.nodes.draining import create_draining_subscription
from rubber_rig.nodes.heartbeat import PERIOD, start_heartbeat
from rubber_rig.nodes.params import ParameterError, declare
from rubber_rig.nodes.spin import spin_node
from rubber_rig.nodes.ticks import NodeTicks
from rubber_rig.online import (
    DEFAULT_REVERSAL_THRESHOLD,
    SOURCES,
    ChoiceError,
    ModelChoice,
    OnlinePredictor,
    batch_problem,
)
from rubber_rig.online.cutter import CycleCutter
from rubber_rig.online.predictor import CHOICE_FIELDS
from rubber_rig.recording.gaps import RESTART, StreamOrder

VALUE_NAMES = ('k0', 'k_inf', 'tau', 'alpha', 'x2', 'f_fmax')
VALUE_UNITS = {'k0': 'N/m', 'k_inf': 'N/m', 'tau': 's', 'alpha': '-', 'x2': 'm', 'f_fmax': 'N'}
VALUE_RANGES = {'k0': (1e3, 1e11), 'k_inf': (1e3, 1e11), 'tau': (1e-7, 1e4), 'alpha': (1e-3, 1.0),
                'x2': (1e-8, 1e-1), 'f_fmax': (1e-3, 1e7)}   # wide physical bounds; k_inf >= k0 is checked too
WARN_EVERY = 5.0      # [s] throttle of the warnings about bad sample batches
CHOICE_PARAMS = CHOICE_FIELDS + tuple('values.' + n for n in VALUE_NAMES)   # what a model choice is made of


class ElementModelNode(Node):

    def __init__(self, node_name: str = 'element_model', **kwargs):
        super().__init__(node_name, **kwargs)
        defaults = load_parameter_set('swing_arm_joint_20C').as_dict()
        declare(self, 'model', 'fractional_zener_berg', 'element model (fractional Zener + Berg friction, '
                'seed 000; seed000 is its earlier name); a model file or a set of another model type in '
                'parameter_set brings its own',
                choices=('fractional_zener_berg', 'seed000'), read_only=True)
        declare(self, 'source', 'parameter_set', 'where the model parameters come from', choices=SOURCES)
        declare(self, 'parameter_set', 'swing_arm_joint_20C', 'named parameter set (any model type), a parameter '
                'table FILE.yaml[:SET], or a model file (.yaml with an "elements" list; source parameter_set)')
        declare(self, 'temperature', 20.0, 'specimen temperature (source temperature; start value of '
                'rig_temperature)', range=(-40.0, 20.0), units='degC')
        for name in VALUE_NAMES:
            declare(self, 'values.' + name, defaults[name], f'explicit model parameter {name} (source values)',
                    range=VALUE_RANGES[name], units=VALUE_UNITS[name])
        declare(self, 'temperature_hysteresis', 0.5, 'rig temperature change that re-evaluates the parameters',
                range=(0.01, 20.0), units='K')
        declare(self, 'warmup_time', 5.0, 'displacement history run through a rebuilt model before it '
                'predicts', range=(0.0, 60.0), units='s')
        declare(self, 'friction_reversal_threshold', DEFAULT_REVERSAL_THRESHOLD, 'Berg friction reversal '
                'deadband: a velocity reversal counts once the measured displacement is this far back from its '
                'extreme, so sensor noise does not reset the friction reference state; about 10x the displacement '
                'noise RMS (default: 10x the simulated rig\'s 0.2 um), 0 = the paper\'s rule', range=(0.0, 1e-4),
                units='m')
        self.publish_branches = declare(self, 'publish_branches', True, 'publish per-branch forces')
        self.cycle_metrics = declare(self, 'cycle_metrics', True, 'publish per-cycle metrics')
        min_amplitude = declare(self, 'min_cycle_amplitude', 5e-6, 'cycles with a smaller displacement amplitude '
                                'are noise (rig holding still) and are not reported', range=(0.0, 1e-2), units='m')

        try:  # validate the whole choice once at start: the error names the offending parameter
            choice = self._choice()
            resolved = choice.checked(CHOICE_PARAMS)
        except ChoiceError as exc:   # spin_node logs it as one line and exits with status 2 (see the docstring)
            raise ParameterError(self, exc.field, str(exc)) from None
        self.predictor = OnlinePredictor(choice, self.get_parameter('warmup_time').value,
                                         self.get_parameter('temperature_hysteresis').value, resolved)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)

        self.cutter = CycleCutter(min_amplitude)   # cycles block by block, once their setpoints are known
        self._validated = None           # (choice, resolved) of the parameter change being set
        self.batches_dropped = 0         # sample batches refused (batch_problem)
        self.order = StreamOrder()       # a batch that went back is held until the next says restart or stray
        self.pub_prediction = self.create_publisher(ModelPrediction, topics.PREDICTION, topics.STREAM_QOS)
        self.pub_metrics = self.create_publisher(CycleMetrics, topics.CYCLE_METRICS, topics.EVENT_QOS)
        self.pub_params = self.create_publisher(ModelParameters, topics.MODEL_PARAMETERS, topics.LATCHED_QOS)
        self.auth = declare_auth(self)   # samples and setpoints must carry the rig key's signature (nodes/auth.py)
        # a backlog (a busy computer delayed this node) is read in one wake-up, not one batch per executor cycle
        self.samples_topic = create_draining_subscription(self, RigSampleBatch, topics.SAMPLES, self.on_samples,
                                                          topics.STREAM_QOS).topic_name
        # setpoints come a lead time before their samples: read before each sample batch, no wake-up of their own
        self.setpoints = create_draining_subscription(self, SetpointBatch, topics.SETPOINTS, self.on_setpoints,
                                                      topics.STREAM_QOS, polled=True)
        self.setpoints_topic = self.setpoints.topic_name
        self._published_params = None
        self.publish_parameters()
        self.ticks = NodeTicks(self, {   # one timer (nodes/ticks.py)
            'setpoints': (PERIOD, self.setpoints.drain),   # also when no samples come
            'heartbeat': (PERIOD, start_heartbeat(self, lambda: self.predictor.model_name, timer=False)),
            'diagnostics': (1.0, start_auth_diagnostics(self, self.auth))})
        choice = self.predictor.choice
        self.get_logger().info(f'model {self.predictor.model_name} from {choice.source}: {self.predictor.params}, '
                               f'friction reversal threshold {choice.friction_reversal_threshold:g} m')

    @property
    def stray_batches(self) -> int:
        """Batches that went back and were not followed: stale or foreign."""
        return self.order.strays

    # -- data path --------------------------------------------------------------------------------------------
    def on_setpoints(self, msg: SetpointBatch) -> None:
        if self.auth.refuse(self, msg, SETPOINTS, self.setpoints_topic):
            return
        self.cutter.setpoints(msg.first_sequence, len(msg.displacement), msg.block_index, msg.end_of_stream)
        self.process_cycles()

    def on_samples(self, msg: RigSampleBatch) -> None:
        """A batch with a valid signature goes to the model; a forged one is refused (counted, named in
        /diagnostics): it neither enters the prediction nor makes a cycle the detectors judge.
        """
        self.setpoints.drain()
        if not self.auth.refuse(self, msg, SAMPLES, self.samples_topic):
            self.take_samples(msg)

    def take_samples(self, msg: RigSampleBatch) -> None:
        x, f, _ = conv.batch_arrays(msg)
        problem = batch_problem(msg.first_sequence, msg.sample_period, len(x), len(f))
        if problem is not None:
            self.batches_dropped += 1
            self.get_logger().warning(f'sample batch at sequence {msg.first_sequence} dropped: {problem} '
                                      f'({self.batches_dropped} dropped so far)', throttle_duration_sec=WARN_EVERY)
            return
        if len(x) == 0:
            return
        # one batch going back is not yet a restart: the next one says (recording.gaps.StreamOrder, the rule the
        # recorder's loss ledger follows): a restarted driver's batch is followed by its own next, a stale or
        # foreign one (another publisher, a copy replayed late) by the stream it interrupted
        verdict, take = self.order.arrive(msg.first_sequence, len(x), self.predictor.next_sequence, msg)
        if verdict is not None and verdict[0] == RESTART:
            self.get_logger().info(f'sample sequence went back from {self.predictor.next_sequence} to '
                                   f'{verdict[1].first_sequence} (driver restarted?): model and cycle detection '
                                   'start afresh')
            self.predictor.restart()
            self.cutter.restart()
            self.take_samples(verdict[1])
        elif verdict is not None:
            self.get_logger().warning(f'sample batch at sequence {verdict[1].first_sequence} ignored: it went back '
                                      f'from {self.predictor.next_sequence} and the stream went on where it was '
                                      f'(stale or foreign; {self.stray_batches} so far)',
                                      throttle_duration_sec=WARN_EVERY)
        if not take:
            return
        bad = self.predictor.nonfinite_samples
        predicted, branches = self.predictor.process(msg.first_sequence, msg.sample_period, x, msg.temperature)
        bad_force = len(f) - int(np.count_nonzero(np.isfinite(f)))
        if self.predictor.nonfinite_samples > bad or bad_force:
            self.get_logger().warning(f'sample batch at sequence {msg.first_sequence}: '
                                      f'{self.predictor.nonfinite_samples - bad} non-finite displacement and '
                                      f'{bad_force} non-finite force samples of {len(x)} left out of the model and '
                                      f'the cycle metrics ({self.predictor.nonfinite_samples} displacement samples '
                                      f'so far)', throttle_duration_sec=WARN_EVERY)
        if self.predictor.params is not self._published_params:
            self.publish_parameters()
        self.pub_prediction.publish(conv.prediction_msg(
            msg, predicted, self.predictor.branch_names, branches if self.publish_branches else None))
        if self.cycle_metrics:
            self.cutter.samples(msg.first_sequence, msg.sample_period, x, f, predicted,
                                conv.to_seconds(msg.header.stamp))
            self.process_cycles()

    def process_cycles(self) -> None:
        """Publish the metrics of the cycles finished (online.cutter.CycleCutter: block by block)."""
        for c in self.cutter.cycles():
            m = c.cycle
            self.pub_metrics.publish(conv.cycle_metrics_msg(m.measured, m.model, c.block, m.index, c.t_end,
                                                            m.start_sequence, m.end_sequence, m.residual_rms))
        for why in self.cutter.error_messages:
            self.get_logger().warning(why, throttle_duration_sec=WARN_EVERY)
        self.cutter.error_messages.clear()

    def publish_parameters(self) -> None:
        p = self.predictor
        now = self.get_clock().now().nanoseconds * 1e-9
        self.pub_params.publish(conv.model_parameters_msg(p.model_name, p.parameter_set, p.temperature,
                                                          p.params.as_dict(), now))
        self._published_params = p.params

    # -- run-time parameter changes -------------------------------------------------------------------------------
    def _choice(self, changed: dict | None = None) -> ModelChoice:
        def value(name):
            return (changed or {}).get(name, self.get_parameter(name).value)
        return ModelChoice(source=value('source'), parameter_set=value('parameter_set'),
                           temperature=value('temperature'),
                           values={n: value('values.' + n) for n in VALUE_NAMES},
                           friction_reversal_threshold=value('friction_reversal_threshold'))

    def _on_set_parameters(self, params) -> SetParametersResult:
        changed = {p.name: p.value for p in params}
        if not set(changed) & set(CHOICE_PARAMS):
            return SetParametersResult(successful=True)
        try:
            choice = self._choice(changed)
            self._validated = (choice, choice.checked(changed))
        except ChoiceError as exc:
            self._validated = None
            return SetParametersResult(successful=False, reason=f'{exc.field}: {exc}')
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, params) -> None:
        names = {p.name for p in params}
        if names & set(CHOICE_PARAMS):
            choice = self._choice()
            validated, self._validated = self._validated, None
            try:   # install what the validating callback resolved (a parameter file is read once, there)
                self.predictor.set_choice(choice, validated[1] if validated and validated[0] == choice else None)
            except Exception as exc:   # noqa: BLE001 - cannot happen after validation; keep the running model
                self.get_logger().error(f'model parameters ({", ".join(sorted(names))}) not applied: {exc}; the '
                                        f'model keeps {self.predictor.params}')
                return
            self.publish_parameters()
            threshold = self.predictor.choice.friction_reversal_threshold
            self.get_logger().info(f'model parameters changed ({", ".join(sorted(names))}): {self.predictor.params}, '
                                   f'friction reversal threshold {threshold:g} m')
        if 'publish_branches' in names:
            self.publish_branches = self.get_parameter('publish_branches').value
        if 'cycle_metrics' in names:
            self.cycle_metrics = self.get_parameter('cycle_metrics').value


def main(args=None):
    spin_node(ElementModelNode, args)


if __name__ == '__main__':
    main()
