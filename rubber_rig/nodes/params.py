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

"""Declaring parameters with descriptors, and errors that name the parameter.

Every node parameter is declared with a description and, for numbers, a range: rclpy then refuses an
out-of-range value from a parameter file, the command line or ``ros2 param set`` with a message naming the
parameter. Cross-field rules (e.g. ``limits.displacement_min < limits.displacement_max``) are checked by the
node at start and raise :class:`ParameterError`, whose message starts with the parameter's name.
"""
from __future__ import annotations

import difflib
from typing import Any, Sequence

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter

from .rclpy_compat import parameter_overrides


class ParameterError(ValueError):
    """A parameter value is invalid; the message names the parameter (``parameter 'p' of node 'n': why``).

    ``node``: the node (or its name). ``logger_name`` is the node's logger (namespace included), so whoever
    reports the error at start (rubber_rig.nodes.spin) logs it under the node's name.
    """

    def __init__(self, node, name: str, why: str):
        node_name = node.get_name() if isinstance(node, Node) else str(node)
        self.parameter = name
        self.why = why
        self.logger_name = node.get_logger().name if isinstance(node, Node) else node_name
        super().__init__(f"parameter '{name}' of node '{node_name}': {why}")


def declare(node: Node, name: str, default: Any, description: str, *, range: tuple | None = None,
            choices: Sequence[str] | None = None, read_only: bool = False, units: str = '') -> Any:
    """Declare one parameter with a descriptor and return its (validated) value."""
    d = ParameterDescriptor(description=f'{description}' + (f' [{units}]' if units else ''),
                            read_only=read_only)
    if range is not None:
        lo, hi = range
        if isinstance(default, bool):
            raise TypeError('no range for a bool parameter')
        if isinstance(default, int):
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        d.additional_constraints = f'{lo} <= {name} <= {hi}'
    if choices is not None:
        d.additional_constraints = 'one of: ' + ', '.join(choices)
    _promote_int_override(node, name, default)
    try:
        value = node.declare_parameter(name, default, d).value
    # rclpy's range check: re-raise naming node and field
    except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
        raise ParameterError(node, name, str(exc)) from None
    if choices is not None and value not in choices:
        raise ParameterError(node, name, f'{value!r} is not one of {", ".join(choices)}')
    return value


def _promote_int_override(node: Node, name: str, default: Any) -> None:
    """YAML writes ``sample_rate: 1000`` as an integer; accept it for a double parameter as ros2 users expect.

    rclpy keeps the overrides from parameter files and the constructor until the parameter is declared; an
    integer there would be refused as the wrong type.
    """
    overrides = parameter_overrides(node)
    p = overrides.get(name)
    if isinstance(default, float) and p is not None and p.type_ == Parameter.Type.INTEGER:
        overrides[name] = Parameter(name, Parameter.Type.DOUBLE, float(p.value))


def check(node: Node, condition: bool, name: str, why: str) -> None:
    """Raise ParameterError naming ``name`` unless ``condition`` holds."""
    if not condition:
        raise ParameterError(node, name, why)


def undeclared_overrides(node: Node) -> list[str]:
    """Parameters given to ``node`` (parameter file, command line) that it never declared.

    rclpy keeps such values in the overrides and ignores them without a word, so a misspelt key in a config
    file (``sim.specimen.frition_reversal_threshold``) would silently leave the default in force. Call after
    the constructor has declared everything; returns the names and logs one warning per name, with the
    closest declared names as a hint.
    """
    unknown = sorted(k for k in parameter_overrides(node) if not node.has_parameter(k))
    known = sorted(node.list_parameters([], 0).names)     # depth 0: every parameter
    for name in unknown:
        close = difflib.get_close_matches(name, known, n=2, cutoff=0.6)
        hint = f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ''
        node.get_logger().warning(f"parameter '{name}' is not a parameter of node '{node.get_name()}' and is "
                                  f"ignored{hint}")
    return unknown


def accept_integers_for_doubles(node: Node) -> None:
    """``ros2 param set /rig_driver limits.force_max 5`` sends an integer; for a double parameter that is what
    the user meant. rclpy's public pre-set hook converts it before the type check refuses it.
    """
    def promote(parameters):
        out = []
        for p in parameters:
            if p.type_ == Parameter.Type.INTEGER and node.has_parameter(p.name) \
                    and node.get_parameter(p.name).type_ == Parameter.Type.DOUBLE:
                p = Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
            out.append(p)
        return out
    node.add_pre_set_parameters_callback(promote)
