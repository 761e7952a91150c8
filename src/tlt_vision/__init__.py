"""Vision (paper §V.E): Mask R-CNN segmentation and C-3PO certified poses."""
