"""The vision node's service handlers, one module per service, and what they share.

Each handler is a class built with its collaborators (:mod:`tlt_vision.node` wires them) and
called as the service's callback; it answers every request, a failure being an answer with its
reason:

* :mod:`.inspect_part`: ``InspectPart``, a presented strut or cross frame, or a rivet in a gun;
* :mod:`.inspect_bay`: ``InspectBay``, a bay's corner joints against the mission's;
* :mod:`.check_alignment`: ``CheckAlignment``, a held part against its joint positions;
* :mod:`.locate_tag`: ``LocateTag``, a dispenser's frame from its AprilTag.

What they share: :mod:`.frame_source` (which camera, the request's time, one fresh frame),
:mod:`.detector` (the segmenter at the node's scores), :mod:`.frame_poser` (poses of a frame's
detections), :mod:`.world` (the tower's place, estimates in the world) and :mod:`.reports` (the
answered messages and their log lines).
"""
