"""GPIO for the end effector: rivet-gun outputs and the limit-switch input (paper §V.B.4, Fig. 12)."""
