"""Ground software (paper §V.A): CCSDS link to the CRS, SQLite archive, Qt GUI and CLI."""
