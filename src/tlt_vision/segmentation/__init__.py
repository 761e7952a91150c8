"""Mask R-CNN instance segmentation in plain torch, sized for the CPU (paper §V.E)."""
