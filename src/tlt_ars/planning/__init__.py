"""Motion planning for the UR10e arms on OMPL and pinocchio/coal (paper §V.D; docs/motion-planning.md)."""
