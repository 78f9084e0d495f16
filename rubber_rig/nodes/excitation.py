"""excitation: runs test programs on the rig, streaming setpoints ahead of the measured samples.

Action:      run_program (msg_defs/action/RunProgram; feedback: block, cycle, achieved amplitude; result:
             per-block summaries)
Services:    ~/abort (std_srvs/Trigger: smooth ramp to rest), ~/hold (std_srvs/SetBool: true = hold,
             false = resume), ~/load_program (msg_defs/srv/LoadProgram: validate without running)
Subscribes:  samples (msg_defs/RigSampleBatch: amplitude control, progress), status (msg_defs/RigStatus,
             latched: sample rate and limits of the rig, faults)
Publishes:   setpoints (msg_defs/SetpointBatch), program (std_msgs/String, latched: YAML of the running program)

Setpoints are generated from the sample index by rubber_rig.excitation.ProgramRunner (never from wall-clock
time) and published ``lead_time`` ahead of the latest measured sample, so the driver always has setpoints
queued. The sample rate and the limits come from the driver's latched status, so they cannot disagree.
"""
from __future__ import annotations

import math

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future

from msg_defs.action import RunProgram
from msg_defs.msg import RigSampleBatch, RigStatus, SetpointBatch
from msg_defs.srv import LoadProgram
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger

from rubber_rig.excitation import Program, ProgramRunner, program_source
from rubber_rig.nodes import conversions as conv
from rubber_rig.nodes import topics
from rubber_rig.nodes.params import declare
from rubber_rig.nodes.spin import spin_node

READY_STATES = (RigStatus.STATE_IDLE, RigStatus.STATE_RUNNING, RigStatus.STATE_HOLDING)


def read_program(path: str = '', yaml_text: str = '') -> tuple[Program, str]:
    """(validated Program, its YAML text) from a file path / shipped name, or from YAML text."""
    if path:
        text, name = program_source(path)
        return Program.from_yaml_text(text, name=name), text
    if not yaml_text.strip():
        raise ValueError('no program: give program_path or program_yaml')
    return Program.from_yaml_text(yaml_text, name='goal'), yaml_text


class ExcitationNode(Node):

    def __init__(self, node_name: str = 'excitation', **kwargs):
        super().__init__(node_name, **kwargs)
        self.program_param = declare(self, 'program', '', 'program (shipped name or YAML path) to run as soon as '
                                     'the rig is ready; empty: wait for a run_program goal')
        self.amplitude_control = declare(self, 'amplitude_control', True, 'adjust command amplitude and mean '
                                         'so the measured amplitude reaches the target (program parameter only)')
        self.compensation_memory = declare(self, 'compensation_memory', True, 'with amplitude control, each '
                                           'block starts from the gain and mean offset earlier blocks of the run '
                                           'learned (false: every block starts uncompensated)')
        self.lead_time = declare(self, 'lead_time', 0.5, 'how far ahead of the latest measured sample '
                                 'setpoints are streamed', range=(0.02, 5.0), units='s')
        self.batch_size = declare(self, 'batch_size', 50, 'setpoints per SetpointBatch', range=(1, 5000))
        self.stream_period = declare(self, 'stream_period', 0.02, 'period of the streaming timer',
                                     range=(0.001, 0.5), units='s')
        self.feedback_period = declare(self, 'feedback_period', 0.2, 'period of action feedback',
                                       range=(0.01, 10.0), units='s')
        if self.stream_period >= self.lead_time / 2:
            from rubber_rig.nodes.params import ParameterError
            raise ParameterError(self.get_name(), 'stream_period', f'{self.stream_period} s must be below half '
                                 f'of lead_time ({self.lead_time} s) or the driver could starve')
        if self.program_param:  # validate at start: a wrong name fails here, naming the parameter
            try:
                self._pending = read_program(self.program_param)
            except (ValueError, FileNotFoundError) as exc:
                from rubber_rig.nodes.params import ParameterError
                raise ParameterError(self.get_name(), 'program', str(exc)) from None
        else:
            self._pending = None

        self.status: RigStatus | None = None
        self.next_sample = None          # sequence after the latest measured sample
        self.runner: ProgramRunner | None = None
        self.end_sequence = None         # sequence after the last setpoint of the finished runner
        self.goal_handle = None
        self._done: Future | None = None
        self._last_feedback = 0.0
        self.result: RunProgram.Result | None = None   # result of the last run (also for program runs)

        self.pub_setpoints = self.create_publisher(SetpointBatch, topics.SETPOINTS, topics.STREAM_QOS)
        self.pub_program = self.create_publisher(String, topics.PROGRAM, topics.LATCHED_QOS)
        self.create_subscription(RigSampleBatch, topics.SAMPLES, self.on_samples, topics.STREAM_QOS)
        self.create_subscription(RigStatus, topics.STATUS, self.on_status, topics.LATCHED_QOS)
        self.create_service(Trigger, '~/abort', self.on_abort)
        self.create_service(SetBool, '~/hold', self.on_hold)
        self.create_service(LoadProgram, '~/load_program', self.on_load_program)
        self.action = ActionServer(self, RunProgram, 'run_program', execute_callback=self.execute,
                                   goal_callback=self.on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT)
        self.create_timer(self.stream_period, self.stream)

    # -- inputs -----------------------------------------------------------------------------------------------
    def on_status(self, msg: RigStatus) -> None:
        self.status = msg
        if self.runner is not None and msg.state == RigStatus.STATE_FAULT:
            # the driver ramps the actuator down itself; stop commanding and report why
            self.runner.abort('rig fault: ' + '; '.join(msg.fault_messages or conv.fault_names(msg.faults)))
            self._finish(success=False)

    def on_samples(self, msg: RigSampleBatch) -> None:
        n = len(msg.displacement)
        self.next_sample = msg.first_sequence + n
        if self.runner is not None and n:
            self.runner.feed_measurement(msg.first_sequence, conv.as_array(msg.displacement))

    # -- starting programs ------------------------------------------------------------------------------------------
    def rig_ready(self) -> str:
        """'' when a program can start, else why not."""
        if self.status is None:
            return "no rig status received on 'status' yet (is rig_driver active?)"
        if self.status.state not in READY_STATES:
            return f'rig is {self.status.state_name}'
        if self.runner is not None:
            return 'a program is already running'
        return ''

    def start(self, program: Program, text: str, amplitude_control: bool) -> None:
        """Build the runner (limits checked against every setpoint before anything is sent)."""
        limits = conv.limits_from_msg(self.status.limits)
        lead = int(math.ceil(self.lead_time * self.status.sample_rate))
        # An idle rig streams nothing and starts at the sequence of the first setpoint it gets; a streaming
        # (holding) rig gets the program lead_time ahead of its latest sample.
        start = 0 if self.next_sample is None else self.next_sample + lead
        self.runner = ProgramRunner(program, self.status.sample_rate, limits, amplitude_control,
                                    start_sequence=start, compensation_memory=self.compensation_memory)
        self.start_sequence = self.runner.sequence
        self.end_sequence = None
        self.result = None
        self.pub_program.publish(String(data=text))
        self.get_logger().info(f"program '{program.name}': {len(program.blocks)} blocks, "
                               f'{program.duration(self.status.sample_rate):.1f} s, starts at sample '
                               f'{self.start_sequence}')

    # -- streaming (timer) ------------------------------------------------------------------------------------------
    def stream(self) -> None:
        if self.runner is None:
            if self._pending is not None and not self.rig_ready():
                program, text = self._pending
                self._pending = None
                self.start(program, text, self.amplitude_control)
            return
        r = self.runner
        measured = self.start_sequence if self.next_sample is None else max(self.next_sample, self.start_sequence)
        target = measured + int(math.ceil(self.lead_time * self.status.sample_rate))
        while not r.finished and r.sequence < target:
            first, block = r.sequence, (r.block_index if r.state == 'running' else -1)
            x = r.next_setpoints(self.batch_size)
            self.pub_setpoints.publish(conv.setpoint_batch_msg(first, 1.0 / self.status.sample_rate, x, block))
        if r.finished and self.end_sequence is None:
            self.end_sequence = r.sequence
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.goal_handle is not None and now - self._last_feedback >= self.feedback_period:
            self._last_feedback = now
            self.goal_handle.publish_feedback(self.feedback())
        if self.end_sequence is not None and self.next_sample is not None and self.next_sample >= self.end_sequence:
            self._finish(success=not r.aborted)   # measured to the end: the summaries are complete

    def feedback(self) -> RunProgram.Feedback:
        p = self.runner.progress
        return RunProgram.Feedback(block_index=p.block_index, block_count=p.block_count, block_name=p.block_name,
                                   cycle=p.cycle, cycles_total=p.cycles_total, target_amplitude=p.target_amplitude,
                                   achieved_amplitude=p.achieved_amplitude, progress=p.fraction)

    def _finish(self, success: bool) -> None:
        r = self.runner
        if r is None:
            return
        result = RunProgram.Result(success=success and not r.aborted,
                                   message=r.abort_reason if r.aborted else 'completed',
                                   blocks=[conv.block_summary_msg(s) for s in r.block_summaries])
        self.result = result
        self.runner = None
        self.get_logger().info(f'program ended: {result.message}')
        if self._done is not None and not self._done.done():
            self._done.set_result(result)

    # -- action -------------------------------------------------------------------------------------------------------
    def on_goal(self, goal) -> GoalResponse:
        busy = self.runner is not None or self._done is not None
        return GoalResponse.REJECT if busy else GoalResponse.ACCEPT

    async def execute(self, goal_handle) -> RunProgram.Result:
        goal = goal_handle.request
        try:
            program, text = read_program(goal.program_path, goal.program_yaml)
            why = self.rig_ready()
            if why:
                raise ValueError(why)
            self.start(program, text, goal.amplitude_control)
        except (ValueError, FileNotFoundError) as exc:   # ProgramError, LimitError: name block and field
            goal_handle.abort()
            return RunProgram.Result(success=False, message=str(exc))
        self.goal_handle, self._done = goal_handle, Future()
        def check_cancel():
            if goal_handle.is_cancel_requested and self.runner is not None and not self.runner.aborted:
                self.runner.abort('goal cancelled')   # smooth ramp to rest; the goal ends when it is done
        cancel_timer = self.create_timer(0.05, check_cancel)
        try:
            result = await self._done
        finally:
            self.destroy_timer(cancel_timer)
            self.goal_handle, self._done = None, None
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif result.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    # -- services ---------------------------------------------------------------------------------------------------------
    def on_abort(self, request, response):
        if self.runner is None:
            response.success, response.message = False, 'no program running'
        else:
            self.runner.abort('operator abort')
            response.success, response.message = True, 'ramping down to the rest position'
        return response

    def on_hold(self, request, response):
        if self.runner is None:
            response.success, response.message = False, 'no program running'
        elif request.data:
            self.runner.hold()
            response.success, response.message = True, 'holding at the block mean'
        else:
            self.runner.resume()
            response.success, response.message = True, 'resuming the held block from its start'
        return response

    def on_load_program(self, request, response):
        try:
            program, _ = read_program(request.path, request.program_yaml)
            rate = self.status.sample_rate if self.status else 1000.0
            if self.status is not None:
                conv.limits_from_msg(self.status.limits).check_program(program, rate)
            response.success, response.message = True, f"program '{program.name}' is valid"
            response.block_count, response.duration = len(program.blocks), program.duration(rate)
        except (ValueError, FileNotFoundError) as exc:
            response.success, response.message = False, str(exc)
        return response


def main(args=None):
    spin_node(ExcitationNode, args)


if __name__ == '__main__':
    main()
