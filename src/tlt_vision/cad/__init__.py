"""CAD models of the part classes as surface point samplers with annotated semantic keypoints."""
