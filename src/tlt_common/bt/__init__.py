"""Behaviour-tree core shared by the CRS and the ARS (paper §V.C).

``nodes``: Action and Condition node types (Colledanchise and Ögren, Table 3) on py_trees.
``ros``: non-blocking behaviours for ROS action goals, service calls and topic data (a package).
``server_readiness``: whether an action or service server is up, asked of rclpy at most once a period.
``status_codec``: a tree's status as a bounded byte string and as ``TreeStatus`` messages.
``shape_definition``: a tree shape's definition as a document and as link-sized parts.
``writable_blackboard``: the registry of blackboard keys the ground may write.
``ground_keys``: which agent, member or dispenser a ground "Set Blackboard Value" key names.
``viewer``: text and PNG renderings of a tree with its statuses.
"""
