"""C-3PO (paper §V.E): keypoints on the point cloud, corrector, registration and certificate."""
