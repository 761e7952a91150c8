"""The Assistant Robot System (paper §IV.C, §V.C.3): one process per UR10e arm."""
