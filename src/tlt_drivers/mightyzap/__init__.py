"""MightyZAP linear actuators (Top Grippers) over the IR serial protocol with pyserial."""
