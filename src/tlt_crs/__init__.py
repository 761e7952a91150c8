"""The Construction Robot System (paper §IV.B, §V.C.2): CRS behaviour tree, tower model, ground link."""
