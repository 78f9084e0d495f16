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


"""What marks a conformance scenario (a function of the run's link.ConformanceLink): the requirements it judges,
and the one way out of a run, Aborted.
"""


class Aborted(RuntimeError):
    """The run left the operator's envelope (or could not continue safely): ABORT was commanded."""


def judges(*requirement_ids):
    """Decorator of a scenario (a function of the ConformanceLink): the requirements it judges. A scenario that
    fails on its own (an exception other than Aborted, e.g. a controller that does not do what the scenario needs)
    fails those it had not judged yet, with the reason (active.ConformanceRun.run), and the run goes on.
    """
    def mark(scenario):
        scenario.requirements = tuple(requirement_ids)
        return scenario
    return mark
