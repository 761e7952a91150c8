"""Code the TLT agents share, below every agent and driver (it imports none of them):

* ``bt``: behaviour-tree node types, the non-blocking ROS behaviours and the status codec;
* ``ccsds``: the ground link's packets, authentication and codec;
* ``mission``: mission files, the tower model and the dispensers' tag mounts;
* ``geometry``: transforms and the UR10e model, one convention at the boundaries;
* ``ros``: rclpy helpers (nodes, executors, spinning, timers, stamps, watches, isolation);
* ``launch`` and ``recording``: the launcher and the MCAP recorder;
* ``config_schema``, ``ros_names``, ``interfaces``: configuration checking, the system's names and
  its interfaces.
"""
