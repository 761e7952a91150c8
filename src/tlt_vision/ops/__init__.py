"""Plain-torch vision operators (torchvision does not work with the CPU torch of this project).

Boxes are ``(x1, y1, x2, y2)`` in pixels, float tensors of shape ``(N, 4)``; point clouds are
``(..., N, 3)`` in metres.
"""
