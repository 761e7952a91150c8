"""Helpers for processes that run rclpy nodes: the node, its executor and spin loop, timers, message
stamps, the ROS graph, signals and shutdown, and a run's own ROS domain.

Node and executor:
``lean_node``: a ``Node`` without rclpy's default QoS-event handlers.
``direct_executor``: executors that call quick callbacks straight from the wait.
``spin_loop``: a spin loop that survives an entity destroyed while a wait set is built.
``action_client``: an ``ActionClient`` safe to send goals from a thread other than the executor's.
``periodic_timer``: timers on sim time under the twin and on the monotonic clock on hardware.
``stamps``: float seconds into and out of ``builtin_interfaces`` Time and Duration.
``action_graph``: what the graph lists for an action server, to say why it is not ready.

Process life:
``interpreter_lock``: the interpreter's switch interval for nodes beside busy executor threads.
``stop_signals``: SIGINT and SIGTERM as a request to stop, with rclpy shut down by the process.
``executor_stop``: stop an executor once the callbacks it is running have ended.
``node_teardown``: destroy a node with its action servers and clients.
``isolation``: a ROS domain of its own for each run on one machine.
``rosout_logging``: the process's Python ``logging`` on ``/rosout``, at its ``--log-level`` or
``TLT_LOG_LEVEL``.

Watches on the wall clock, outside the executor (``watch_thread`` is their thread):
``sim_clock_watch``: ``/clock`` has stopped.
``topic_silence_watch``: a topic the node needs has gone silent.

The system's topic, service and action names are not here but in ``tlt_common.ros_names``: they are
the interface the agents, the drivers and the tests share, not a helper for running a node.
"""
