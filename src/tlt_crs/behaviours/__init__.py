"""Behaviours of the CRS tree (paper §V.C.2), grouped by what they talk to."""
