"""The lifter link (paper §V.B.1): protocol, serial hardware interface, velocity trajectory
controller and the ``lifter`` driver node."""
