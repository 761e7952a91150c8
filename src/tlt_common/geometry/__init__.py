"""Geometry shared by the ARS, vision and the twin: rigid transforms and their one set of
conventions (:mod:`.transforms`), and the UR10e arm's published model and kinematics
(:mod:`.ur10e`)."""
