"""The UR10e arm link over ur-rtde: configuration, the link itself, the hardware interface and the node."""
