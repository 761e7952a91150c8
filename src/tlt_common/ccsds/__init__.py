"""The CCSDS ground link shared by the CRS and the GSW: definitions, packet codec, authentication."""
