"""Offline tools: training and dataset rendering for the vision models, and the search for the
ARS's coarse dispenser poses. They sit above every runtime package and the twin; nothing at run
time imports them."""
