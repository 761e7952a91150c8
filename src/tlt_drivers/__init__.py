"""Hardware drivers (paper §V.B): Dynamixel, MightyZAP, lifter serial, UR RTDE and GPIO links."""
