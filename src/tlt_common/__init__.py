"""Code the TLT agents share: configuration loading, the launcher, and (as they land) the
behaviour-tree node types and status codec, the CCSDS packet definitions and the mission model."""
