"""Helpers shared by the tests that run nodes in-process with real rclpy + Fast DDS."""
import time
from contextlib import contextmanager

import rclpy
from rclpy.executors import SingleThreadedExecutor


@contextmanager
def ros_context(domain_id: int = None):
    """An initialised rclpy context of its own (on ``domain_id`` if given), shut down on exit."""
    ctx = rclpy.Context()
    if domain_id is None:
        rclpy.init(context=ctx)
    else:
        rclpy.init(context=ctx, domain_id=domain_id)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@contextmanager
def spinning(context, *nodes):
    """A SingleThreadedExecutor with ``nodes`` added; on exit the nodes are removed and destroyed and the
    executor shut down."""
    executor = SingleThreadedExecutor(context=context)
    for n in nodes:
        executor.add_node(n)
    try:
        yield executor
    finally:
        for n in nodes:
            executor.remove_node(n)
            n.destroy_node()
        executor.shutdown()


def spin_until(executor, condition, timeout=20.0):
    """Spin until ``condition()`` holds or ``timeout`` seconds pass; returns the condition's last value."""
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    return condition()
